#!/usr/bin/env bash
# shellcheck disable=SC2016,SC2034  # tool command lines are stored single-quoted and eval'd
# bench/run.sh - measure exrfog against its peers on a 1920x1080 frame.
#
# usage: bench/run.sh [BUILD_DIR]        (default: <repo>/build)
#
# Generates a 1920x1080 RGBA half + Z float ZIP frame with make_sample, then runs
# BENCH_RUNS (default 7) interleaved rounds of
#   (a) oiiotool IN -o OUT                                   the usual copy
#   (a') bench/floor --codec zlib IN OUT                     the transcode floor
#        (OpenEXRCore alone decoding and re-encoding every chunk; see bench/floor.sh)
#   (b) exrfog --fog exp:density=0.02 IN -o OUT              the brief's workload
#   (c) exrfog with per-channel exp2 plus linear fog (two components, three taus)
#   (c') exrfog with the numpy peer's own half-space fog
#   (d) python3 numpy_halfspace_fog.py IN OUT                the numpy/OIIO peer
# and prints a Markdown table of medians (wall seconds, peak RSS) with ratios to
# oiiotool and to the floor; the same table goes to bench/results.md.  Nothing here asserts on time.
#
# Environment:
#   BENCH_RUNS=7        timed rounds (the order of the tools rotates every round)
#   BENCH_WARMUP=1      untimed rounds first (page cache, lazy loading)
#   BENCH_SIZE=1920x1080
#   EXRFOG_THREADS=N    pass --threads N to exrfog
#   PYTHON=python3      interpreter for the peer (else the first of python3,
#                       /usr/bin/python3 that can import OpenImageIO and numpy)
#   MAKE_SAMPLE=path    make_sample binary (else BUILD_DIR/make_sample, else built with cc)
#
# Wall time: bash's EPOCHREALTIME around the run (ms resolution); peak RSS: %M of
# /usr/bin/time -f '%e %M' (apt-get install -y time).
set -uo pipefail

die() { echo "bench: $*" >&2; exit 1; }

here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
shared="$(cd "$(dirname "$0")/../../shared" 2>/dev/null && pwd)" || shared=""
build="${1:-$repo/build}"
[[ -d "$build" ]] && build="$(cd "$build" && pwd)"
runs="${BENCH_RUNS:-7}"
warmup="${BENCH_WARMUP:-1}"
size="${BENCH_SIZE:-1920x1080}"
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || die "BENCH_RUNS must be a positive integer"
[[ "$warmup" =~ ^[0-9]+$ ]] || die "BENCH_WARMUP must be a non-negative integer"
[[ "$size" =~ ^[1-9][0-9]*x[1-9][0-9]*$ ]] || die "BENCH_SIZE must be WxH"

tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-bench.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT

notes=()
note() { notes+=("$*"); echo "note: $*" >&2; }

timer=/usr/bin/time
if [[ ! -x "$timer" ]]; then
    timer=""
    note "/usr/bin/time not found (apt-get install -y time): peak RSS not measured"
fi

# --- the input frame -------------------------------------------------------
make_sample="${MAKE_SAMPLE:-$build/make_sample}"
if [[ ! -x "$make_sample" ]]; then
    echo "bench: $make_sample not found; compiling samples/make_sample.c with cc" >&2
    make_sample="$tmp/make_sample"
    # shellcheck disable=SC2046
    cc -std=c11 -O2 "$repo/samples/make_sample.c" -o "$make_sample" \
        $(pkg-config --cflags --libs OpenEXR 2>/dev/null || echo "-I/usr/include/OpenEXR -lOpenEXRCore-3_1") -lm \
        || die "could not build make_sample"
fi
in="$tmp/frame.exr"
echo "bench: rendering $size frame with $make_sample ..." >&2
t0=$EPOCHREALTIME
"$make_sample" "$in" --size "$size" --compression zip >&2 || die "make_sample failed"
t1=$EPOCHREALTIME
gen_s=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.1f", b - a }')
in_bytes=$(stat -c %s "$in")

# --- the tools ----------------------------------------------------------------
names=() cmds=()
add_tool() { names+=("$1"); cmds+=("$2"); }   # $2: command line, eval'd with IN/OUT set

command -v oiiotool >/dev/null 2>&1 || die "oiiotool not found (apt-get install -y openimageio-tools)"
add_tool "oiiotool (copy)" 'oiiotool "$IN" -o "$OUT"'

exrfog="$build/exrfog"
threads=()
[[ -n "${EXRFOG_THREADS:-}" ]] && threads=(--threads "$EXRFOG_THREADS")
floor_i=-1
if [[ -x "$build/floor" ]]; then
    floor_i=${#names[@]}
    add_tool "floor (OpenEXRCore transcode, stock zlib)" \
        '"$build/floor" "${threads[@]}" --codec zlib "$IN" "$OUT"'
else
    note "bench/floor not built ($build/floor): no floor row (cmake --build $build --target floor)"
fi
if [[ -x "$exrfog" ]]; then
    add_tool "exrfog exp:density=0.02" '"$exrfog" "${threads[@]}" --fog exp:density=0.02 "$IN" -o "$OUT"'
    add_tool "exrfog exp:density=0.02 zip:1" \
        '"$exrfog" "${threads[@]}" --fog exp:density=0.02 --compression zip:1 "$IN" -o "$OUT"'
    add_tool "exrfog exp2 R,G,B + linear" \
        '"$exrfog" "${threads[@]}" --fog exp2:density=0.01,0.012,0.015 --fog linear:start=5:end=400 "$IN" -o "$OUT"'
    # The numpy peer's own fog, like for like: half-space y < 1, density 0.15,
    # colour 0.6,0.65,0.7, sky at the peer's 1e7 stand-in distance.
    add_tool "exrfog halfspace (the peer's fog)" \
        '"$exrfog" "${threads[@]}" --fog halfspace:plane=0,1,0,-1:density=0.15 --fog-color 0.6,0.65,0.7 --sky distance=1e7 "$IN" -o "$OUT"'
else
    echo "exrfog not built ($exrfog)"
    note "exrfog not built ($exrfog): no exrfog rows"
fi

peer="$shared/peers/numpy_halfspace_fog.py"
python=""
if [[ -z "$shared" || ! -f "$peer" ]]; then
    note "numpy peer not found at $(dirname "$0")/../../shared/peers/numpy_halfspace_fog.py: skipped"
else
    for py in ${PYTHON:-python3 /usr/bin/python3}; do
        if command -v "$py" >/dev/null 2>&1 && "$py" -c 'import OpenImageIO, numpy' >/dev/null 2>&1; then
            python="$(command -v "$py")"; break
        fi
    done
    if [[ -n "$python" ]]; then
        add_tool "numpy peer (halfspace)" '"$python" "$peer" "$IN" "$OUT"'
    else
        note "python3 with OpenImageIO + numpy not found (apt-get install -y python3-openimageio python3-numpy): numpy peer skipped"
    fi
fi

ntools=${#names[@]}

# --- measure --------------------------------------------------------------------
declare -A walls rss failed
run_one() {   # $1 tool index, $2 1 = record
    local i=$1 IN="$in" OUT="$tmp/out_$1.exr" log="$tmp/log_$1" tf="$tmp/time_$1" a b rc
    rm -f "$OUT"
    a=$EPOCHREALTIME
    if [[ -n "$timer" ]]; then
        eval "\"\$timer\" -f '%e %M' -o \"\$tf\" ${cmds[$i]}" >"$log" 2>&1; rc=$?
    else
        eval "${cmds[$i]}" >"$log" 2>&1; rc=$?
    fi
    b=$EPOCHREALTIME
    if (( rc != 0 )) || [[ ! -s "$OUT" ]]; then
        if [[ -z "${failed[$i]:-}" ]]; then
            echo "bench: '${names[$i]}' failed (exit $rc); last output:" >&2
            tail -n 5 "$log" | sed 's/^/    /' >&2
        fi
        failed[$i]=1
        return
    fi
    (( $2 )) || return 0
    walls[$i]+="$(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.4f", b - a }') "
    [[ -n "$timer" ]] && rss[$i]+="$(awk 'END { print $NF }' "$tf") "
}

for (( r = 0; r < warmup + runs; ++r )); do
    record=$(( r >= warmup ))
    if (( record )); then echo "bench: round $((r - warmup + 1))/$runs" >&2
    else echo "bench: warm-up round $((r + 1))/$warmup" >&2; fi
    for (( k = 0; k < ntools; ++k )); do run_one $(( (k + r) % ntools )) "$record"; done
done

median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{ v[NR] = $1 } END {
    if (NR == 0) exit; if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

med_wall=() med_rss=() nok=()
for (( i = 0; i < ntools; ++i )); do
    med_wall[i]="$(median <<<"${walls[$i]:-}")"
    med_rss[i]="$(median <<<"${rss[$i]:-}")"
    nok[i]=$(wc -w <<<"${walls[$i]:-}")
done

ratio() { [[ -n "$1" && -n "$2" ]] && awk -v a="$1" -v b="$2" 'BEGIN { if (b > 0) printf "%.2f×", a / b; else print "n/a" }' || echo "n/a"; }

cpu="$(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: *//')"
{
    echo "## exrfog benchmark"
    echo
    echo "- date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
    echo "- machine: $(nproc) CPUs, ${cpu:-unknown CPU}, $(uname -sr)"
    echo "- input: ${size} RGBA half + Z float, ZIP, made by make_sample ($(awk -v b="$in_bytes" 'BEGIN { printf "%.1f MB", b / 1e6 }'), rendered in ${gen_s} s)"
    echo "- runs: ${runs} timed (+${warmup} warm-up), interleaved, tool order rotated each round; medians"
    echo "- oiiotool $(oiiotool --version 2>/dev/null)${python:+; peer interpreter $python}${EXRFOG_THREADS:+; exrfog --threads $EXRFOG_THREADS}"
    echo
    echo "| tool | median wall s | wall / oiiotool | wall / floor | median peak RSS MB | RSS / oiiotool | ok runs |"
    echo "|---|---:|---:|---:|---:|---:|---:|"
    for (( i = 0; i < ntools; ++i )); do
        if [[ -z "${med_wall[i]}" ]]; then
            echo "| ${names[i]} | failed | | | | | 0/$runs |"
            continue
        fi
        w=$(awk -v a="${med_wall[i]}" 'BEGIN { printf "%.3f", a }')
        if [[ -n "${med_rss[i]}" ]]; then m=$(awk -v a="${med_rss[i]}" 'BEGIN { printf "%.1f", a / 1024 }'); else m="n/a"; fi
        fl=""; (( floor_i >= 0 )) && fl="${med_wall[floor_i]}"
        echo "| ${names[i]} | $w | $(ratio "${med_wall[i]}" "${med_wall[0]}") | $(ratio "${med_wall[i]}" "$fl") | $m | $(ratio "${med_rss[i]}" "${med_rss[0]}") | ${nok[i]}/$runs |"
    done
    if (( ${#notes[@]} )); then
        echo
        for n in "${notes[@]}"; do echo "- note: $n"; done
    fi
} > "$tmp/table.md"

cat "$tmp/table.md"
cp "$tmp/table.md" "$here/results.md" || die "could not write $here/results.md"
echo "bench: table written to $here/results.md" >&2
