#!/usr/bin/env bash
# bench/pixels.sh - what a small exrfog_fog_pixels call costs beside a big one,
# per model, through the public API (bench/pixels_bench.c says how).
#
# usage: bench/pixels.sh [BUILD_DIR]     (default: <repo>/build, a Release build)
#
# Writes the table, with the machine and the date, to bench/pixels.md.
# Environment: PIXELS_RUNS=5 (rounds per model; medians). Nothing asserts on time.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
build="${1:-$repo/build}"
bin="$build/pixels_bench"
[[ -x "$bin" ]] || { echo "pixels: no $bin (cmake --build $build --target pixels_bench)" >&2; exit 1; }
runs="${PIXELS_RUNS:-5}"
cpu="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
table="$("$bin" "$runs" | tee /dev/stderr)"
{
  echo "# exrfog_fog_pixels: a 64-pixel call beside a 1-Mpixel call"
  echo
  echo "Machine: $cpu, $(nproc) cores, $(uname -sr); $(date -u '+%Y-%m-%d %H:%M UTC');"
  echo "source $(git -C "$repo" rev-parse --short HEAD 2>/dev/null || echo '?'). One thread, medians of $runs rounds."
  echo
  echo "A 1024 x 1024 image (a ground plane to 60 units under a camera 1.7 up, sky above the"
  echo "horizon) fogged in one call, then in 16,384 calls of 64 pixels: rows (64 x 1, the"
  echo "caller's rows contiguous) and tiles (8 x 8 of a 1024-wide image). The ratio is the small"
  echo "calls' total over the big call's time: what one 64-pixel call costs over 64 times the"
  echo "per-pixel cost of a 1-Mpixel call."
  echo
  echo "$table"
} > "$here/pixels.md.new"
mv "$here/pixels.md.new" "$here/pixels.md"
cat "$here/pixels.md"
