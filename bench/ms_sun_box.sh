#!/bin/bash
# bench/ms_sun_box.sh - a sun's multiple scattering in a box of fog (issue 44: the solve in three
# dimensions, src/core/lit_vms.c) against Blender Cycles with 128 volume bounces, and its cost.
#
#   bench/ms_sun_box.sh [BUILD_DIR] > bench/ms_sun_box.md
#   MS_SUN_BOX_GRID=FILE bench/ms_sun_box.sh [BUILD_DIR]   (re-print a grid of ms_compare lines)
#
# bench/ms_compare.py with sbox=X0,Y0,X1,Y1: bench/ms_blender.py's slab cut to that footprint,
# from below the black ground to TOP (exrfog: box:min=X0,Y0,-1:max=X1,Y1,TOP with
# scattering=multiple:ground=0), the camera 2 up looking 8 degrees down along +y, facing the box's
# front face; MS_SUN_BOX_SPP samples (default 2048), 64x36, errors per 4x4 block. The scenes are
# those the independent column approximation failed on (bench/ms.md, stop 62; its g 0.85 case at
# g 0.6), a wider, thinner box, g 0.7 and 0.85 (beyond the harmonics: each camera bind scores
# the phase itself), and the camera inside a box (footprint -30..30 about it) at g 0.5 and 0.85.
# Only the last was used to choose anything (where the camera's own table starts, lit_vms.c).
# Then the cost at 1080p.
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms_sun_box.sh MS_SUN_BOX_SPP 2048 "${1:-build}"
# elevation density albedo g top footprint
cases=("30 0.1 0.95 0.5 10 sbox=-15,10,15,40" "30 0.3 0.95 0.5 10 sbox=-15,10,15,40"
       "10 0.1 0.95 0.5 10 sbox=-15,10,15,40" "10 0.3 0.95 0.5 10 sbox=-15,10,15,40"
       "60 0.3 0.8 0 5 sbox=-10,15,10,35" "30 0.1 0.99 0.6 10 sbox=-15,10,15,40"
       "5 0.2 0.95 0.5 10 sbox=-15,10,15,40" "30 1.0 0.95 0.5 10 sbox=-15,10,15,40"
       "20 0.2 0.9 0.3 8 sbox=-12,12,12,36" "45 0.5 0.99 0 6 sbox=-8,14,8,30"
       "40 0.3 0.95 0.6 3 sbox=-40,5,40,80" "30 0.1 0.95 0.7 10 sbox=-15,10,15,40"
       "30 0.1 0.99 0.85 10 sbox=-15,10,15,40" "30 0.1 0.95 0.5 10 sbox=-30,-30,30,30"
       "30 0.1 0.99 0.85 10 sbox=-30,-30,30,30")
if [[ -n "${MS_SUN_BOX_GRID:-}" ]]; then
    cp "$MS_SUN_BOX_GRID" "$tmp/grid.jsonl" || die "MS_SUN_BOX_GRID=$MS_SUN_BOX_GRID unreadable"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "$spp" "$1" "$2" "$3" "$4" "$5" \
            64 36 4 - "$6" >>"$tmp/grid.jsonl" || die "case $c failed"
    done
fi
lc_tag="a sun on a box of fog" lc_light="sun:towards=0.5,1,0.3:intensity=3" lamp_cost \
    "box:min=-10,0,-35:max=14,10,-15:density=0.1:albedo=0.9" \
    "box:min=-10,0,-35:max=14,10,-15:density=0.1:albedo=0.9:phase=hg:g=0.5"
ms_header "A sun's multiple scattering in a box of fog, against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, 64x36, $spp samples, volume bounces 0 and 128; bench/ms_blender.py with sbox=: homogeneous fog in a box over the footprint, from below a black ground to its top, a black world, a sun of strength 1, the camera 2 up looking 8 degrees down along +y"
echo "- exrfog: box:min=X0,Y0,-1:max=X1,Y1,TOP of the same density, albedo and HG g, --up-axis z, the same sun with scattering=single and =multiple:ground=0"
ms_errors_note 4
"$py" - "$tmp/grid.jsonl" "$tmp/cost" "$tmp/solves" "$here" <<'PYEOF'
import sys
sys.path.insert(0, sys.argv[4])
import ms_report
rows = ms_report.grid(sys.argv[1])
print("| sun elevation | box (x, y footprint; z to top) | density | albedo | g | single / Cycles (median) | single vs Cycles' bounces 0 | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered | multiple alone, exrfog / Cycles (frame means) |")
print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows:
    x0, y0, x1, y1 = r["sbox"].split(",")
    print("| %g | %s..%s, %s..%s; top %g | %s" % (r["elev"], x0, x1, y0, y1, r["top"], ms_report.case_cells(r)))
print()
ms_report.summary(rows)
print()
ms_report.cost_table("Cost at 1080p (make_sample's frame, a sun towards 0.5,1,0.3 on a box of fog ahead of the camera, 2 threads, medians of 5 runs)",
                     sys.argv[2], sys.argv[3])
PYEOF
