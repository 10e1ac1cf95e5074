#!/usr/bin/env bash
# bench/codec.sh - speed and size of each zip level, stock zlib (OpenEXRCore)
# against libdeflate, on the transcode floor (bench/floor: decode + re-encode
# every chunk, no per-pixel work).
#
# usage: bench/codec.sh [BUILD_DIR]      (default: <repo>/build-rel)
#
# Frames: make_sample RGBA half + Z float, 1920x1080 and 3840x2160 (ZIP).
# For every size, codec and level 1..9 (and the default, no level), the
# floor transcodes the frame to ZIP at that level; BENCH_RUNS (default 5)
# rounds, the codec/level cases interleaved and rotated each round; medians.
# Prints a Markdown table (wall s, output MB, ratio to zlib at level 6 and
# to the input); nothing asserts on time.
#
# Environment: BENCH_RUNS=5, BENCH_SIZES="1920x1080 3840x2160", THREADS=2.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
build="${1:-$here/../build-rel}"
runs="${BENCH_RUNS:-5}"
sizes="${BENCH_SIZES:-1920x1080 3840x2160}"
threads="${THREADS:-2}"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-codec.XXXXXX")" || exit 1
trap 'rm -rf "$tmp"' EXIT
median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{ v[NR] = $1 } END {
    if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

echo "| frame | codec | level | median wall s | output MB | wall / zlib:6 | size / zlib:6 |"
echo "|---|---|---:|---:|---:|---:|---:|"
for size in $sizes; do
    in="$tmp/in_$size.exr"
    "$build/make_sample" "$in" --size "$size" --compression zip >/dev/null 2>&1 || exit 1
    cases=()
    for codec in zlib libdeflate; do
        for level in default 1 2 3 4 5 6 7 8 9; do cases+=("$codec:$level"); done
    done
    declare -A wall=() bytes=()
    n=${#cases[@]}
    for (( r = 0; r < runs; ++r )); do
        for (( k = 0; k < n; ++k )); do
            c=${cases[$(( (k + r) % n ))]}
            codec=${c%%:*} level=${c#*:}
            comp=zip; [[ $level != default ]] && comp="zip:$level"
            out="$tmp/out.exr"
            a=$EPOCHREALTIME
            "$build/floor" --threads "$threads" --codec "$codec" --compression "$comp" "$in" "$out" || exit 1
            b=$EPOCHREALTIME
            wall[$c]+="$(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.4f", b - a }') "
            bytes[$c]=$(stat -c %s "$out")
        done
    done
    ref_w=$(median <<<"${wall[zlib:6]}") ref_b=${bytes[zlib:6]}
    for c in "${cases[@]}"; do
        w=$(median <<<"${wall[$c]}")
        awk -v s="$size" -v c="${c%%:*}" -v l="${c#*:}" -v w="$w" -v b="${bytes[$c]}" -v rw="$ref_w" -v rb="$ref_b" \
            'BEGIN { printf "| %s | %s | %s | %.3f | %.2f | %.2f | %.3f |\n", s, c, l, w, b / 1e6, w / rw, b / rb }'
    done
    unset wall bytes
done
echo
echo "- $(date -u '+%Y-%m-%d %H:%M UTC'); $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | sed 's/.*: *//'); floor --threads $threads; $runs runs, interleaved, medians"
