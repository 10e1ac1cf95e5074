#!/usr/bin/env bash
# shellcheck disable=SC2016  # tool command lines are stored single-quoted and eval'd
# bench/floor.sh - exrfog against the transcode floor (bench/floor: every
# chunk decoded and re-encoded through OpenEXRCore on N threads, no
# per-pixel work), stock zlib and libdeflate, and against oiiotool.
#
# usage: bench/floor.sh [BUILD_DIR]       (default: <repo>/build-rel)
#
# For every frame size, compression (the input's, kept on output) and
# thread count, BENCH_RUNS rounds (after BENCH_WARMUP untimed ones) run,
# interleaved and rotated each round:
#   floor --codec zlib            the stock floor (OpenEXRCore's zlib)
#   floor --codec libdeflate      (ZIP/ZIPS only: the codec changes nothing else)
#   oiiotool IN -o OUT            (oiiotool uses every core whatever N)
#   exrfog exp, exrfog halfspace + height + box, each with --codec zlib and
#   --codec libdeflate (one row each for uncompressed and PIZ)
# and prints medians and ratios to the stock floor of the same run; every
# output is checked pixel-identical (floor) or read back (oiiotool --diff
# floor vs input) once. Nothing asserts on time.
#
# Environment:
#   BENCH_RUNS=7  BENCH_WARMUP=1
#   BENCH_SIZES="1920x1080 3840x2160"  BENCH_COMPS="none zip zips piz"  BENCH_THREADS="1 2"
#   BENCH_QUICK=1   a quick check: BENCH_RUNS=3, 1920x1080 only
#   BENCH_OUT=FILE  also write the table there (default: bench/floor.md unless quick)
#   BENCH_NOTE=TEXT a note for the table (e.g. that the machine was shared)
set -uo pipefail
die() { echo "floor.sh: $*" >&2; exit 1; }
here="$(cd "$(dirname "$0")" && pwd)"
build="${1:-$here/../build-rel}"
[[ -d "$build" ]] && build="$(cd "$build" && pwd)"
if [[ -n "${BENCH_QUICK:-}" ]]; then
    runs="${BENCH_RUNS:-3}" sizes="${BENCH_SIZES:-1920x1080}" out_md="${BENCH_OUT:-}"
else
    runs="${BENCH_RUNS:-7}" sizes="${BENCH_SIZES:-1920x1080 3840x2160}" out_md="${BENCH_OUT:-$here/floor.md}"
fi
warmup="${BENCH_WARMUP:-1}"
comps="${BENCH_COMPS:-none zip zips piz}"
thread_counts="${BENCH_THREADS:-1 2}"
for b in floor exrfog make_sample; do [[ -x "$build/$b" ]] || die "$build/$b not built"; done
command -v oiiotool >/dev/null 2>&1 || die "oiiotool not found"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-floor.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT

cam='--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 50'
exp_fog='--fog exp:density=0.02'
combo_fog='--fog halfspace:plane=0,1,0,-1:density=0.05 --fog height:density=0.02:falloff=0.1:base=0 --fog box:min=-3,0,-12:max=3,2.5,-4:density=0.2'
median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{ v[NR] = $1 } END {
    if (NR == 0) exit; if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

rows=()
for size in $sizes; do
    for comp in $comps; do
        in="$tmp/in.exr"
        echo "floor.sh: making $size $comp" >&2
        "$build/make_sample" "$in" --size "$size" --compression "$comp" >/dev/null 2>&1 || die "make_sample failed"
        for nt in $thread_counts; do
            names=() cmds=()
            add() { names+=("$1"); cmds+=("$2"); }
            zipish=0; [[ $comp == zip || $comp == zips ]] && zipish=1
            add "floor (stock zlib)" '"$build/floor" --threads $nt --codec zlib "$in" "$OUT"'
            (( zipish )) && add "floor (libdeflate)" '"$build/floor" --threads $nt --codec libdeflate "$in" "$OUT"'
            add "oiiotool copy" 'oiiotool "$in" -o "$OUT"'
            if (( zipish )); then
                for c in zlib libdeflate; do
                    add "exrfog exp, $c" '"$build/exrfog" --threads $nt --codec '$c' $cam $exp_fog "$in" -o "$OUT"'
                    add "exrfog 3-component, $c" '"$build/exrfog" --threads $nt --codec '$c' $cam $combo_fog "$in" -o "$OUT"'
                done
            else
                add "exrfog exp" '"$build/exrfog" --threads $nt $cam $exp_fog "$in" -o "$OUT"'
                add "exrfog 3-component" '"$build/exrfog" --threads $nt $cam $combo_fog "$in" -o "$OUT"'
            fi
            n=${#names[@]}
            declare -A walls=()
            for (( r = 0; r < warmup + runs; ++r )); do
                for (( k = 0; k < n; ++k )); do
                    i=$(( (k + r) % n )) OUT="$tmp/out_$i.exr"
                    rm -f "$OUT"
                    a=$EPOCHREALTIME
                    eval "${cmds[$i]}" >/dev/null 2>"$tmp/err" || { cat "$tmp/err" >&2; die "${names[$i]} failed"; }
                    b=$EPOCHREALTIME
                    (( r >= warmup )) && walls[$i]+="$(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.4f", b - a }') "
                done
                if (( r == 0 )); then   # the floors are transcodes: same pixels
                    oiiotool --diff "$in" "$tmp/out_0.exr" >/dev/null 2>&1 || die "floor output differs from the input"
                    (( zipish )) && { oiiotool --diff "$in" "$tmp/out_1.exr" >/dev/null 2>&1 || die "libdeflate floor output differs"; }
                fi
            done
            ref=$(median <<<"${walls[0]}")
            oii=$(median <<<"${walls[$(( zipish ? 2 : 1 ))]}")
            for (( i = 0; i < n; ++i )); do
                m=$(median <<<"${walls[$i]}")
                row="$(awk -v s="$size" -v c="$comp" -v t="$nt" -v name="${names[$i]}" -v m="$m" -v f="$ref" -v o="$oii" \
                    'BEGIN { printf "| %s | %s | %s | %s | %.3f | %.2f× | %.2f× |", s, c, t, name, m, m / f, m / o }')"
                rows+=("$row")
                echo "$row" >&2   # progress: an interrupted run still has its rows
            done
            unset walls
        done
    done
done
{
    echo "## exrfog against the transcode floor"
    echo
    echo "Made by bench/floor.sh. The stock floor is bench/floor --codec zlib: OpenEXRCore alone decoding and"
    echo "re-encoding every chunk on the same threads, no per-pixel work (its output is checked pixel-identical"
    echo "to the input). Ratios are to the stock floor and to oiiotool of the same run and frame."
    echo
    echo "| frame | compression | threads | tool | median wall s | / stock floor | / oiiotool |"
    echo "|---|---|---:|---|---:|---:|---:|"
    printf '%s\n' "${rows[@]}"
    echo
    echo "- $(date -u '+%Y-%m-%d %H:%M UTC'); $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | sed 's/.*: *//'), $(uname -sr)"
    echo "- $runs timed runs (+$warmup warm-up) per row, interleaved, order rotated each round; medians of wall time"
    echo "- input: make_sample RGBA half + Z float, output compression = input's, default zip level (6)"
    [[ -n "${BENCH_NOTE:-}" ]] && echo "- note: $BENCH_NOTE"
} > "$tmp/table.md"
cat "$tmp/table.md"
[[ -n "$out_md" ]] && cp "$tmp/table.md" "$out_md" && echo "floor.sh: table written to $out_md" >&2
exit 0
