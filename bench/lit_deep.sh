#!/bin/bash
# bench/lit_deep.sh - lit fog on deep input (issue 42 item 14) against the
# unlit deep run of the same file and oiiotool's deep copy, in the same run.
#
#   bench/lit_deep.sh [BUILD_DIR] [SHARED_DIR] > bench/lit_deep.md
#
# Input: Weta's deep elements of the OpenEXR test images (Balls, Leaves,
# Trunks; 1024x576, ../shared/real-exr/openexr-images/v2/LowResLeftView),
# with a camera given by flags (they carry none). Per element, interleaved,
# LIT_ROUNDS rounds (default 3), medians of wall time on 2 threads:
#   oiiotool IN -o OUT (a deep copy, the I/O floor),
#   exrfog --deep fog with height fog, unlit (the baseline),
#   the same lit by a point lamp, by a spot, and a lamp in exp fog,
#   --deep samples and --deep flatten with the lamp, and --deep fog with a
#   lamp on the camera's other side (z -10 against 20);
# fog samples per pixel from --stats.
set -u
build="${1:-build}"
shared="${2:-../shared}"
rounds="${LIT_ROUNDS:-3}"
die() { echo "lit_deep.sh: $*" >&2; exit 1; }
[[ -x "$build/exrfog" ]] || die "$build/exrfog not built"
command -v oiiotool >/dev/null || die "oiiotool not found"
[[ -x /usr/bin/time ]] || die "/usr/bin/time not found (apt-get install -y time)"
dir="$shared/real-exr/openexr-images/v2/LowResLeftView"
[[ -d "$dir" ]] || die "$dir not found"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-litdeep.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT
cam="--fov 50 --world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --threads 2"
height="height:density=0.05:falloff=0.3"
lamp="point:position=0,3,20:intensity=50"
lamp_back="point:position=0,3,-10:intensity=50"
spot="spot:position=0,6,20:aim=0,-0.3,1:cone=50:blend=0.2:intensity=80"
names=("oiiotool deep copy" "--deep fog, height fog, unlit" "--deep fog, height fog, a lamp"
       "--deep fog, height fog, a spot" "--deep fog, exp fog, unlit" "--deep fog, exp fog, a lamp"
       "--deep samples, height fog, a lamp" "--deep flatten, height fog, unlit"
       "--deep flatten, height fog, a lamp" "--deep fog, height fog, a lamp on the camera's other side")
args=("" "--deep fog --fog $height" "--deep fog --fog $height --light $lamp"
      "--deep fog --fog $height --light $spot" "--deep fog --fog exp:density=0.02"
      "--deep fog --fog exp:density=0.02 --light $lamp" "--deep samples --fog $height --light $lamp"
      "--deep flatten --fog $height" "--deep flatten --fog $height --light $lamp"
      "--deep fog --fog $height --light $lamp_back")
declare -A T F
load0="$(cut -d' ' -f1-3 /proc/loadavg)"
for e in Balls Leaves Trunks; do
    in="$dir/$e.exr"
    for ((r = 0; r < rounds; ++r)); do
        for i in "${!args[@]}"; do
            rm -f "$tmp/out.exr"
            if ((i == 0)); then
                cmd=(oiiotool "$in" -o "$tmp/out.exr")
            else
                # shellcheck disable=SC2206
                cmd=("$build/exrfog" "$in" -o "$tmp/out.exr" ${args[$i]} $cam --stats)
            fi
            /usr/bin/time -f "%e" -o "$tmp/time" "${cmd[@]}" >/dev/null 2>"$tmp/err" ||
                { cat "$tmp/err" >&2; die "$e: ${names[$i]} failed"; }
            T[$e,$i]+="$(cat "$tmp/time") "
            F[$e,$i]=$(grep -o 'fog samples mean [0-9.]*' "$tmp/err" | grep -o '[0-9.]*$')
        done
    done
done
median() { tr ' ' '\n' | grep . | sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
echo "## Lit fog on deep input"
echo
echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $load0 before, $(cut -d' ' -f1-3 /proc/loadavg) after"
echo "- build: $build, source $(git -C "$(dirname "$0")" rev-parse --short HEAD 2>/dev/null)"
echo "- input: Weta's deep elements (1024x576, the OpenEXR test images), camera by flags; 2 threads; $rounds rounds interleaved, medians of wall time"
echo "- fog: $height, exp:density=0.02; lights: $lamp, $spot, $lamp_back"
echo
echo "| element | entry | wall s | / the unlit run (same fog; flatten: unlit flatten) | / oiiotool deep copy | fog samples per pixel |"
echo "|---|---|---:|---:|---:|---:|"
for e in Balls Leaves Trunks; do
    copy=$(echo "${T[$e,0]}" | median)
    for i in "${!args[@]}"; do
        t=$(echo "${T[$e,$i]}" | median)
        case $i in
            2 | 3 | 6 | 9) base=1 ;;
            5) base=4 ;;
            8) base=7 ;;
            *) base= ;;
        esac
        rel="–"
        [[ -n "$base" ]] && rel=$(awk -v a="$t" -v b="$(echo "${T[$e,$base]}" | median)" 'BEGIN {printf "%.1f×", a / b}')
        printf '| %s | %s | %.2f | %s | %s | %s |\n' "$e" "${names[$i]}" "$t" "$rel" \
            "$(awk -v a="$t" -v b="$copy" 'BEGIN {printf "%.1f×", a / b}')" "${F[$e,$i]:-–}"
    done
done
