#!/usr/bin/env bash
# shellcheck disable=SC2016,SC2034  # tool command lines are stored single-quoted and eval'd
# bench/models.sh - per-model throughput and accuracy of exrfog on a 1920x1080 frame.
#
# usage: bench/models.sh [BUILD_DIR]     (default: <repo>/build; a Release build:
#        cmake -S . -B build-bench -DCMAKE_BUILD_TYPE=Release && cmake --build build-bench -j2)
#
# Renders the same 1920x1080 RGBA half + Z float ZIP frame as bench/run.sh (make_sample),
# then
#   1. runs BUILD_DIR/model_bench on it: for every model (the list lives in
#      bench/model_bench.c; `model_bench --list` prints it) the fog pass alone
#      (ef_fog_block over the whole frame, one thread, best / median of
#      MODEL_BENCH_RUNS runs) in Mpixel/s, and the max |dT| and max relative
#      tau error of the closed forms against the reference integrator on every
#      8th pixel each way (surface segments and rays to infinity);
#   2. times end to end, in BENCH_RUNS interleaved rounds (tool order rotated each
#      round, medians), `oiiotool IN -o OUT`, the transcode floor (BUILD_DIR/floor
#      --codec zlib: OpenEXRCore alone decoding and re-encoding every chunk on the
#      same threads, see bench/floor.sh) and `exrfog --fog SPEC IN -o OUT` for
#      every model;
# and prints a Markdown table, also written to bench/models.md (whose sections
# after the table, from its first "### " heading on, are kept). Nothing asserts on time.
#
# Environment:
#   BENCH_RUNS=7          timed end-to-end rounds
#   BENCH_WARMUP=1        untimed rounds first
#   MODEL_BENCH_RUNS=5    timed fog passes per model in model_bench
#   BENCH_SIZE=1920x1080
#   EXRFOG_THREADS=N      pass --threads N to exrfog (default: every core)
#   MAKE_SAMPLE=path      make_sample binary (else BUILD_DIR/make_sample)
set -uo pipefail

die() { echo "models: $*" >&2; exit 1; }

here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
build="${1:-$repo/build}"
[[ -d "$build" ]] || die "no build directory $build"
build="$(cd "$build" && pwd)"
runs="${BENCH_RUNS:-7}"
warmup="${BENCH_WARMUP:-1}"
mb_runs="${MODEL_BENCH_RUNS:-5}"
size="${BENCH_SIZE:-1920x1080}"
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || die "BENCH_RUNS must be a positive integer"
[[ "$warmup" =~ ^[0-9]+$ ]] || die "BENCH_WARMUP must be a non-negative integer"
[[ "$mb_runs" =~ ^[1-9][0-9]*$ ]] || die "MODEL_BENCH_RUNS must be a positive integer"
[[ "$size" =~ ^[1-9][0-9]*x[1-9][0-9]*$ ]] || die "BENCH_SIZE must be WxH"

exrfog="$build/exrfog"
model_bench="$build/model_bench"
floor="$build/floor"
make_sample="${MAKE_SAMPLE:-$build/make_sample}"
for b in "$exrfog" "$model_bench" "$floor" "$make_sample"; do
    [[ -x "$b" ]] || die "$b not built (cmake --build $build)"
done
command -v oiiotool >/dev/null 2>&1 || die "oiiotool not found (apt-get install -y openimageio-tools)"
build_type="$(sed -n 's/^CMAKE_BUILD_TYPE:[A-Z]*=//p' "$build/CMakeCache.txt" 2>/dev/null)"

tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-models.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT

# --- the input frame (as bench/run.sh) ---------------------------------------
in="$tmp/frame.exr"
echo "models: rendering $size frame with $make_sample ..." >&2
"$make_sample" "$in" --size "$size" --compression zip >&2 || die "make_sample failed"
in_bytes=$(stat -c %s "$in")

# --- 1. fog pass and accuracy per model ----------------------------------------
echo "models: model_bench (fog pass, 1 thread, $mb_runs runs per model; reference check) ..." >&2
"$model_bench" "$in" --tsv --runs "$mb_runs" >"$tmp/mb.tsv" || die "model_bench failed"

# --- 2. end to end ----------------------------------------------------------------
names=() specs=() cmds=()
names+=("oiiotool (copy)"); specs+=(""); cmds+=('oiiotool "$IN" -o "$OUT"')
threads=()
[[ -n "${EXRFOG_THREADS:-}" ]] && threads=(--threads "$EXRFOG_THREADS")
names+=("floor (stock zlib)"); specs+=("")
cmds+=('"$floor" "${threads[@]}" --codec zlib "$IN" "$OUT"')
first_model=${#names[@]}
while IFS=$'\t' read -r name spec _; do
    names+=("$name"); specs+=("$spec")
    c='"$exrfog" "${threads[@]}"'
    read -ra parts <<<"$spec"
    for s in "${parts[@]}"; do c+=" --fog '$s'"; done
    cmds+=("$c"' "$IN" -o "$OUT"')
done < <("$model_bench" --list)
ntools=${#names[@]}

declare -A walls failed
run_one() {   # $1 tool index, $2 1 = record
    local i=$1 IN="$in" OUT="$tmp/out_$1.exr" log="$tmp/log_$1" a b rc
    rm -f "$OUT"
    a=$EPOCHREALTIME
    eval "${cmds[$i]}" >"$log" 2>&1; rc=$?
    b=$EPOCHREALTIME
    if (( rc != 0 )) || [[ ! -s "$OUT" ]]; then
        if [[ -z "${failed[$i]:-}" ]]; then
            echo "models: '${names[$i]}' failed (exit $rc); last output:" >&2
            tail -n 5 "$log" | sed 's/^/    /' >&2
        fi
        failed[$i]=1
        return
    fi
    (( $2 )) || return 0
    walls[$i]+="$(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.4f", b - a }') "
}

for (( r = 0; r < warmup + runs; ++r )); do
    record=$(( r >= warmup ))
    if (( record )); then echo "models: round $((r - warmup + 1))/$runs" >&2
    else echo "models: warm-up round $((r + 1))/$warmup" >&2; fi
    for (( k = 0; k < ntools; ++k )); do run_one $(( (k + r) % ntools )) "$record"; done
done

median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{ v[NR] = $1 } END {
    if (NR == 0) exit; if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

med=()
for (( i = 0; i < ntools; ++i )); do med[i]="$(median <<<"${walls[$i]:-}")"; done

fmt_spec() { local out="" s parts; read -ra parts <<<"$1"
    for s in "${parts[@]}"; do out+="${out:+ }\`$s\`"; done; echo "$out"; }

tdesc="its default of one thread per core ($(nproc))"
[[ -n "${EXRFOG_THREADS:-}" ]] && tdesc="--threads $EXRFOG_THREADS"
cpu="$(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: *//')"
{
    echo "## exrfog per-model benchmark"
    echo
    echo "- date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
    echo "- machine: $(nproc) CPUs, ${cpu:-unknown CPU}, $(uname -sr)"
    echo "- build: ${build_type:-unknown} ($build)"
    echo "- input: ${size} RGBA half + Z float, ZIP, made by make_sample ($(awk -v b="$in_bytes" 'BEGIN { printf "%.1f MB", b / 1e6 }'))"
    echo "- fog pass: \`ef_fog_block\` over the whole frame on 1 thread, best / median of ${mb_runs} runs (bench/model_bench.c)"
    echo "- end to end: \`exrfog --fog SPEC IN -o OUT\` with $tdesc, \`oiiotool IN -o OUT\` and the transcode floor (\`bench/floor --codec zlib IN OUT\`, the same threads), ${runs} timed rounds (+${warmup} warm-up), interleaved, order rotated each round; medians of wall time"
    echo "- accuracy: closed-form tau (summed over components) against the reference integrator (\`ef_ref_tau\`; for exp, the same integrator on its constant density) on every 8th pixel each way, surface segment and ray to infinity; T = exp(-tau) per channel"
    echo "- oiiotool $(oiiotool --version 2>/dev/null)"
    echo
    echo "| model | SPEC | fog pass Mpixel/s (1 thread, best / median) | end-to-end s | / oiiotool | / floor | max \\|dT\\| | max rel tau error |"
    echo "|---|---|---:|---:|---:|---:|---:|---:|"
    o="${med[0]}" f="${med[1]}"
    over() { [[ -n "$2" ]] && awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f×", a / b }' || echo "n/a"; }
    for (( i = 0; i < first_model; ++i )); do
        if [[ -n "${med[i]}" ]]; then
            echo "| ${names[i]} | | | $(awk -v a="${med[i]}" 'BEGIN { printf "%.3f", a }') | $(over "${med[i]}" "$o") | $(over "${med[i]}" "$f") | | |"
        else
            echo "| ${names[i]} | | | failed | | | | |"
        fi
    done
    for (( i = first_model; i < ntools; ++i )); do
        line="$(awk -F'\t' -v n="${names[i]}" '$1 == n' "$tmp/mb.tsv")"
        IFS=$'\t' read -r _ _ best medp dT rel _ <<<"$line"
        if [[ -n "${med[i]}" ]]; then
            e2e=$(awk -v a="${med[i]}" 'BEGIN { printf "%.3f", a }')
            ratio="$(over "${med[i]}" "$o") | $(over "${med[i]}" "$f")"
        else
            e2e="failed"; ratio=" | "
        fi
        if [[ -n "$line" ]]; then
            pass=$(awk -v a="$best" -v b="$medp" 'BEGIN { printf "%.1f / %.1f", a, b }')
        else
            pass="failed"; dT=""; rel=""
        fi
        echo "| ${names[i]} | $(fmt_spec "${specs[i]}") | $pass | $e2e | $ratio | $dT | $rel |"
    done
} > "$tmp/table.md"

cat "$tmp/table.md"
# Keep the history sections of the previous file (from its first "### " on).
if [[ -f "$here/models.md" ]]; then
    awk '/^### / { keep = 1 } keep' "$here/models.md" > "$tmp/history.md"
    if [[ -s "$tmp/history.md" ]]; then echo >> "$tmp/table.md"; cat "$tmp/history.md" >> "$tmp/table.md"; fi
fi
cp "$tmp/table.md" "$here/models.md" || die "could not write $here/models.md"
echo "models: table written to $here/models.md" >&2
