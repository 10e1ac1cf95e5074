#!/bin/bash
# bench/ms_sweep.sh - a sun's multiple scattering over a sweep of shots
# (issue 44's cost: within 2x the same sun's single scattering at 1080p on
# 2 threads), one build's multiple scattering against another's in the
# same run, and the largest difference of their outputs.
#
#   bench/ms_sweep.sh BEFORE_EXRFOG AFTER_EXRFOG [BUILD_DIR] > bench/ms_sweep.md
#
# Shots: make_sample frames at MS_SIZE (default 1920x1080) from seven
# cameras (height, pitch, fov: at the horizon, 5 up, 30 up, 60 up looking
# 20 degrees down, 120 up, 12 up looking 2 degrees up so half the frame
# is sky, 300 up), times four suns (3.6, 12 and 77 degrees up ahead, and
# 27 degrees up behind the camera), times three fogs that are the same
# along the ground (steep height fog, gentle height fog whose rays run
# long, a slab half-space 20 deep). Per shot, interleaved, MS_ROUNDS
# rounds (default 2), medians of wall time on 2 threads (the default
# output, half): the after build's single scattering, its multiple, and
# the before build's multiple; then the two multiple outputs once more in
# float, untimed, for their difference.
set -u
# shellcheck source=bench/sweep_lib.sh
. "$(dirname "$0")/sweep_lib.sh"
sweep_setup ms_sweep.sh MS 1920x1080 "$@"
py=/usr/bin/python3
views=("horizon:1.7,-4,60" "5up:5,-5,60" "30up:30,-8,60" "60up:60,-20,60" "120up:120,-20,60"
       "sky:12,2,60" "300up:300,-10,60")
suns=("low:sun:towards=1,0.09,-1:intensity=3" "mid:sun:towards=1,0.3,-1:intensity=3"
      "high:sun:towards=0.3,2,-0.3:intensity=3" "behind:sun:towards=0,0.5,1:intensity=3")
fogs=("steep:height:density=0.05:falloff=0.1:base=0:albedo=0.9:phase=hg:g=0.6"
      "gentle:height:density=0.01:falloff=0.01:base=0:albedo=0.95:phase=hg:g=0.5"
      "slab:halfspace:plane=0,1,0,-20:density=0.05:albedo=0.99:phase=hg:g=0.85")
sweep_frames "${views[@]}"
wall() {   # wall seconds of one run (its arguments), to the millisecond
    local s e
    s=$(date +%s.%N)
    "$@" >/dev/null 2>"$tmp/err" || { cat "$tmp/err" >&2; die "run failed: $*"; }
    e=$(date +%s.%N)
    echo "$e - $s" | bc
}
echo "## A sun's multiple scattering over a sweep of shots"
echo
echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg) before"
echo "- before: $before; after: $after"
echo "- frames: make_sample $size (ground plane y = 0, spheres, sky) from each camera (height, pitch, fov); 2 threads; $rounds rounds interleaved, medians of wall time (date +%s.%N); multiple scattering with ground=0; every timed run writes the default (half) output; max diff: the largest |after - before| of the multiple runs' RGB written once more in float, relative to max(|before|, 1e-3)"
echo
echo "| camera | sun | fog | single s | multiple s | / single | before: multiple s | / single | max diff |"
echo "|---|---|---|---:|---:|---:|---:|---:|---:|"
: >"$tmp/ratios"
for v in "${views[@]}"; do
    vn=${v%%:*}
    for l in "${suns[@]}"; do
        sn=${l%%:*} sun=${l#*:}
        for f in "${fogs[@]}"; do
            fn=${f%%:*} fog=${f#*:}
            ts="" tm="" tb=""
            for ((r = 0; r < rounds; ++r)); do
                ts+="$(wall "$after" "$tmp/$vn.exr" -o "$tmp/s.exr" --fog "$fog" --light "$sun" --threads 2) "
                tm+="$(wall "$after" "$tmp/$vn.exr" -o "$tmp/a.exr" --fog "$fog" --light "$sun:scattering=multiple:ground=0" --threads 2) "
                tb+="$(wall "$before" "$tmp/$vn.exr" -o "$tmp/b.exr" --fog "$fog" --light "$sun:scattering=multiple:ground=0" --threads 2) "
            done
            # the outputs compared in float, outside the timed runs
            "$after" "$tmp/$vn.exr" -o "$tmp/a.exr" --fog "$fog" --light "$sun:scattering=multiple:ground=0" -d float >/dev/null 2>&1 || die "float run"
            "$before" "$tmp/$vn.exr" -o "$tmp/b.exr" --fog "$fog" --light "$sun:scattering=multiple:ground=0" -d float >/dev/null 2>&1 || die "float run"
            s=$(echo "$ts" | median) m=$(echo "$tm" | median) b=$(echo "$tb" | median)
            d=$(max_rel_diff "$tmp/b.exr" "$tmp/a.exr")
            ra=$(awk -v a="$m" -v b="$s" 'BEGIN {printf "%.2f", a / b}')
            rb=$(awk -v a="$b" -v b="$s" 'BEGIN {printf "%.2f", a / b}')
            echo "$vn/$sn/$fn $ra $rb" >>"$tmp/ratios"
            printf '| %s | %s | %s | %.3f | %.3f | %sx | %.3f | %sx | %s |\n' "$vn" "$sn" "$fn" "$s" "$m" "$ra" "$b" "$rb" "$d"
        done
    done
done
echo
"$py" - "$tmp/ratios" <<'EOF'
import statistics as st
import sys
rows = [l.split() for l in open(sys.argv[1]) if l.strip()]
for col, name in ((1, "after"), (2, "before")):
    v = sorted((float(r[col]), r[0]) for r in rows)
    print("- %s: multiple over single, median %.2fx, worst %.2fx (%s); %d of %d shots within 2x"
          % (name, st.median(x for x, _ in v), v[-1][0], v[-1][1],
             sum(x <= 2.0 for x, _ in v), len(v)))
EOF
