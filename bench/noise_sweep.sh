#!/usr/bin/env bash
# bench/noise_sweep.sh - the noise fog's default method on a sweep of shots
# (issue 41), end to end at 1080p against the `oiiotool IN -o OUT` copy of
# the same frame, and its accuracy against the reference integrator.
#
# usage: bench/noise_sweep.sh [BUILD_DIR]   (a Release build; default <repo>/build)
#
# The shots come from BUILD_DIR/noise_sweep --list (bench/noise_sweep.c: the
# bench's two, the issue's three, two worst corners and 24 drawn from a
# fixed seed). Per shot:
#   1. make_sample renders the 1920x1080 RGBA half + Z float ZIP frame with
#      the shot's camera (--view HEIGHT,PITCH,FOV: the ground plane, spheres
#      and sky the accuracy step's rays see, with objects in front);
#   2. `oiiotool IN -o OUT` and `exrfog IN -o OUT --fog SPEC --stats`
#      (default threads, default method: no method, tol, ttol or lod key)
#      run interleaved, oiiotool every round, exrfog while its runs fit
#      E2E_BUDGET seconds (at least once, killed past E2E_MAX: shown as
#      over); medians of wall time, and --stats' costliest pixel re-timed;
#   3. noise_sweep measures |dT| against the reference on PIXELS sampled
#      pixels (long sky and far-ground rays over-represented), the error
#      output's coverage and the evaluations per pixel.
# Writes bench/noise_sweep.md. Nothing asserts on time.
#
# Environment: BENCH_RUNS=3, E2E_BUDGET=20, E2E_MAX=300, PIXELS=1000,
# ONLY=NAME (one shot), SKIP_ACCURACY=1, SKIP_E2E=1, LOD=1 (every SPEC with
# lod=pixel, the shots where it is refused listed as such; accuracy
# against its own reference; writes bench/noise_sweep_lod.md instead).
set -uo pipefail
die() { echo "noise_sweep: $*" >&2; exit 1; }
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
build="$(cd "${1:-$repo/build}" && pwd)" || die "no build directory"
runs="${BENCH_RUNS:-3}" budget="${E2E_BUDGET:-20}" emax="${E2E_MAX:-300}"
pixels="${PIXELS:-1000}" only="${ONLY:-}" lod="${LOD:-}"
exrfog="$build/exrfog" sweep="$build/noise_sweep" make_sample="$build/make_sample"
for b in "$exrfog" "$sweep" "$make_sample"; do [[ -x "$b" ]] || die "missing $b (build it)"; done
command -v oiiotool >/dev/null || die "oiiotool is not installed (apt-get install openimageio-tools)"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
out="$here/noise_sweep.md" lodarg=() lodkey=""
if [[ -n "$lod" ]]; then out="$here/noise_sweep_lod.md" lodarg=(--lod) lodkey=":lod=pixel"; fi
now() { date +%s.%N; }
# Whether exrfog refuses SPEC for its lod key (noise-separable, patchy fog).
refused() {
    "$exrfog" --fog "$1" --explain "$tmp/none.exr" >/dev/null 2>"$tmp/why.txt" && return 1
    grep -q 'lod=pixel' "$tmp/why.txt"
}
median() { sort -g | awk '{ a[NR] = $1 } END { if (NR == 0) print "nan"; else if (NR % 2) print a[(NR + 1) / 2]; else print (a[NR / 2] + a[NR / 2 + 1]) / 2 }'; }

start=$(date -u '+%Y-%m-%d %H:%M:%S UTC')
{
    echo "## exrfog noise fog on a sweep of shots (issue 41)${lodkey:+, every SPEC with lod=pixel}"
    echo
    echo "- date: $start"
    echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | sed 's/.*: //'), $(uname -sr)"
    echo "- build: $build, source $(git -C "$repo" rev-parse --short HEAD 2>/dev/null)"
    echo "- frames: 1920x1080 RGBA half + Z float, ZIP, made by make_sample --view HEIGHT,PITCH,FOV (ground plane y = 0, spheres, sky; camera turned 6 degrees right)"
    echo "- end to end: oiiotool $(oiiotool --version 2>/dev/null | head -1) \`oiiotool IN -o OUT\` and \`exrfog IN -o OUT --fog SPEC --stats\` (default threads, default method), interleaved, medians of wall time; exrfog while its runs fit ${budget} s (at least one run; killed past ${emax} s); the costliest pixel is --stats' re-timed maximum (one core)"
    echo "- accuracy: bench/noise_sweep.c on ${pixels} pixels per shot (60 % uniform, 20 % within 2 % of the frame's height of the horizon, 20 % sky or far ground) of the same camera over the ground plane alone: |dT| against ef_ref_tau_long; within = |dT| <= 2^-12 (the man page's promise); covers = the error output T expm1(err) >= |dT|"
    echo
} > "$out.tmp"

if [[ -z "${SKIP_E2E:-}" ]]; then
    {
        echo "### End to end, 1080p"
        echo
        echo "| shot | camera (height, pitch, fov) | SPEC | oiiotool s | exrfog s (runs) | / oiiotool | costliest pixel µs | evals/px mean | over the work bound |"
        echo "|---|---|---|---:|---:|---:|---:|---:|---:|"
    } >> "$out.tmp"
    while IFS=$'\t' read -r name h p f spec; do
        [[ -n "$only" && "$name" != "$only" ]] && continue
        if [[ -n "$lod" ]] && refused "$spec$lodkey"; then
            printf '| %s | %s, %s°, %s° | `%s` | – | lod=pixel refused | | | | |\n' "$name" "$h" "$p" "$f" "$spec" >> "$out.tmp"
            continue
        fi
        spec="$spec$lodkey"
        in="$tmp/in.exr"
        "$make_sample" "$in" --size 1920x1080 --view "$h,$p,$f" >/dev/null || die "make_sample $name"
        o=() e=() over=0 stats=""
        spent=0
        for r in $(seq 1 "$runs"); do
            t0=$(now); oiiotool "$in" -o "$tmp/copy.exr" || die "oiiotool"; t1=$(now)
            o+=("$(echo "$t1 - $t0" | bc -l)")
            if (( r == 1 )) || awk -v s="$spent" -v b="$budget" 'BEGIN { exit !(s < b) }'; then
                t0=$(now)
                timeout "$emax" "$exrfog" "$in" -o "$tmp/fog.exr" --fog "$spec" --stats 2>"$tmp/stats.txt"
                rc=$?
                t1=$(now)
                if (( rc == 124 )); then over=1; break; fi
                (( rc == 0 )) || die "exrfog $name: exit $rc: $(cat "$tmp/stats.txt")"
                d=$(echo "$t1 - $t0" | bc -l)
                e+=("$d")
                spent=$(echo "$spent + $d" | bc -l)
                stats=$(cat "$tmp/stats.txt")
            fi
        done
        om=$(printf '%s\n' "${o[@]}" | median)
        if (( over )); then
            em="> $emax" ratio="> $(awk -v a="$emax" -v b="$om" 'BEGIN { printf "%.0f", a / b }')×"
        else
            em=$(printf '%s\n' "${e[@]}" | median)
            ratio=$(awk -v a="$em" -v b="$om" 'BEGIN { printf "%.2f×", a / b }')
            em=$(awk -v a="$em" 'BEGIN { printf "%.2f", a }')
        fi
        worst=$(grep -o 'costliest pixel re-timed [0-9.e+-]*' <<<"$stats" | awk '{ print $4 }')
        evals=$(grep -o 'noise evaluations mean [0-9.e+-]*' <<<"$stats" | awk '{ print $4 }')
        obound=$(grep -o 'over the work bound [0-9]*' <<<"$stats" | awk '{ print $5 }')
        printf '| %s | %s, %s°, %s° | `%s` | %.2f | %s (%d) | %s | %s | %s | %s |\n' "$name" "$h" "$p" "$f" "$spec" \
            "$om" "$em" "${#e[@]}" "$ratio" "${worst:-–}" "${evals:-–}" "${obound:-–}" >> "$out.tmp"
        echo "noise_sweep: $name: oiiotool $om s, exrfog $em s ($ratio)" >&2
    done < <("$sweep" --list)
    echo >> "$out.tmp"
fi

if [[ -z "${SKIP_ACCURACY:-}" ]]; then
    {
        echo "### Accuracy against the reference, ${pixels} pixels per shot"
        echo
    } >> "$out.tmp"
    if [[ -n "$only" ]]; then
        "$sweep" --pixels "$pixels" --only "$only" "${lodarg[@]}" >> "$out.tmp"
    else
        "$sweep" --pixels "$pixels" "${lodarg[@]}" >> "$out.tmp"
    fi
    echo >> "$out.tmp"
fi
echo "- finished: $(date -u '+%Y-%m-%d %H:%M:%S UTC')" >> "$out.tmp"
mv "$out.tmp" "$out"
echo "noise_sweep: wrote $out" >&2
