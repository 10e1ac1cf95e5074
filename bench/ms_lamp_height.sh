#!/bin/bash
# bench/ms_lamp_height.sh - a point lamp's multiple scattering in height fog (issue 44: lamps in
# fog that is not uniform, ms.h's local mode) against Blender Cycles with 128 volume bounces.
#
#   bench/ms_lamp_height.sh [BUILD_DIR] > bench/ms_lamp_height.md
#   MS_LAMP_GRID=bench/ms_lamp_height_grid.jsonl bench/ms_lamp_height.sh [BUILD_DIR]  (re-print)
#
# bench/ms_compare.py with falloff=K: bench/ms_lamp_blender.py's lamp 10 units ahead in
# exponential height fog DENSITY exp(-K z) (Cycles marches it in steps of a fiftieth of the
# scale height), volume bounces 0 and 128, MS_LAMP_SPP samples (default 2048), 64x36; exrfog's
# height fog of the same density, falloff, albedo and HG g with the lamp's scattering=single
# and =multiple. Errors per 4x4 block relative to Cycles' radiance with every bounce, and the
# multiple scattering alone (exrfog's multiple less its single, against Cycles' 128 bounces
# less its 0). Then the cost at 1080p: a lamp in height fog, single against multiple, on 2
# threads, and the solve's own time (once per scene).
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms_lamp_height.sh MS_LAMP_SPP 2048 "${1:-build}"
# density albedo g falloff [samples behind]: the last, the lamp 10 units behind the camera
cases=("0.05 0.95 0.5 0.1" "0.2 0.95 0.5 0.1" "0.2 0.8 0 0.1" "0.1 0.95 0.5 0.3" "0.2 0.99 0.85 0.1"
       "0.1 0.95 0.5 0.1 1024 behind")
if [[ -n "${MS_LAMP_GRID:-}" ]]; then
    cp "$MS_LAMP_GRID" "$tmp/grid.jsonl" || die "MS_LAMP_GRID=$MS_LAMP_GRID unreadable"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "${5:-$spp}" 0 "$1" "$2" "$3" 0 64 36 4 \
            - lamp=10 "falloff=$4" ${6:+"$6"} >>"$tmp/grid.jsonl" || die "case $c failed"
    done
    cp "$tmp/grid.jsonl" "$here/ms_lamp_height_grid.jsonl"
fi
lc_tag="camera 2 up, lamp behind" lamp_cost "height:density=0.1:falloff=0.1:albedo=0.9" \
    "height:density=0.1:falloff=0.1:albedo=0.9:phase=hg:g=0.5" \
    "height:density=0.1:falloff=0.3:albedo=0.99:phase=hg:g=0.85"
# a lamp ahead of the camera (it looks along -z), and a camera 60 up looking 20 degrees down on a lamp below it
lc_tag="camera 2 up, lamp ahead" lc_lamp=2,3,-15 lamp_cost "height:density=0.1:falloff=0.1:albedo=0.9" \
    "height:density=0.1:falloff=0.1:albedo=0.9:phase=hg:g=0.5"
lc_tag="camera 60 up, 20 degrees down" lc_view=60,-20,60 lamp_cost "height:density=0.1:falloff=0.1:albedo=0.9" \
    "height:density=0.1:falloff=0.1:albedo=0.9:phase=hg:g=0.5"
ms_header "A point lamp's multiple scattering in height fog against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, 64x36, volume bounces 0 and 128; bench/ms_lamp_blender.py with falloff=K: height fog DENSITY exp(-K z) in a box 600 wide from z = -4/K to 15/K, a black world, the camera at the origin looking along +y (60 degrees), a point lamp of 100 W (radius 0) at (1.5, 10, 1)"
echo "- exrfog: height:density=DENSITY:falloff=K with the same albedo and HG g, --up-axis z, point:position=1.5,10,1:intensity=100/(4 pi) with scattering=single and =multiple"
ms_errors_note 4
"$py" - "$tmp/grid.jsonl" "$tmp/cost" "$tmp/solves" "$here" <<'PYEOF'
import sys
sys.path.insert(0, sys.argv[4])
import ms_report
rows = ms_report.grid(sys.argv[1])
print("| density | falloff | density x 10 (the lamp's distance) | lamp | albedo | g | samples | single / Cycles (median) | single vs Cycles' bounces 0 | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered | multiple alone, exrfog / Cycles (frame means) |")
print("|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows:
    print("| %g | %g | %.2f | %s | %g | %g | %d | %.3f | %+.2f %% | %.2f %% | %.2f %% | %+.2f %% | %.2f %% | %.2e | %.0f %% | %.3f |" % (
        r["density"], r["falloff"], r["lamp_tau"], "behind the camera" if r.get("behind") else "ahead",
        r["albedo"], r["g"], r["spp"],
        r["single_share_median"], 100 * r["single_check_median"], 100 * r["rel_median"],
        100 * r["rel_p99"], 100 * r["rel_signed_median"], 100 * r["noise_rel_median"],
        r["err_rel_median"], 100 * r["covered"], ms_report.ms_ratio(r)))
print()
ms_report.summary(rows)
m, solve, fogs = ms_report.costs(sys.argv[2], sys.argv[3])
print()
print("### Cost at 1080p (a point lamp in height fog, 2 threads, medians of 5 runs)")
print()
print("| shot and fog | single s | multiple s | / single | the solve (once per scene) | / single without the solve |")
print("|---|---:|---:|---:|---:|---:|")
for fog in fogs:
    s1, sm = m[fog + "/single"], m[fog + "/multiple"]
    sv = solve.get(fog, 0.0)
    print("| `%s` | %.2f | %.2f | %.2fx | %.2f s | %.2fx |" % (fog, s1, sm, sm / s1, sv, (sm - sv) / s1))
PYEOF
