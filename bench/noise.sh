#!/usr/bin/env bash
# shellcheck disable=SC2016,SC2034  # tool command lines are stored single-quoted and eval'd
# bench/noise.sh - the speed/accuracy trade of exrfog's noise fog on a 1920x1080 frame.
#
# usage: bench/noise.sh [BUILD_DIR]      (default: <repo>/build; a Release build:
#        cmake -S . -B build-bench -DCMAKE_BUILD_TYPE=Release -DEXRFOG_TESTS=OFF
#        cmake --build build-bench -j2 && bench/noise.sh build-bench)
#
# Renders the 1920x1080 RGBA half + Z float ZIP frame of bench/run.sh (make_sample),
# then
#   1. runs BUILD_DIR/noise_bench on it (the entries live in bench/noise_bench.c;
#      `noise_bench --list` prints them): per method and tolerance the fog pass
#      alone on one thread (Mpixel/s, seconds per frame, noise evaluations per
#      pixel) and, on every 8th pixel each way, max and 99.9th-percentile |dT|
#      against the reference integrator (noise-separable preintegrated: against
#      its own method=exact tau) and the share of pixels whose error output covers
#      the actual error;
#   2. times end to end `exrfog --fog SPEC IN -o OUT` (default threads) for every
#      timed entry, `oiiotool IN -o OUT` and the transcode floor (bench/floor
#      --codec zlib, same threads), interleaved, the order rotated each round,
#      medians. Slow entries run fewer rounds (at most E2E_BUDGET seconds
#      each, at least one run) and entries predicted above E2E_MAX seconds are not
#      run: their row shows the prediction (exp's end-to-end time plus the fog
#      pass over the threads), marked as such;
#   3. checks the targets of issue 7 against the measured values, plots max |dT|
#      against fog-pass time with gnuplot (bench/noise_trade.png) and writes the
#      tables to bench/noise.md.
# Nothing asserts on time; the targets are printed PASS or FAIL as measured.
#
# Environment:
#   BENCH_RUNS=5            end-to-end rounds (oiiotool, the floor and exp run in every round)
#   E2E_BUDGET=30           seconds of end-to-end runs per noise entry (>= 1 run)
#   E2E_MAX=60              entries predicted slower than this are not run end to end
#   NOISE_BENCH_RUNS=5      fog-pass runs per entry (fewer when over the budget)
#   NOISE_BENCH_BUDGET=10   seconds of fog-pass runs per entry
#   NOISE_BENCH_SAMPLE=8    1 in K pixels timed when the whole frame is over the budget
#   NOISE_BENCH_STEP=8      accuracy on every S-th pixel each way
#   EXRFOG_THREADS=N        pass --threads N to exrfog (default: one per core)
#   MAKE_SAMPLE=path        make_sample binary (else BUILD_DIR/make_sample)
set -uo pipefail

die() { echo "noise: $*" >&2; exit 1; }

here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
build="${1:-$repo/build}"
[[ -d "$build" ]] || die "no build directory $build"
build="$(cd "$build" && pwd)"
runs="${BENCH_RUNS:-5}"
e2e_budget="${E2E_BUDGET:-30}"
e2e_max="${E2E_MAX:-60}"
nb_runs="${NOISE_BENCH_RUNS:-5}"
nb_budget="${NOISE_BENCH_BUDGET:-10}"
nb_sample="${NOISE_BENCH_SAMPLE:-8}"
nb_step="${NOISE_BENCH_STEP:-8}"
size=1920x1080
for v in runs e2e_budget e2e_max nb_runs nb_budget nb_sample nb_step; do
    [[ "${!v}" =~ ^[1-9][0-9]*$ ]] || die "$v must be a positive integer (got '${!v}')"
done

exrfog="$build/exrfog"
noise_bench="$build/noise_bench"
floor="$build/floor"
make_sample="${MAKE_SAMPLE:-$build/make_sample}"
for b in "$exrfog" "$noise_bench" "$floor" "$make_sample"; do
    [[ -x "$b" ]] || die "$b not built (cmake --build $build)"
done
command -v oiiotool >/dev/null 2>&1 || die "oiiotool not found (apt-get install -y openimageio-tools)"
gnuplot=""
command -v gnuplot >/dev/null 2>&1 && gnuplot="$(command -v gnuplot)"
[[ -n "$gnuplot" ]] || echo "noise: gnuplot not found (apt-get install -y gnuplot-nox): no plot" >&2
build_type="$(sed -n 's/^CMAKE_BUILD_TYPE:[A-Z]*=//p' "$build/CMakeCache.txt" 2>/dev/null)"
src_dir="$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$build/CMakeCache.txt" 2>/dev/null)"
rev=""
if [[ -n "$src_dir" ]] && git -C "$src_dir" rev-parse --short HEAD >/dev/null 2>&1; then
    rev="$(git -C "$src_dir" rev-parse --short HEAD)"
    git -C "$src_dir" diff --quiet HEAD -- src 2>/dev/null || rev+=" with uncommitted changes in src/"
fi

tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-noise.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT
t_start=$EPOCHREALTIME
load_before="$(cut -d' ' -f1-3 /proc/loadavg)"

# --- the input frame (as bench/run.sh) -----------------------------------------
in="$tmp/frame.exr"
echo "noise: rendering $size frame with $make_sample ..." >&2
"$make_sample" "$in" --size "$size" --compression zip >&2 || die "make_sample failed"
in_bytes=$(stat -c %s "$in")

# --- 1. fog pass and accuracy ----------------------------------------------------
echo "noise: noise_bench (fog pass on 1 thread; accuracy on every ${nb_step}th pixel) ..." >&2
"$noise_bench" "$in" --tsv --runs "$nb_runs" --budget "$nb_budget" --sample "$nb_sample" \
    --step "$nb_step" >"$tmp/nb.tsv" || die "noise_bench failed"
t_nb=$EPOCHREALTIME

# Columns: family name spec timed sample runs mpix_best mpix_median frame_s evals_px
#          max_dT p999_dT covered surface_px sky_px max_dtau
declare -A F_fam F_spec F_timed F_sample F_runs F_mpix F_frame F_evals F_max F_p999 F_cov F_npx F_tau
order=()
while IFS=$'\t' read -r fam name spec timed sample nruns _best mpix frame evals mx p999 cov npx _sky mtau; do
    F_tau[$name]=$mtau
    order+=("$name")
    F_fam[$name]=$fam; F_spec[$name]=$spec; F_timed[$name]=$timed; F_sample[$name]=$sample
    F_runs[$name]=$nruns; F_mpix[$name]=$mpix; F_frame[$name]=$frame; F_evals[$name]=$evals
    F_max[$name]=$mx; F_p999[$name]=$p999; F_cov[$name]=$cov; F_npx[$name]=$npx
done <"$tmp/nb.tsv"
(( ${#order[@]} )) || die "noise_bench printed nothing"

# --- 2. end to end -----------------------------------------------------------------
threads=()
nthreads=$(nproc)
if [[ -n "${EXRFOG_THREADS:-}" ]]; then threads=(--threads "$EXRFOG_THREADS"); nthreads=$EXRFOG_THREADS; fi
names=("oiiotool (copy)" "floor (stock zlib)")
cmds=('oiiotool "$IN" -o "$OUT"' '"$floor" "${threads[@]}" --codec zlib "$IN" "$OUT"')
for name in "${order[@]}"; do
    (( F_timed[$name] )) || continue
    names+=("$name")
    cmds+=('"$exrfog" "${threads[@]}" --fog '"'${F_spec[$name]}'"' "$IN" -o "$OUT"')
done
ntools=${#names[@]}
exp_i=-1
for (( i = 0; i < ntools; ++i )); do [[ "${F_fam[${names[i]}]:-}" == baseline ]] && exp_i=$i; done
(( exp_i > 0 )) || die "no exp baseline entry in noise_bench --list"

declare -A walls failed
last=""
run_one() {   # $1 tool index, $2 1 = record; sets last (seconds) on success
    local i=$1 IN="$in" OUT="$tmp/out_$1.exr" log="$tmp/log_$1" a b rc
    rm -f "$OUT"
    last=""
    a=$EPOCHREALTIME
    eval "${cmds[$i]}" >"$log" 2>&1; rc=$?
    b=$EPOCHREALTIME
    if (( rc != 0 )) || [[ ! -s "$OUT" ]]; then
        if [[ -z "${failed[$i]:-}" ]]; then
            echo "noise: '${names[$i]}' failed (exit $rc); last output:" >&2
            tail -n 5 "$log" | sed 's/^/    /' >&2
        fi
        failed[$i]=1
        return
    fi
    last="$(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.4f", b - a }')"
    (( $2 )) && walls[$i]+="$last "
    return 0
}

# Warm-up (page cache, lazy loading): oiiotool, the floor and exp once,
# untimed. exp's time is the I/O part of the predictions.
echo "noise: end to end: warm-up" >&2
run_one 0 0
run_one 1 0
run_one "$exp_i" 0
io_s="${last:-0.5}"
nrun=() pred=()
for (( i = 0; i < ntools; ++i )); do
    name="${names[i]}"
    if (( i <= 1 || i == exp_i )); then nrun[i]=$runs; pred[i]=""; continue; fi
    pred[i]="$(awk -v io="$io_s" -v f="${F_frame[$name]}" -v t="$nthreads" 'BEGIN { printf "%.3f", io + f / t }')"
    nrun[i]="$(awk -v p="${pred[i]}" -v b="$e2e_budget" -v m="$e2e_max" -v r="$runs" 'BEGIN {
        if (p > m) { print 0; exit } n = int(b / p); if (n < 1) n = 1; if (n > r) n = r; print n }')"
done
for (( r = 0; r < runs; ++r )); do
    echo "noise: end to end: round $((r + 1))/$runs" >&2
    for (( k = 0; k < ntools; ++k )); do
        i=$(( (k + r) % ntools ))
        (( nrun[i] > r )) && run_one "$i" 1
    done
done
t_e2e=$EPOCHREALTIME
# The per-pixel work distribution of the two defaults, from --stats (the
# time line and the component's line), one run each on the same threads.
stats_lines=()
for name in "${order[@]}"; do
    case "${F_fam[$name]}" in horizon-adaptive) ;; adaptive) [[ "${F_spec[$name]}" == *method=* ]] && continue;; *) continue;; esac
    "$exrfog" "${threads[@]}" --stats --fog "${F_spec[$name]}" "$in" -o "$tmp/stats.exr" 2>"$tmp/stats.log" || continue
    stats_lines+=("| \`${F_spec[$name]}\` | $(grep -o 'time per pixel.*' "$tmp/stats.log" | sed 's/time per pixel (every component, one core): //') | $(grep -o 'noise evaluations mean [^,]*' "$tmp/stats.log" | sed 's/noise evaluations //') | $(grep -o 'over the work bound [0-9]* pixels' "$tmp/stats.log" | sed 's/over the work bound //') | $(grep -o '(|dT|, as --aov error) max [0-9.e+-]*' "$tmp/stats.log" | sed 's/.* max //') |")
done
load_after="$(cut -d' ' -f1-3 /proc/loadavg)"

median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{ v[NR] = $1 } END {
    if (NR == 0) exit; if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
declare -A E_med E_n E_pred
for (( i = 0; i < ntools; ++i )); do
    E_med[${names[i]}]="$(median <<<"${walls[$i]:-}")"
    E_n[${names[i]}]=$(wc -w <<<"${walls[$i]:-}")
    E_pred[${names[i]}]="${pred[i]}"
done
oiio="${E_med[oiiotool (copy)]}"
flo="${E_med[floor (stock zlib)]}"
expn="${names[exp_i]}"
exp_med="${E_med[$expn]}"
[[ -n "$oiio" && -n "$flo" && -n "$exp_med" ]] || die "oiiotool, the floor or exp failed end to end"

# --- formatting helpers ----------------------------------------------------------------
fnum() { awk -v v="$1" -v f="$2" 'BEGIN { if (v == "" || v == "-") print "–"; else printf f, v }'; }
e2e_cell() {   # name -> "s | / oiiotool | / floor | / exp"
    local n="$1" m="${E_med[$1]:-}" p="${E_pred[$1]:-}"
    if [[ -n "$m" ]]; then
        awk -v m="$m" -v o="$oiio" -v f="$flo" -v e="$exp_med" -v k="${E_n[$n]}" \
            'BEGIN { printf "%.2f (%d) | %.2f× | %.2f× | %.2f×", m, k, m / o, m / f, m / e }'
    elif [[ -n "$p" ]]; then
        awk -v m="$p" -v o="$oiio" -v f="$flo" -v e="$exp_med" \
            'BEGIN { printf "≈ %.0f (predicted, not run) | ≈ %.0f× | ≈ %.0f× | ≈ %.0f×", m, m / o, m / f, m / e }'
    else
        echo "failed | | | "
    fi
}
sci() { awk -v v="$1" 'BEGIN { if (v == "" || v == "-") print "–"; else if (v == 0) print "0"; else printf "%.1e", v }'; }
pct() { awk -v v="$1" 'BEGIN { if (v == "" || v == "-") print "–"; else printf "%.1f %%", 100 * v }'; }
timed_on() {   # "N runs, whole frame" or "N runs, 1 in K px"
    local n="${F_runs[$1]}" k="${F_sample[$1]}"
    printf '%s run%s, %s' "$n" "$( (( n == 1 )) || echo s)" "$( (( k == 1 )) && echo "whole frame" || echo "1 in $k px")"
}
label() {   # the short method label of an entry
    local s="${F_spec[$1]}"
    case "${F_fam[$1]}" in
        baseline) echo "exp (baseline)";;
        exact|separable-exact) echo "exact";;
        adaptive) if [[ "$s" == *tol=* ]]; then echo "adaptive tol=${s##*tol=}"; else echo "adaptive (default, ttol=2^-12)"; fi;;
        horizon-baseline) echo "exp (baseline)";;
        horizon-adaptive) echo "adaptive (default, ttol=2^-12)";;
        horizon-ttol) echo "adaptive ttol=${s##*ttol=}";;
        horizon-tol) echo "adaptive tol=2^-12 (the old default)";;
        horizon-exact) echo "exact";;
        horizon-steps) echo "steps=${s##*steps=}";;
        adaptive-ttol) echo "adaptive ttol=${s##*ttol=}";;
        steps) echo "steps=${s##*steps=}";;
        preintegrated) echo "preintegrated pieces=${s##*pieces=}";;
        *) echo "$1";;
    esac
}

# --- 3a. the trade: adaptive against steps at equal max |dT| ------------------------------
# Points: time = fog pass seconds per frame (1 thread), error = max |dT|.
: >"$tmp/adaptive.dat"; : >"$tmp/ttol.dat"; : >"$tmp/steps.dat"; : >"$tmp/exact.dat"; : >"$tmp/preint.dat"
: >"$tmp/h_adaptive.dat"; : >"$tmp/h_steps.dat"; : >"$tmp/h_other.dat"
: >"$tmp/adaptive.tau"; : >"$tmp/ttol.tau"; : >"$tmp/steps.tau"; : >"$tmp/exact.tau"; : >"$tmp/preint.tau"
for name in "${order[@]}"; do
    (( F_timed[$name] )) || continue
    case "${F_fam[$name]}" in
        adaptive) f=adaptive; l="${F_spec[$name]}"; [[ "$l" == *tol=* ]] && l="${l##*tol=}" || l="2^{-12}";;
        adaptive-ttol) f=ttol; l="${F_spec[$name]##*ttol=}";;
        steps) f=steps; l="${F_spec[$name]##*steps=}";;
        exact) f=exact; l="exact";;
        preintegrated) f=preint; l="${F_spec[$name]##*pieces=}";;
        horizon-adaptive) f=h_adaptive; l="default";;
        horizon-ttol) f=h_adaptive; l="ttol=${F_spec[$name]##*ttol=}";;
        horizon-steps) f=h_steps; l="${F_spec[$name]##*steps=}";;
        horizon-exact) f=h_other; l="exact";;
        horizon-tol) f=h_other; l="tol=2^{-12}";;
        *) continue;;
    esac
    printf '%s\t%s\t%s\n' "${F_frame[$name]}" "${F_max[$name]}" "$l" >>"$tmp/$f.dat"
    printf '%s\t%s\t%s\n' "${F_frame[$name]}" "${F_tau[$name]}" "$l" >>"$tmp/$f.tau"
done
sort -g -k2,2 "$tmp/adaptive.tau" >"$tmp/adaptive.bytau"
sort -g -k2,2 "$tmp/steps.tau" >"$tmp/steps.bytau"
sort -g -k2,2 "$tmp/adaptive.dat" >"$tmp/adaptive.byerr"
sort -g -k2,2 "$tmp/ttol.dat" >"$tmp/ttol.byerr"
sort -g -k2,2 "$tmp/steps.dat" >"$tmp/steps.byerr"

# interp FILE E: log-log interpolation of time at error E along the points of FILE
# (sorted by error); prints "time how", how = "between A and B", "extrapolated" or "".
interp_awk='
    { t[NR] = $1; e[NR] = $2; l[NR] = $3 }
    END {
        n = NR; if (n == 0) exit
        for (i = 1; i < n; ++i)
            if (E >= e[i] && E <= e[i + 1]) {
                f = (log(E) - log(e[i])) / (log(e[i + 1]) - log(e[i]))
                printf "%.6g\tbetween %s and %s\n", exp(log(t[i]) + f * (log(t[i + 1]) - log(t[i]))), l[i], l[i + 1]
                exit
            }
        if (ext && n >= 2) {   # beyond either end: the slope of the two nearest points
            i = E < e[1] ? 1 : n - 1
            f = (log(E) - log(e[i])) / (log(e[i + 1]) - log(e[i]))
            printf "%.6g\textrapolated from %s and %s\n", exp(log(t[i]) + f * (log(t[i + 1]) - log(t[i]))), l[i], l[i + 1]
        }
    }'
plain() { local x="${1//\{/}"; echo "${x//\}/}"; }   # 2^{-12} -> 2^-12 (gnuplot's markup out)
interp() { awk -F'\t' -v E="$2" -v ext="${3:-0}" "$interp_awk" "$1"; }

# trade FAM KEY: rows of steps against adaptive family FAM (adaptive: tol=, ttol: ttol=)
# at equal max |dT| into trade_rows; the smallest speed-up into min_speedup.
trade() {
    local fam="$1" key="$2" ts es ls res ta how sp amin loose tl ll
    trade_rows=() min_speedup="" n_cmp=0
    [[ -s "$tmp/$fam.byerr" ]] || return 0
    while IFS=$'\t' read -r ts es ls; do
        res="$(interp "$tmp/$fam.byerr" "$es")"
        if [[ -n "$res" ]]; then
            ta="${res%%$'\t'*}"; how="${res#*$'\t'}"
            sp="$(awk -v a="$ts" -v b="$ta" 'BEGIN { printf "%.1f", a / b }')"
            trade_rows+=("| steps=$ls | $(sci "$es") | $(fnum "$ts" %.1f) | $(fnum "$ta" %.2f) (adaptive $key $(plain "$how")) | **${sp}×** |")
            n_cmp=$((n_cmp + 1))
            min_speedup="$(awk -v a="$sp" -v m="$min_speedup" 'BEGIN { print (m == "" || a < m) ? a : m }')"
        else
            amin="$(head -n1 "$tmp/$fam.byerr" | cut -f2)"
            if awk -v e="$es" -v a="$amin" 'BEGIN { exit !(e < a) }'; then
                trade_rows+=("| steps=$ls | $(sci "$es") | $(fnum "$ts" %.1f) | more accurate than every adaptive $key point | not compared |")
            else
                # Steps is less accurate than the loosest adaptive tolerance measured.
                loose="$(tail -n1 "$tmp/$fam.byerr")"
                tl="$(cut -f1 <<<"$loose")"; ll="$(cut -f3 <<<"$loose")"
                sp="$(awk -v a="$ts" -v b="$tl" 'BEGIN { printf "%.1f", a / b }')"
                trade_rows+=("| steps=$ls | $(sci "$es") | $(fnum "$ts" %.1f) | $(fnum "$tl" %.2f) ($key=$(plain "$ll"), already more accurate) | ${sp}× (adaptive also more accurate) |")
            fi
        fi
    done <"$tmp/steps.byerr"
}
trade ttol ttol
ttol_rows=("${trade_rows[@]}") ttol_speedup="$min_speedup" ttol_cmp=$n_cmp
trade adaptive tol
# The other direction: steps' time at each adaptive point's error.
rev_rows=()
while IFS=$'\t' read -r ta ea la; do
    res="$(interp "$tmp/steps.byerr" "$ea" 1)"
    [[ -n "$res" ]] || continue
    tsi="${res%%$'\t'*}"; how="${res#*$'\t'}"
    sp="$(awk -v a="$tsi" -v b="$ta" 'BEGIN { printf "%.1f", a / b }')"
    rev_rows+=("| adaptive tol=$(plain "$la") | $(sci "$ea") | $(fnum "$ta" %.2f) | $(fnum "$tsi" %.1f) (steps $how) | ${sp}× |")
done <"$tmp/adaptive.byerr"

# The same at equal max |dtau|, the quantity tol= bounds on every ray (informative: the
# target above is on |dT|, where rays with small T hide steps' larger tau errors).
tau_rows=()
while IFS=$'\t' read -r ts es ls; do
    res="$(interp "$tmp/adaptive.bytau" "$es")"
    if [[ -n "$res" ]]; then
        ta="${res%%$'\t'*}"; how="${res#*$'\t'}"
        sp="$(awk -v a="$ts" -v b="$ta" 'BEGIN { printf "%.1f", a / b }')"
        tau_rows+=("| steps=$ls | $(sci "$es") | $(fnum "$ts" %.1f) | $(fnum "$ta" %.2f) (adaptive tol $(plain "$how")) | ${sp}× |")
    elif awk -v e="$es" -v a="$(tail -n1 "$tmp/adaptive.bytau" | cut -f2)" 'BEGIN { exit !(e > a) }'; then
        loose="$(tail -n1 "$tmp/adaptive.bytau")"
        tl="$(cut -f1 <<<"$loose")"; el="$(cut -f2 <<<"$loose")"; ll="$(cut -f3 <<<"$loose")"
        sp="$(awk -v a="$ts" -v b="$tl" 'BEGIN { printf "%.1f", a / b }')"
        tau_rows+=("| steps=$ls | $(sci "$es") | $(fnum "$ts" %.1f) | $(fnum "$tl" %.2f) (tol=$(plain "$ll"), max \\|Δτ\\| $(sci "$el"): already more accurate) | ${sp}× (adaptive also more accurate) |")
    fi
done <"$tmp/steps.bytau"

# --- 3b. targets ----------------------------------------------------------------------------
def_name="" p1_name=""
for name in "${order[@]}"; do
    [[ "${F_fam[$name]}" == adaptive && "${F_spec[$name]}" != *method=* ]] && def_name="$name"
    [[ "${F_fam[$name]}" == preintegrated && "${F_spec[$name]}" == *pieces=1 ]] && p1_name="$name"
done
verdict() { awk -v v="$1" -v lim="$2" -v op="$3" 'BEGIN {
    if (v == "") { print "NOT MEASURED"; exit }
    ok = op == "le" ? v <= lim : v >= lim; print ok ? "PASS" : "FAIL" }'; }
t1_val="" t3_val=""
[[ -n "$def_name" && -n "${E_med[$def_name]:-}" ]] && t1_val="$(awk -v a="${E_med[$def_name]}" -v b="$oiio" 'BEGIN { printf "%.2f", a / b }')"
[[ -n "$p1_name" && -n "${E_med[$p1_name]:-}" ]] && t3_val="$(awk -v a="${E_med[$p1_name]}" -v b="$exp_med" 'BEGIN { printf "%.2f", a / b }')"
t1="$(verdict "$t1_val" 10 le)"
# The target is on max |dT|: the faster of the two ways adaptive takes a
# tolerance (both are printed).
best_speedup="$(awk -v a="$min_speedup" -v b="$ttol_speedup" 'BEGIN { if (a == "") print b; else if (b == "") print a; else print (a > b ? a : b) }')"
t2="$(verdict "$best_speedup" 5 ge)"
t3="$(verdict "$t3_val" 1.3 le)"

# --- 3c. the plot ---------------------------------------------------------------------------------
plot_note=""
if [[ -n "$gnuplot" ]]; then
    cpu_short="$(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: *//' | cut -c1-40)"
    term="pngcairo size 1000,720 font 'DejaVu Sans,11'"
    "$gnuplot" -e 'set terminal' 2>/dev/null | grep -q pngcairo || term="png size 1000,720"
    cat >"$tmp/plot.gp" <<EOF
set terminal $term
set output '$tmp/noise_trade.png'
set title "exrfog noise fog on the 1920x1080 sample (4 octaves at scale 10; dashed: the horizon scene, sky included):\nmax |ΔT| against fog-pass time (1 thread, ${cpu_short:-unknown CPU}, $(date -u '+%Y-%m-%d'))"
set logscale xy
set format y "10^{%L}"
set xlabel "fog pass, seconds per frame on 1 thread (log)"
set ylabel "max |ΔT| over the surface pixels checked (log)"
set grid xtics ytics mxtics mytics lc rgb '#dddddd'
set key right center box opaque spacing 1.2
set arrow from graph 0, first 2**-11 to graph 1, first 2**-11 nohead dt 2 lc rgb '#888888'
set label "half-float step just below T = 1 (2^{-11})" at graph 0.98, first 2**-11 right offset 0,0.7 tc rgb '#666666' font ',9'
plot '$tmp/adaptive.dat' using 1:2 with linespoints pt 7 ps 1.3 lw 2 lc rgb '#1f77b4' title 'noise adaptive (tol: error of τ)', \\
     '' using 1:2:3 with labels offset 1.2,0.8 font ',9' tc rgb '#1f77b4' notitle, \\
     '$tmp/ttol.dat' using 1:2 with linespoints pt 11 ps 1.3 lw 2 lc rgb '#ff7f0e' title 'noise adaptive (ttol: error of T)', \\
     '' using 1:2:3 with labels offset -1.5,-0.8 font ',9' tc rgb '#ff7f0e' notitle, \\
     '$tmp/steps.dat' using 1:2 with linespoints pt 5 ps 1.2 lw 2 lc rgb '#d62728' title 'noise steps (N)', \\
     '' using 1:2:3 with labels offset 1.2,-0.8 font ',9' tc rgb '#d62728' notitle, \\
     '$tmp/exact.dat' using 1:2 with points pt 9 ps 2 lc rgb '#2ca02c' title 'noise exact', \\
     '$tmp/preint.dat' using 1:2 with linespoints pt 13 ps 1.3 lw 2 lc rgb '#9467bd' title 'noise-separable preintegrated (pieces; vs its exact τ)', \\
     '' using 1:2:3 with labels offset 0,1.1 font ',9' tc rgb '#9467bd' notitle, \\
     '<sort -g $tmp/h_adaptive.dat' using 1:2 with linespoints pt 6 ps 1.4 lw 2 dt 2 lc rgb '#17becf' title 'horizon scene: adaptive (default, ttol)', \\
     '' using 1:2:3 with labels offset 1.5,0.8 font ',9' tc rgb '#17becf' notitle, \\
     '$tmp/h_steps.dat' using 1:2 with linespoints pt 4 ps 1.2 lw 2 dt 2 lc rgb '#8c564b' title 'horizon scene: steps (N)', \\
     '' using 1:2:3 with labels offset 1.2,-0.8 font ',9' tc rgb '#8c564b' notitle, \\
     '$tmp/h_other.dat' using 1:2 with points pt 8 ps 1.6 lc rgb '#7f7f7f' title 'horizon scene: exact, tol=2^{-12}', \\
     '' using 1:2:3 with labels offset 0,1.1 font ',9' tc rgb '#7f7f7f' notitle
EOF
    if "$gnuplot" "$tmp/plot.gp" 2>"$tmp/gnuplot.log" && [[ -s "$tmp/noise_trade.png" ]]; then
        cp "$tmp/noise_trade.png" "$here/noise_trade.png" || die "could not write $here/noise_trade.png"
    else
        plot_note="gnuplot failed: $(head -c 300 "$tmp/gnuplot.log")"
        echo "noise: $plot_note" >&2
    fi
else
    plot_note="gnuplot not found: plot not made"
fi

# --- 3d. the report ---------------------------------------------------------------------------------
t_end=$EPOCHREALTIME
cpu="$(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: *//')"
tdesc="its default of one thread per core ($(nproc))"
[[ -n "${EXRFOG_THREADS:-}" ]] && tdesc="--threads $EXRFOG_THREADS"
mins() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f min", (b - a) / 60 }'; }
{
    echo "## exrfog noise fog: the speed/accuracy trade"
    echo
    echo "- date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
    echo "- machine: $(nproc) CPUs, ${cpu:-unknown CPU}, $(uname -sr); load average $load_before before, $load_after after"
    echo "- build: ${build_type:-unknown} ($build)${rev:+, source $rev}"
    echo "- input: ${size} RGBA half + Z float, ZIP, made by make_sample ($(awk -v b="$in_bytes" 'BEGIN { printf "%.1f MB", b / 1e6 }')); y-up, camera at y = 1.7 looking down -z, objects from z = -5 to -180, ground plane to the horizon"
    echo "- fog pass: \`ef_fog_block\` on 1 thread (bench/noise_bench.c), median of up to ${nb_runs} runs within ${nb_budget} s per entry, the entries interleaved (one run of each per round); the whole frame when that fits, else 1 in ${nb_sample} pixels: in every row one span of 1/${nb_sample} of the width, shifted from row to row, so every row and every stretch of columns is represented (the runs and the sample are in the last column of the tables); s/frame = that rate over the 2,073,600 pixels"
    echo "- evals/px: noise evaluations (one octave at one point) per pixel, mean over the accuracy grid, sky included (as \`--stats\` counts them)"
    echo "- end to end: \`exrfog --fog SPEC IN -o OUT\` with $tdesc, \`oiiotool IN -o OUT\` and the transcode floor (\`bench/floor --codec zlib IN OUT\`, OpenEXRCore alone decoding and re-encoding every chunk on the same threads) in the same run, interleaved, order rotated each round, ${runs} rounds after a warm-up of oiiotool, the floor and exp; noise entries run at most ${e2e_budget} s each (at least once; the count is in brackets) and entries predicted above ${e2e_max} s (exp's time plus the fog pass over the threads) are not run; medians of wall time"
    echo "- accuracy: every ${nb_step}th pixel each way, surface pixels only (${F_npx[${order[1]}]:-?} of them; sky pixels are tau = inf for every noise method and the reference, since the noise model here has no falloff); |ΔT| = |e^-τ − e^-τref| in long double, max over channels; τref from the reference integrator (\`ef_ref_tau\`, Gauss–Kronrod split at every octave's lattice crossings); \"covers\" = share of those pixels where T·expm1(info.err) (the \`--aov error\` value) ≥ the actual |ΔT|"
    echo "- oiiotool $(oiiotool --version 2>/dev/null); run time $(mins "$t_start" "$t_end") (noise_bench $(mins "$t_start" "$t_nb"), end to end $(mins "$t_nb" "$t_e2e"))"
    echo
    echo "### noise (\`noise:density=0.02:scale=10:octaves=4\`, contrast 0.9, no falloff)"
    echo
    echo "| method | fog pass Mpixel/s (1 thread) | fog pass s/frame | evals/px | end-to-end s (runs) | / oiiotool | / floor | / exp | max \\|ΔT\\| | 99.9th \\|ΔT\\| | error output covers | fog pass timed on |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    echo "| oiiotool (copy) | | | | $(e2e_cell "oiiotool (copy)") | | | | |"
    echo "| floor (\`bench/floor --codec zlib\`, OpenEXRCore alone) | | | | $(e2e_cell "floor (stock zlib)") | | | | |"
    for name in "${order[@]}"; do
        case "${F_fam[$name]}" in baseline|exact|adaptive|adaptive-ttol|steps) ;; *) continue;; esac
        if [[ "${F_fam[$name]}" == baseline ]]; then
            echo "| $(label "$name") \`${F_spec[$name]}\` | $(fnum "${F_mpix[$name]}" %.2f) | $(fnum "${F_frame[$name]}" %.3f) | 0 | $(e2e_cell "$name") | – | – | – | $(timed_on "$name") |"
            continue
        fi
        echo "| $(label "$name") | $(fnum "${F_mpix[$name]}" %.3f) | $(fnum "${F_frame[$name]}" %.1f) | $(fnum "${F_evals[$name]}" %.0f) | $(e2e_cell "$name") | $(sci "${F_max[$name]}") | $(sci "${F_p999[$name]}") | $(pct "${F_cov[$name]}") | $(timed_on "$name") |"
    done
    echo
    echo "### noise-separable (\`noise-separable:density=0.02:scale=10:octaves=4:axes=xz:falloff=0.05:contrast=0.9\`)"
    echo
    echo "Preintegrated against the same SPEC's \`method=exact\` τ (the seed's approximation error); exact against the reference integrator. Sky pixels are left out: on a sky ray the envelope lets the fog end only far away, and a few degrees above the horizon \`method=exact\` walks the cells of kilometres of ray (2.5 s for one pixel 0.05 rad up, over a minute 0.01 rad up), so exact is a yardstick here and not timed."
    echo
    echo "| method | fog pass Mpixel/s (1 thread) | fog pass s/frame | evals/px | end-to-end s (runs) | / oiiotool | / floor | / exp | max \\|ΔT\\| | 99.9th \\|ΔT\\| | error output covers | fog pass timed on |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    for name in "${order[@]}"; do
        case "${F_fam[$name]}" in
            separable-exact)
                echo "| exact (vs the reference) | not timed | | | | | | | $(sci "${F_max[$name]}") | $(sci "${F_p999[$name]}") | $(pct "${F_cov[$name]}") | |";;
            preintegrated)
                echo "| $(label "$name") | $(fnum "${F_mpix[$name]}" %.3f) | $(fnum "${F_frame[$name]}" %.1f) | $(fnum "${F_evals[$name]}" %.0f) | $(e2e_cell "$name") | $(sci "${F_max[$name]}") | $(sci "${F_p999[$name]}") | $(pct "${F_cov[$name]}") | $(timed_on "$name") |";;
        esac
    done
    echo
    echo "### Adaptive against steps at equal max |ΔT|"
    echo
    echo "Time is the fog pass in seconds per frame on one thread. For each steps point, the adaptive time at the same max |ΔT| is interpolated log-log between the two adaptive tolerances whose measured max |ΔT| bracket it (the adaptive points sorted by error); the speed-up is the ratio."
    echo
    echo "| steps | max \\|ΔT\\| | steps s/frame | adaptive s/frame at that error | adaptive speed-up |"
    echo "|---|---:|---:|---:|---:|"
    for row in "${trade_rows[@]}"; do echo "$row"; done
    echo
    if (( ${#ttol_rows[@]} )); then
        echo "The same with \`ttol=\` (adaptive bounding |ΔT| itself, the error measured here, instead of |Δτ|: rays through dense fog, where T is small, get a larger τ budget and drop their fine octaves):"
        echo
        echo "| steps | max \\|ΔT\\| | steps s/frame | adaptive (ttol) s/frame at that error | adaptive speed-up |"
        echo "|---|---:|---:|---:|---:|"
        for row in "${ttol_rows[@]}"; do echo "$row"; done
        echo
    fi
    echo "And the other way: steps' time at each adaptive point's max |ΔT| (interpolated log-log between the bracketing steps counts; below steps=1024's error, extrapolated along the last two steps points)."
    echo
    echo "| adaptive | max \\|ΔT\\| | adaptive s/frame | steps s/frame at that error | adaptive speed-up |"
    echo "|---|---:|---:|---:|---:|"
    for row in "${rev_rows[@]}"; do echo "$row"; done
    echo
    echo "At equal max |Δτ| instead (the error tol= bounds on every ray, compared where the reference τ < 60, short of the opaque cut; informative, the target is on |ΔT|): steps' largest τ errors sit on long rays, where T is small and |ΔT| hides them, while adaptive holds τ on every ray."
    echo
    echo "| steps | max \\|Δτ\\| | steps s/frame | adaptive s/frame at that error | adaptive speed-up |"
    echo "|---|---:|---:|---:|---:|"
    if (( ${#tau_rows[@]} )); then for row in "${tau_rows[@]}"; do echo "$row"; done; else echo "| – | | | no steps point inside the adaptive τ error range | |"; fi
    echo
    echo "### The horizon scene (\`$(sed -n 's/^#define HORIZON \"\(.*\)\"$/\1/p' "$here/noise_bench.c")\`)"
    echo
    echo "Ground fog that thins with height, unbounded (issue 21): sky rays leave it after hundreds to thousands of units, the far ground is kilometres away. Accuracy against the reference integrated chunk by chunk along the whole ray (\`ef_ref_tau_long\`), on every 32nd pixel each way, **sky pixels included** ($(fnum "${F_npx[horizon: exact]:-}" %.0f) pixels). The error output of \`exact\` is at the 1e-13 level, where the chunked reference's own rounding (its start points rounded to double, ~1e-16 of kilometres) decides \"covers\": its max |ΔT| is what certifies it."
    echo
    echo "| method | fog pass Mpixel/s (1 thread) | fog pass s/frame | evals/px | end-to-end s (runs) | / oiiotool | / floor | / exp | max \\|ΔT\\| | 99.9th \\|ΔT\\| | error output covers | fog pass timed on |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    for name in "${order[@]}"; do
        case "${F_fam[$name]}" in
            horizon-baseline)
                echo "| $(label "$name") \`${F_spec[$name]}\` | $(fnum "${F_mpix[$name]}" %.2f) | $(fnum "${F_frame[$name]}" %.3f) | 0 | $(e2e_cell "$name") | – | – | – | $(timed_on "$name") |";;
            horizon-*)
                echo "| $(label "$name") | $(fnum "${F_mpix[$name]}" %.3f) | $(fnum "${F_frame[$name]}" %.1f) | $(fnum "${F_evals[$name]}" %.0f) | $(e2e_cell "$name") | $(sci "${F_max[$name]}") | $(sci "${F_p999[$name]}") | $(pct "${F_cov[$name]}") | $(timed_on "$name") |";;
        esac
    done
    echo
    echo "Per-pixel work of the defaults on both scenes, from \`exrfog --stats\` ($tdesc): the fog's time per pixel (all components, on its thread), noise evaluations, pixels over the per-ray work bound, and the largest error estimate of T."
    echo
    echo "| SPEC | time per pixel | noise evaluations per pixel | over the work bound | largest \\|ΔT\\| estimate |"
    echo "|---|---|---|---:|---:|"
    for row in "${stats_lines[@]}"; do echo "$row"; done
    echo
    echo "### Targets (issue 7)"
    echo
    echo "| target | measured | status |"
    echo "|---|---|---|"
    echo "| default adaptive ≤ 10× the oiiotool copy end to end | ${t1_val:-–}× ($(fnum "${E_med[$def_name]:-}" %.2f) s / $(fnum "$oiio" %.2f) s) | **$t1** |"
    echo "| at equal measured max error, adaptive ≥ 5× faster than steps (fog pass) | smallest interpolated speed-up: with tol= ${min_speedup:-–}× over $n_cmp steps point(s), with ttol= ${ttol_speedup:-–}× over $ttol_cmp, inside each one's error range | **$t2** |"
    echo "| preintegrated pieces=1 ≤ 1.3× the exp model end to end | ${t3_val:-–}× ($(fnum "${E_med[$p1_name]:-}" %.2f) s / $(fnum "$exp_med" %.2f) s) | **$t3** |"
    echo
    echo "### Targets (issue 21)"
    echo
    echo "| target | measured | status |"
    echo "|---|---|---|"
    h_name=""
    for name in "${order[@]}"; do [[ "${F_fam[$name]}" == horizon-adaptive ]] && h_name="$name"; done
    for n in "$def_name" "$h_name"; do
        [[ -n "$n" ]] || continue
        v=""
        [[ -n "${E_med[$n]:-}" ]] && v="$(awk -v a="${E_med[$n]}" -v b="$oiio" 'BEGIN { printf "%.2f", a / b }')"
        echo "| default ≤ 5× the oiiotool copy end to end: \`${F_spec[$n]}\` | ${v:-not run}× ($(fnum "${E_med[$n]:-}" %.2f) s / $(fnum "$oiio" %.2f) s) | **$(verdict "$v" 5 le)** |"
    done
    for row in "${stats_lines[@]}"; do
        mx="$(grep -o 'max [0-9.e+]* us' <<<"$row" | head -n1 | awk '{ print $2 }')"
        rt="$(grep -o 're-timed [0-9.e+]* us' <<<"$row" | head -n1 | awk '{ print $2 }')"
        echo "| costliest pixel ≤ 1 ms of one core at the default: $(cut -d'|' -f2 <<<"$row") | re-timed ${rt:-–} µs (plain max ${mx:-–} µs, the machine's stalls included) | **$(verdict "$rt" 1000 le)** |"
    done
    echo
    if [[ -z "$plot_note" ]]; then
        echo "![max |ΔT| against fog-pass time](noise_trade.png)"
    else
        echo "- note: $plot_note"
    fi
} >"$tmp/noise.md"

cat "$tmp/noise.md"
cp "$tmp/noise.md" "$here/noise.md" || die "could not write $here/noise.md"
echo "noise: tables written to $here/noise.md${plot_note:+ (no plot)}; plot: $here/noise_trade.png" >&2
