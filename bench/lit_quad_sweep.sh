#!/bin/bash
# bench/lit_quad_sweep.sh - the general lit quadrature (a lamp or spot in
# fog that is not uniform) over a sweep of shots, one build against another
# in the same run: wall time and the largest relative difference of their
# float outputs.
#
#   bench/lit_quad_sweep.sh BEFORE_EXRFOG AFTER_EXRFOG [BUILD_DIR] > bench/lit_quad_sweep.md
#
# Shots: make_sample frames at LQ_SIZE (default 480x270) from five cameras
# (height, pitch, fov: at the horizon with the sky in frame, 30 up, 120 up
# looking 20 degrees down, 12 up looking 2 degrees up so half the frame is
# sky, 300 up), times four lights (a lamp ahead near the ground, a lamp
# behind the camera, a lamp high and far, a spot looking down), times
# four fogs (steep height fog, gentle height fog whose rays run long,
# height fog with a box volume, and height fog over a thin uniform mist). Every run on 2 threads, LQ_ROUNDS rounds
# (default 2) interleaved, medians.
set -u
# shellcheck source=bench/sweep_lib.sh
. "$(dirname "$0")/sweep_lib.sh"
sweep_setup lit_quad_sweep.sh LQ 480x270 "$@"
[[ -x /usr/bin/time ]] || die "/usr/bin/time not found (apt-get install -y time)"
views=("horizon:1.7,-4,60" "30up:30,-8,60" "120up:120,-20,60" "sky:12,2,60" "300up:300,-10,60")
lights=("lamp-ahead:point:position=0,3,-20:intensity=100"
        "lamp-behind:point:position=1,4,12:intensity=100"
        "lamp-high-far:point:position=50,80,-300:intensity=5000"
        "spot:spot:position=0,10,-30:aim=0,-1,0.1:cone=40:blend=0.2:intensity=300")
fogs=("steep:--fog height:density=0.05:falloff=0.3:base=0"
      "gentle:--fog height:density=0.01:falloff=0.01:base=0"
      "box:--fog height:density=0.05:falloff=0.3:base=0 --fog box:min=-10,0,-60:max=10,8,-10:density=0.1"
      "mist:--fog height:density=0.05:falloff=0.3:base=0 --fog exp:density=0.005")
sweep_frames "${views[@]}"
echo "## The general lit quadrature over a sweep of shots"
echo
echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg) before"
echo "- before: $before; after: $after"
echo "- frames: make_sample $size (ground plane, spheres, sky) from each camera (height, pitch, fov); 2 threads; $rounds rounds interleaved, medians of wall time; max rel. diff: the largest |after - before| / max(|before|, 1e-3) over the float outputs' RGB"
echo
echo "| camera | light | fog | before s | after s | speed-up | max rel. diff |"
echo "|---|---|---|---:|---:|---:|---:|"
for v in "${views[@]}"; do
    vn=${v%%:*}
    for l in "${lights[@]}"; do
        ln=${l%%:*}
        for f in "${fogs[@]}"; do
            fn=${f%%:*}
            tb="" ta=""
            for ((r = 0; r < rounds; ++r)); do
                for side in before after; do
                    bin=$before
                    [[ $side == after ]] && bin=$after
                    # shellcheck disable=SC2086
                    /usr/bin/time -f "%e" -o "$tmp/t" "$bin" "$tmp/$vn.exr" -o "$tmp/$side.exr" -d float \
                        ${f#*:} --light "${l#*:}" --threads 2 2>"$tmp/err" >/dev/null ||
                        { cat "$tmp/err" >&2; die "$vn $ln $fn $side failed"; }
                    if [[ $side == before ]]; then tb+="$(cat "$tmp/t") "; else ta+="$(cat "$tmp/t") "; fi
                done
            done
            mb=$(echo "$tb" | median) ma=$(echo "$ta" | median)
            diff=$(max_rel_diff "$tmp/before.exr" "$tmp/after.exr")
            echo "| $vn | $ln | $fn | $mb | $ma | $(awk -v b="$mb" -v a="$ma" 'BEGIN {printf "%.2fx", b / a}') | $diff |"
        done
    done
done
