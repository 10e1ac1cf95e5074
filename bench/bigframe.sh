#!/usr/bin/env bash
# bench/bigframe.sh - peak memory of exrfog on a 16384x16384 frame.
#
# usage: bench/bigframe.sh [BUILD_DIR] [SIZE]   (defaults: build, 16384)
#
# Makes a SIZE x SIZE RGBA + Z half ZIP frame with oiiotool (constant
# colour, Z = 25; oiiotool itself needs ~SIZE^2 * 20 bytes to make it), then
# fogs it once with exrfog under /usr/bin/time and prints wall time and
# peak RSS. exrfog streams by chunks, so its peak should not grow with SIZE.
set -euo pipefail
build="${1:-build}"
size="${2:-16384}"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-big.XXXXXX")"
trap 'rm -rf "$tmp"' EXIT
oiiotool --pattern constant:color=0.5,0.4,0.3,1,25 "${size}x${size}" 5 --chnames R,G,B,A,Z \
    -d half --compression zip -o "$tmp/big.exr"
/usr/bin/time -f '%e %M' -o "$tmp/time" "$build/exrfog" "$tmp/big.exr" -o "$tmp/fog.exr" \
    --world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 50 --fog exp:density=0.02 --stats
read -r wall rss < "$tmp/time"
echo "| ${size}x${size} RGBA+Z half ZIP | $(nproc) CPUs | ${wall} s | $((rss / 1024)) MB peak RSS |"
