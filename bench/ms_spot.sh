#!/bin/bash
# bench/ms_spot.sh - a spot's multiple scattering (issue 44: spots, ms.h's ef_lms_spot) against
# Blender Cycles with 128 volume bounces.
#
#   bench/ms_spot.sh [BUILD_DIR] > bench/ms_spot.md
#   MS_SPOT_GRID=bench/ms_spot_grid.jsonl bench/ms_spot.sh [BUILD_DIR]  (re-print)
#
# bench/ms_compare.py with spot=CONE: bench/ms_lamp_blender.py's lamp 10 units ahead made a spot
# of that cone (blend 0.2) aimed straight down, in homogeneous fog, volume bounces 0 and 128,
# MS_SPOT_SPP samples (default 2048), 64x36; exrfog's exp fog of the same density, albedo and HG
# g with the spot (cosine=1, as Cycles 3.x's spots) scattering=single and =multiple. Errors per
# 4x4 block relative to Cycles' radiance with every bounce, and the multiple scattering alone
# (exrfog's multiple less its single, against Cycles' 128 bounces less its 0). Then the cost at
# 1080p: a spot, single against multiple, on 2 threads, and the solve's own time.
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms_spot.sh MS_SPOT_SPP 2048 "${1:-build}"
# density albedo g cone [behind | across]: the spot 10 units behind the camera (only its
# scattered light in view), or aimed along -x across the view
cases=("0.2 0.95 0 40" "0.2 0.95 0.5 40" "0.05 0.95 0.5 40" "0.2 0.8 0.85 60" "0.2 0.99 0 20"
       "0.2 0.95 0 40 behind" "0.2 0.95 0.5 40 behind" "0.2 0.95 0.5 40 across" "0.2 0.95 0 40 across")
if [[ -n "${MS_SPOT_GRID:-}" ]]; then
    cp "$MS_SPOT_GRID" "$tmp/grid.jsonl" || die "MS_SPOT_GRID=$MS_SPOT_GRID unreadable"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "$spp" 0 "$1" "$2" "$3" 0 64 36 4 \
            - lamp=10 "spot=$4" ${5:+"$5"} >>"$tmp/grid.jsonl" || die "case $c failed"
    done
    cp "$tmp/grid.jsonl" "$here/ms_spot_grid.jsonl"
fi
lc_tag="a spot 25 behind aimed down" lc_light="spot:position=2,3,25:aim=0,-1,0.2:cone=40:blend=0.2:intensity=40" \
    lamp_cost "exp:density=0.05:albedo=0.9" "exp:density=0.05:albedo=0.9:phase=hg:g=0.5" \
    "height:density=0.1:falloff=0.1:albedo=0.9:phase=hg:g=0.5"
ms_header "A spot's multiple scattering against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, $spp samples, 64x36, volume bounces 0 and 128; bench/ms_lamp_blender.py with spot=CONE: homogeneous fog in a cube 4 km wide about the camera, a black world, the camera at the origin looking along +y (60 degrees), a spot of 100 W (radius 0, blend 0.2) at (1.5, 10, 1) aimed straight down (behind: at (1.5, -10, 1); across: aimed along -x)"
echo "- exrfog: exp fog of the same density, albedo and HG g, --up-axis z, spot:position=1.5,10,1:aim=0,0,-1 (or -1,0,0):cone=CONE:blend=0.2:cosine=1:intensity=100/(4 pi) with scattering=single and =multiple"
ms_errors_note 4
"$py" - "$tmp/grid.jsonl" "$tmp/cost" "$tmp/solves" "$here" <<'PYEOF'
import sys
sys.path.insert(0, sys.argv[4])
import ms_report
rows = ms_report.grid(sys.argv[1])
print("| density (lamp tau) | spot | cone | albedo | g | single vs Cycles' bounces 0 (frame means) | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered | multiple alone, exrfog / Cycles (frame means) |")
print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows:
    where = "behind the camera, aimed down" if r.get("behind") else "ahead, aimed across" if r.get("across") else "ahead, aimed down"
    sv = ("%+.2f %%" % (100 * (r["exrfog_single_mean"] / r["cycles_single_mean"] - 1))
          if r["cycles_single_mean"] > 0 else "– (none in view)")
    print("| %g (%.1f) | %s | %g | %g | %g | %s | %.2f %% | %.2f %% | %+.2f %% | %.2f %% | %.2e | %.0f %% | %.3f |" % (
        r["density"], r["lamp_tau"], where, r["spot"], r["albedo"], r["g"],
        sv, 100 * r["rel_median"],
        100 * r["rel_p99"], 100 * r["rel_signed_median"], 100 * r["noise_rel_median"],
        r["err_rel_median"], 100 * r["covered"], ms_report.ms_ratio(r)))
print()
ms_report.summary(rows)
m, solve, fogs = ms_report.costs(sys.argv[2], sys.argv[3])
print()
print("### Cost at 1080p (a spot, 2 threads, medians of 5 runs)")
print()
print("| shot and fog | oiiotool copy s | single s | multiple s | / single | the solve and the cone's table (once per scene) |")
print("|---|---:|---:|---:|---:|---:|")
for fog in fogs:
    s1, sm = m[fog + "/single"], m[fog + "/multiple"]
    sv = solve.get(fog, 0.0)
    print("| `%s` | %.2f | %.2f | %.2f | %.2fx | %.2f s |" % (fog, m[fog + "/copy"], s1, sm, sm / s1, sv))
PYEOF
