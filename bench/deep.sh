#!/bin/bash
# bench/deep.sh - deep fog (issue 24) against oiiotool in the same run.
#
#   bench/deep.sh [BUILD_DIR] > bench/deep.md
#
# Input: a 1920x1080 deep frame from make_sample's header and make_deep's
# synthetic stack (DEEP_SAMPLES volume samples per pixel, default 20),
# deep scanline ZIPS. Entries, interleaved, DEEP_ROUNDS rounds (default 2),
# medians of wall time and of peak RSS (/usr/bin/time):
#   oiiotool IN -o OUT (a deep copy), oiiotool IN --flatten -o OUT,
#   exrfog --deep samples | fog | flatten with exp fog, samples with height
#   fog, and fog elements of height fog at three --deep-tol; output sizes,
#   fog samples per pixel and the largest split-error estimate from --stats.
set -u
build="${1:-build}"
N="${DEEP_SAMPLES:-20}"
rounds="${DEEP_ROUNDS:-2}"
die() { echo "deep.sh: $*" >&2; exit 1; }
for b in exrfog make_sample make_deep; do [[ -x "$build/$b" ]] || die "$build/$b not built"; done
command -v oiiotool >/dev/null || die "oiiotool not found"
[[ -x /usr/bin/time ]] || die "/usr/bin/time not found (apt-get install -y time)"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-deep.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT
"$build/make_sample" "$tmp/flat.exr" --size 1920x1080 --compression zip >&2 || die "make_sample"
"$build/make_deep" "$tmp/flat.exr" "$tmp/in.exr" "$N" || die "make_deep"
oiiotool --info "$tmp/in.exr" >/dev/null || die "oiiotool cannot read the deep frame"
names=("oiiotool deep copy" "oiiotool --flatten" "exrfog --deep samples, exp"
       "exrfog --deep fog, exp" "exrfog --deep flatten, exp" "exrfog --deep samples, height"
       "exrfog --deep fog, height, --deep-tol 1e-2" "exrfog --deep fog, height (--deep-tol 1e-3)"
       "exrfog --deep fog, height, --deep-tol 1e-4")
cmds=("oiiotool $tmp/in.exr -o $tmp/out.exr"
      "oiiotool $tmp/in.exr --flatten -o $tmp/out.exr"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog exp:density=0.02 --stats"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog exp:density=0.02 --deep fog --stats"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog exp:density=0.02 --deep flatten --stats"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog height:density=0.05:falloff=0.3:base=0 --stats"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog height:density=0.05:falloff=0.3:base=0 --deep fog --deep-tol 1e-2 --stats"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog height:density=0.05:falloff=0.3:base=0 --deep fog --stats"
      "$build/exrfog $tmp/in.exr -o $tmp/out.exr --fog height:density=0.05:falloff=0.3:base=0 --deep fog --deep-tol 1e-4 --stats")
declare -A T M S F
load0="$(cut -d' ' -f1-3 /proc/loadavg)"
for ((r = 0; r < rounds; ++r)); do
    for i in "${!cmds[@]}"; do
        rm -f "$tmp/out.exr"
        /usr/bin/time -f "%e %M" -o "$tmp/time" ${cmds[$i]} >/dev/null 2>"$tmp/err" ||
            { cat "$tmp/err" >&2; die "${names[$i]} failed"; }
        read -r sec kb <"$tmp/time"
        T[$i]+="$sec "
        M[$i]+="$kb "
        S[$i]=$(stat -c %s "$tmp/out.exr")
        F[$i]=$(grep -o 'fog samples mean [0-9.]* per pixel\|largest split-error estimate [0-9.e-]*' "$tmp/err" | paste -sd ';' -)
    done
done
median() { tr ' ' '\n' | grep . | sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
echo "## exrfog deep fog against oiiotool"
echo
echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $load0 before, $(cut -d' ' -f1-3 /proc/loadavg) after"
echo "- input: 1920x1080 deep scanline ZIPS, $N volume samples per pixel (bench/make_deep.c), $(stat -c %s "$tmp/in.exr") bytes; exrfog and oiiotool $(oiiotool --version 2>/dev/null | head -1) on 2 threads each (their defaults)"
echo "- $rounds rounds, entries interleaved; medians of wall time and peak RSS"
echo
echo "| entry | wall s | / oiiotool deep copy | / oiiotool --flatten | peak RSS MB | output MB | fog samples |"
echo "|---|---:|---:|---:|---:|---:|---|"
t0=$(echo "${T[0]}" | median); t1=$(echo "${T[1]}" | median)
for i in "${!cmds[@]}"; do
    t=$(echo "${T[$i]}" | median); m=$(echo "${M[$i]}" | median)
    printf '| %s | %.2f | %.2f× | %.2f× | %.0f | %.1f | %s |\n' "${names[$i]}" "$t" \
        "$(echo "$t / $t0" | bc -l)" "$(echo "$t / $t1" | bc -l)" "$(echo "$m / 1024" | bc -l)" \
        "$(echo "${S[$i]} / 1048576" | bc -l)" "${F[$i]:-–}"
done
echo
echo "Targets (issue 24): deep out with exp fog ≤ 2× oiiotool's deep copy; --deep flatten ≤ oiiotool's flatten."
