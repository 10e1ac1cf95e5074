#!/bin/bash
# bench/ms_lamp_box.sh - a point lamp's multiple scattering where the fog ends at a plane (issue
# 44: a box of fog, a half-space) against Blender Cycles with 128 volume bounces, and what the
# error output's leak term (ms.h, ef_lms_local_node) covers.
#
#   bench/ms_lamp_box.sh [BUILD_DIR] > bench/ms_lamp_box.md
#   MS_LAMP_BOX_GRID=FILE bench/ms_lamp_box.sh [BUILD_DIR]   (re-print a grid of ms_compare lines)
#
# bench/ms_compare.py with lamp=10 and box=X0,Y0,Z0,X1,Y1,Z1 (the homogeneous fog fills that box
# alone; exrfog: box:min=:max=) or hs=Z (everything below z = Z; exrfog: halfspace:plane=0,0,1,-Z),
# bench/ms_lamp_blender.py's lamp at (1.5, 10, 1), the camera at the origin looking along +y,
# MS_LAMP_BOX_SPP samples (default 1024), 64x36, errors per 4x4 block. The calib rows are the
# scenes the leak term's weight (LEAK_C) was set on; the others are tests of it. Then the cost at
# 1080p: a lamp in a box of fog, single against multiple, on 2 threads.
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms_lamp_box.sh MS_LAMP_BOX_SPP 1024 "${1:-build}"
# role density albedo g geometry [behind: the lamp 10 behind the camera | spot=CONE: a spot aimed down]
cases=("calib 0.3 0.9 0.3 box=-10,5,-6,10,20,8" "calib 0.15 0.99 0 box=-12,2,-4,14,22,10"
       "calib 0.25 0.92 0.2 hs=2"
       "test 0.2 0.95 0.5 box=-6,4,-5,9,16,7" "test 0.5 0.95 0.5 box=-6,4,-5,9,16,7"
       "test 0.1 0.95 0.5 box=-20,-10,-8,20,30,12" "test 0.3 0.95 0.5 box=-8,14,-6,8,26,6"
       "test 0.2 0.95 0.5 hs=3" "test 0.3 0.9 0 hs=1.5" "test 0.1 0.99 0.3 hs=4"
       "test 0.1 0.95 0.5 box=-20,-30,-8,20,30,12 behind" "test 0.2 0.95 0 box=-6,4,-5,9,16,7 spot=60")
if [[ -n "${MS_LAMP_BOX_GRID:-}" ]]; then
    cp "$MS_LAMP_BOX_GRID" "$tmp/grid.jsonl" || die "MS_LAMP_BOX_GRID=$MS_LAMP_BOX_GRID unreadable"
    for c in "${cases[@]}"; do echo "${c%% *}"; done >"$tmp/roles"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        echo "$1" >>"$tmp/roles"
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "$spp" 0 "$2" "$3" "$4" 0 64 36 4 \
            - lamp=10 "${@:5}" >>"$tmp/grid.jsonl" || die "case $c failed"
    done
fi
lc_tag="a lamp in a box of fog" lc_lamp=2,3,-25 lamp_cost \
    "box:min=-10,0,-35:max=14,10,-15:density=0.1:albedo=0.9" \
    "box:min=-10,0,-35:max=14,10,-15:density=0.1:albedo=0.9:phase=hg:g=0.5"
ms_header "A point lamp's multiple scattering where the fog ends at a plane, against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, 64x36, $spp samples, volume bounces 0 and 128; bench/ms_lamp_blender.py: homogeneous fog in a box (box=) or below a plane (hs=), a black world, the camera at the origin looking along +y (60 degrees), a point lamp of 100 W (radius 0) at (1.5, 10, 1)"
echo "- exrfog: box:min=:max= or halfspace:plane=0,0,1,-Z of the same density, albedo and HG g, --up-axis z, point:position=1.5,10,1:intensity=100/(4 pi) with scattering=single and =multiple"
ms_errors_note 4
"$py" - "$tmp/grid.jsonl" "$tmp/roles" "$tmp/cost" "$tmp/solves" "$here" <<'PYEOF'
import sys
sys.path.insert(0, sys.argv[5])
import ms_report
rows = ms_report.grid(sys.argv[1])
roles = open(sys.argv[2]).read().split()
print("| role | fog | density | albedo | g | single / Cycles (median) | single vs Cycles' bounces 0 | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered | multiple alone, exrfog / Cycles (frame means) |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for role, r in zip(roles, rows):
    geo = ("box " + r["box"]) if r.get("box") else "below z = %g" % r["hs"]
    if r.get("behind"):
        geo += ", the lamp behind the camera"
    if r.get("spot"):
        geo += ", a spot of cone %g aimed down" % r["spot"]
    print("| %s | %s | %s" % (role, geo, ms_report.case_cells(r)))
print()
ms_report.summary(rows)
print()
ms_report.cost_table("Cost at 1080p (a point lamp at 2,3,-25 in a box of fog ahead of the camera, 2 threads, medians of 5 runs)",
                     sys.argv[3], sys.argv[4])
PYEOF
