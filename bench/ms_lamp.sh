#!/bin/bash
# bench/ms_lamp.sh - a point lamp's multiple scattering (issue 44) against Blender Cycles with
# 128 volume bounces, and its cost.
#
#   bench/ms_lamp.sh [BUILD_DIR] > bench/ms_lamp.md
#   MS_LAMP_GRID=bench/ms_lamp_grid.jsonl bench/ms_lamp.sh [BUILD_DIR] > bench/ms_lamp.md  (re-time)
#
# Over the fog's albedo (0.8, 0.95, 0.99), HG g (0, 0.5, 0.85) and the lamp's own optical depth
# to the camera (0.5, 2, 8: density 0.05, 0.2, 0.8 with the lamp 10 units ahead),
# bench/ms_compare.py renders bench/ms_lamp_blender.py's scene (fog everywhere, a point lamp
# of 100 W) with Cycles (volume bounces 0 and 128, MS_LAMP_SPP samples, default 4096, 64x36)
# and runs exrfog on its depth (every pixel sky, or the wall) with the lamp's
# scattering=single and =multiple. Errors per 4x4 block (Cycles' noise averaged down),
# relative to Cycles' radiance with every bounce. Two cases add a black wall over the
# frame's left half between the camera and the lamp (the glow must stop at it), and two put the
# lamp behind the camera (only the fog it lights is in frame). Then the cost
# at 1080p: the lamp in exp fog, single against multiple, on 2 threads.
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms_lamp.sh MS_LAMP_SPP 4096 "${1:-build}"
cases=()
for d in 0.2 0.05 0.8; do
    for a in 0.8 0.95 0.99; do
        for g in 0 0.5 0.85; do
            cases+=("$d $a $g")
        done
    done
done
cases+=("0.2 0.95 0.5 wall=4" "0.05 0.95 0.5 wall=4")
# the lamp behind the camera: the frame shows only the fog it lights
cases+=("0.05 0.95 0.5 behind" "0.2 0.95 0.5 behind")
if [[ -n "${MS_LAMP_GRID:-}" ]]; then
    cp "$MS_LAMP_GRID" "$tmp/grid.jsonl" || die "MS_LAMP_GRID=$MS_LAMP_GRID unreadable"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "$spp" 0 "$1" "$2" "$3" 0 64 36 4 \
            - lamp=10 ${4:+"$4"} >>"$tmp/grid.jsonl" || die "case $c failed"
    done
    cp "$tmp/grid.jsonl" "$here/ms_lamp_grid.jsonl"
fi
# the cost at 1080p: a point lamp in exp fog in front of the camera, single against multiple
lamp_cost "exp:density=0.1:albedo=0.9" "exp:density=0.1:albedo=0.9:phase=hg:g=0.5" \
    "exp:density=0.1:albedo=0.99:phase=hg:g=0.85"
ms_header "A point lamp's multiple scattering against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, $spp samples (or as the table says), 64x36, volume bounces 0 and 128 (max bounces 128, transparent at the default); bench/ms_lamp_blender.py: homogeneous fog in a cube 4 km wide about the camera, a black world, the camera at the origin looking along +y (60 degrees), a point lamp of 100 W (radius 0) at (1.5, 10, 1), or at (1.5, -10, 1) behind the camera"
echo "- exrfog: exp fog of the same density, albedo and HG g, point:position=1.5,10,1:intensity=100/(4 pi) with scattering=single and =multiple, on the render without fog (every pixel sky, or the black wall)"
echo "- errors per 4x4 block, relative to Cycles' radiance with every bounce; 'covered': |exrfog - Cycles| within exrfog's error output plus twice Cycles' noise"
echo
"$py" - "$tmp/grid.jsonl" "$tmp/cost" "$tmp/solves" <<'EOF'
import json, sys, statistics as st
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
print("| lamp tau | wall / lamp | albedo | g | Cycles samples | single / Cycles (median) | exrfog single vs Cycles' bounces 0 | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered |")
print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows:
    print("| %g | %s | %g | %g | %d | %.3f | %+.2f %% | %.2f %% | %.2f %% | %+.2f %% | %.2f %% | %.2e | %.0f %% |" % (
        r["lamp_tau"], "wall at %g" % r["wall"] if r["wall"] else "behind the camera" if r.get("behind") else "-",
        r["albedo"], r["g"], r["spp"],
        r["single_share_median"], 100 * r["single_check_median"], 100 * r["rel_median"],
        100 * r["rel_p99"], 100 * r["rel_signed_median"], 100 * r["noise_rel_median"],
        r["err_rel_median"], 100 * r["covered"]))
free = [r for r in rows if not r["wall"]]
med = [r["rel_median"] for r in free]
print()
print("- %d cases without the wall: median of the per-case median errors %.2f %% (the worst case's %.2f %%); Cycles' own noise per block %.2f-%.2f %% (median %.2f %%); cases whose median error is within 1.25 times Cycles' noise: %d" % (
    len(free), 100 * st.median(med), 100 * max(med), 100 * min(r["noise_rel_median"] for r in free),
    100 * max(r["noise_rel_median"] for r in free), 100 * st.median(r["noise_rel_median"] for r in free),
    sum(r["rel_median"] <= 1.25 * r["noise_rel_median"] for r in free)))
print("- signed error over those cases: median %+.2f %% (a bias beyond the noise would show here)" % (
    100 * st.median(r["rel_signed_median"] for r in free)))
print("- means over the frame, exrfog over Cycles with every bounce: %s" % ", ".join(
    "%+.1f %%" % (100 * (r["exrfog_multiple_mean"] / r["cycles_mean"] - 1)) for r in free))
print("- single scattering's share of Cycles' radiance: %.2f-%.2f (median %.2f)" % (
    min(r["single_share_median"] for r in rows), max(r["single_share_median"] for r in rows),
    st.median(r["single_share_median"] for r in rows)))
cost = {}
for l in open(sys.argv[2]):
    k, v = l.rsplit(" ", 1)
    cost.setdefault(k, []).append(float(v))
m = {k: st.median(v) for k, v in cost.items()}
print()
print("### Cost at 1080p (a point lamp in exp fog, 2 threads, medians of 5 runs)")
print()
print("| fog | run | wall s | / single | / oiiotool copy |")
print("|---|---|---:|---:|---:|")
for fog in sorted({k.rsplit("/", 1)[0] for k in m}):
    for run in ("copy", "single", "multiple"):
        t = m[fog + "/" + run]
        print("| `%s` | %s | %.3f | %.2fx | %.2fx |" % (fog, run, t, t / m[fog + "/single"], t / m[fog + "/copy"]))
print()
for l in open(sys.argv[3]):
    print("- the solve for `%s`: %s" % tuple(l.strip().split("/solve ")))
EOF
