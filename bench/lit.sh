#!/usr/bin/env bash
# shellcheck disable=SC2016  # command lines are stored single-quoted and eval'd
# bench/lit.sh - what lights cost: lit fog end to end on a 1920x1080 frame
# against the same fog unlit and the `oiiotool IN -o OUT` copy, measured in
# the same run.
#
# usage: bench/lit.sh [BUILD_DIR]     (default: <repo>/build, a Release build)
#
# Renders the 1920x1080 RGBA half + Z float ZIP frame of bench/run.sh
# (make_sample), then times in BENCH_RUNS interleaved rounds (order rotated
# each round; medians): the copy, exp, height and half-space fog unlit, the
# sun in height fog and in a half-space layer (closed forms), two point
# lamps in exp fog and one behind the camera (equiangular quadrature), a
# point lamp in a box volume plus height fog (the general quadrature), a
# sun 0.3 degrees up over the earth (planet=: Chapman's function in the
# general quadrature), and
# the sun in height fog through shadow maps of the same scene (make_sample
# --sun-view) of 512^2, 2048^2 and 4096^2 texels (the walk of the map's
# texels, and how it grows with the map), its penumbrae from angle= (16
# tilted copies of the 2048^2 map), and --sky-light with a 2048x1024
# environment (iso, and hg g = 0.9: its convolution included). Prints a Markdown table, also written to bench/lit.md
# (whose sections from its first "### " heading on are kept). Nothing
# asserts on time.
#
# Environment: BENCH_RUNS=3, BENCH_SIZE=1920x1080, EXRFOG_THREADS=N.
set -uo pipefail

die() { echo "lit: $*" >&2; exit 1; }

here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
build="${1:-$repo/build}"
[[ -d "$build" ]] || die "no build directory $build"
build="$(cd "$build" && pwd)"
runs="${BENCH_RUNS:-3}"
size="${BENCH_SIZE:-1920x1080}"
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || die "BENCH_RUNS must be a positive integer"
[[ "$size" =~ ^[1-9][0-9]*x[1-9][0-9]*$ ]] || die "BENCH_SIZE must be WxH"
exrfog="$build/exrfog"
make_sample="${MAKE_SAMPLE:-$build/make_sample}"
for b in "$exrfog" "$make_sample"; do
    [[ -x "$b" ]] || die "$b not built (cmake --build $build)"
done
command -v oiiotool >/dev/null 2>&1 || die "oiiotool not found (apt-get install -y openimageio-tools)"

tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-lit.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT
IN="$tmp/frame.exr"
echo "lit: rendering $size frame ..." >&2
"$make_sample" "$IN" --size "$size" --compression zip >&2 || die "make_sample failed"
px=$(( ${size%x*} * ${size#*x} ))
# a 2048x1024 lat-long environment: a sky gradient and a sun-like lobe
"${PYTHON:-/usr/bin/python3}" - "$tmp/env.exr" <<'PY' >&2 || die "writing the environment failed (python3 with numpy and OpenImageIO)"
import sys
import numpy as np
import OpenImageIO as oiio
W, H = 2048, 1024
y, x = np.mgrid[0:H, 0:W]
th, ph = np.pi * (y + 0.5) / H, np.pi - 2 * np.pi * (x + 0.5) / W
d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
up = np.clip(d[..., 2], 0, 1)[..., None]
img = np.where(up > 0, np.array([0.3, 0.45, 0.8]) + 0.5 * up, 0.1)
s = np.array([np.cos(0.3), 0, np.sin(0.3)])
img = img + (50 * np.exp(-(1 - d @ s) / 0.002))[..., None] * np.array([1, 0.8, 0.5])
b = oiio.ImageBuf(oiio.ImageSpec(W, H, 3, oiio.HALF))
b.set_pixels(oiio.ROI(0, W, 0, H, 0, 1, 0, 3), img.astype(np.float32))
b.write(sys.argv[1]) or sys.exit(b.geterror())
PY
for r in 512 2048 4096; do
    "$make_sample" "$tmp/map$r.exr" --sun-view 0.2,0.3,-1 --size "${r}x$r" >&2 || die "make_sample --sun-view failed"
done

threads=()
[[ -n "${EXRFOG_THREADS:-}" ]] && threads=(--threads "$EXRFOG_THREADS")
H='height:density=0.05:falloff=0.3:base=0'
names=() cmds=() bases=() pxs=()
add() { names+=("$1"); bases+=("$2"); cmds+=("$3"); pxs+=("${4:-$px}"); }
add "oiiotool (copy)" "" 'oiiotool "$IN" -o "$OUT"'
add "exp (unlit)" "" '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog exp:density=0.02'
add "height (unlit)" "" '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog "$H"'
add "halfspace (unlit)" "" '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog halfspace:plane=0,1,0,-4:density=0.05'
add "sun in height fog (closed form)" "height (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog "$H:phase=hg:g=0.6" --light sun:towards=0.2,0.3,-1:intensity=3'
add "two point lamps in exp fog" "exp (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog exp:density=0.02 --light point:position=2,3,-20:intensity=100 --light point:position=-6,2,-60:intensity=200'
add "a lamp behind the camera in exp fog" "exp (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog exp:density=0.02 --light point:position=1,2.5,6:intensity=100'
add "sun in a half-space layer (closed form)" "halfspace (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog halfspace:plane=0,1,0,-4:density=0.05 --light sun:towards=0.2,0.3,-1:intensity=3'
add "point lamp, box + height (general)" "height (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog "$H" --fog box:min=-10,0,-60:max=10,8,-10:density=0.1 --light point:position=2,3,-20:intensity=100'
add "sun 0.3 deg up over a planet (Chapman; general)" "height (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog "$H:phase=hg:g=0.6" --light sun:towards=0.2,0.0053,-1:intensity=3:planet=earth'
add "sky light, iso, exp fog" "exp (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog exp:density=0.02 --sky-light "$tmp/env.exr"'
add "sky light, hg g=0.9, exp fog" "exp (unlit)" \
    '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog exp:density=0.02:phase=hg:g=0.9 --sky-light "$tmp/env.exr"'
for r in 512 2048 4096; do
    add "sun in height fog, ${r}^2 shadow map" "height (unlit)" \
        '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog "$H:phase=hg:g=0.6" --light sun:towards=0.2,0.3,-1:intensity=3:shadow="$tmp/map'"$r"'.exr"'
done
# penumbrae: the sun's disc (0.53 and 2 degrees) through 16 tilted copies
# of the 2048^2 map (filtered; the scene's sun is 17 degrees up, so most
# of its long shadows lie within a penumbra's reach)
for a in 0.53 2; do
    add "sun in height fog, 2048^2 map, angle=$a (penumbra, 16 directions)" "height (unlit)" \
        '"$exrfog" "${threads[@]}" "$IN" -o "$OUT" --fog "$H:phase=hg:g=0.6" --light sun:towards=0.2,0.3,-1:intensity=3:angle='"$a"':shadow="$tmp/map2048.exr"'
done
# Lit noise fog costs milliseconds per pixel: its rows run on a 240x135
# frame of the same scene (the horizon scene of bench/noise.sh), against
# the same noise unlit on it.
SMALL="$tmp/small.exr"
"$make_sample" "$SMALL" --size 240x135 --compression zip >&2 || die "make_sample (small) failed"
N='noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0'
add "noise with falloff (unlit), 240x135" "" '"$exrfog" "${threads[@]}" "$SMALL" -o "$OUT" --fog "$N"' 32400
add "sun in noise, 240x135" "noise with falloff (unlit), 240x135" \
    '"$exrfog" "${threads[@]}" "$SMALL" -o "$OUT" --fog "$N" --light sun:towards=0.3,0.4,-1:intensity=3' 32400
add "point lamp in noise, 240x135" "noise with falloff (unlit), 240x135" \
    '"$exrfog" "${threads[@]}" "$SMALL" -o "$OUT" --fog "$N" --light point:position=4,2,-30:intensity=200' 32400
add "sun in noise, tol=2^-8, 240x135" "noise with falloff (unlit), 240x135" \
    '"$exrfog" "${threads[@]}" "$SMALL" -o "$OUT" --fog "$N:tol=0.00390625" --light sun:towards=0.3,0.4,-1:intensity=3' 32400
n=${#names[@]}
declare -A times
for ((r = 0; r < runs; ++r)); do
    for ((k = 0; k < n; ++k)); do
        i=$(( (k + r) % n ))
        OUT="$tmp/out$i.exr"
        s=$(date +%s.%N)
        eval "${cmds[$i]}" >/dev/null 2>"$tmp/err" || die "${names[$i]} failed: $(cat "$tmp/err")"
        e=$(date +%s.%N)
        times[$i]+="$(echo "$e - $s" | bc) "
        echo "lit: round $((r + 1))/$runs ${names[$i]}: $(echo "$e - $s" | bc) s" >&2
    done
done
median() { tr ' ' '\n' | grep -v '^$' | sort -g | awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }'; }
declare -A med
for ((i = 0; i < n; ++i)); do med[$i]=$(echo "${times[$i]}" | median); done
copy=${med[0]}
cpu="$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -1)"
{
    echo "## Lit fog, end to end ($(date -u '+%Y-%m-%d %H:%M UTC'))"
    echo
    echo "- machine: ${cpu:-unknown CPU}, $(nproc) cores; exrfog $(git -C "$repo" rev-parse --short HEAD 2>/dev/null) ($build)"
    echo "- input: ${size} RGBA half + Z float, ZIP (make_sample; the noise rows: 240x135); $runs interleaved rounds, medians; threads: ${EXRFOG_THREADS:-all}"
    echo
    echo "| run | median s | x copy | x unlit | lights' ns per pixel |"
    echo "|---|---:|---:|---:|---:|"
    for ((i = 0; i < n; ++i)); do
        b="${bases[$i]}" bm="" ns=""
        for ((j = 0; j < n; ++j)); do [[ "${names[$j]}" == "$b" ]] && bm=${med[$j]}; done
        if [[ -n "$bm" ]]; then
            xb=$(awk -v a="${med[$i]}" -v b="$bm" 'BEGIN { printf "%.2f", a / b }')
            ns=$(awk -v a="${med[$i]}" -v b="$bm" -v p="${pxs[$i]}" 'BEGIN { printf "%.0f", (a - b) * 1e9 / p }')
        else
            xb="-"
            ns="-"
        fi
        printf '| %s | %.3f | %.2f | %s | %s |\n' "${names[$i]}" "${med[$i]}" \
            "$(awk -v a="${med[$i]}" -v c="$copy" 'BEGIN { print a / c }')" "$xb" "$ns"
    done
    echo
    echo "ns per pixel: the lit run's wall time minus its unlit run's, over the frame's pixels (on every thread together)."
} >"$tmp/table.md"
cat "$tmp/table.md"
md="$here/lit.md"
{
    echo "# exrfog: lit fog benchmarks (bench/lit.sh)"
    echo
    cat "$tmp/table.md"
    if [[ -f "$md" ]]; then
        echo
        sed -n '/^### /,$p' "$md"
    fi
} >"$tmp/lit.md" && mv "$tmp/lit.md" "$md"
