#!/bin/bash
# bench/ms_lamp_layered.sh - a point lamp's multiple scattering in layered fog (issue 44: the
# density linear between knots in height) against Blender Cycles with 128 volume bounces, and
# what the error output's leak term covers where the profile thins (ms.h, ef_lms_local_node).
#
#   bench/ms_lamp_layered.sh [BUILD_DIR] > bench/ms_lamp_layered.md
#   MS_LAMP_LAYERED_GRID=FILE bench/ms_lamp_layered.sh [BUILD_DIR]   (re-print a grid of ms_compare lines)
#
# bench/ms_compare.py with lamp=10 and lay=H0/F0,H1/F1,... (DENSITY times factors linear between
# the knots' heights, constant beyond; exrfog: layered:heights=:densities=), bench/ms_lamp_blender.py's
# lamp at (1.5, 10, 1) and camera at the origin looking along +y, MS_LAMP_LAYERED_SPP samples
# (default 1024), 64x36, errors per 4x4 block. Every row is a test: the leak term's weight was set
# on bench/ms_lamp_box.sh's calib scenes and is not changed for layers. Then the cost at 1080p.
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms_lamp_layered.sh MS_LAMP_LAYERED_SPP 1024 "${1:-build}"
# density albedo g knots [behind]
cases=("0.2 0.95 0.5 lay=2/1,5/0" "0.3 0.9 0 lay=0/1,3/0.2,8/0" "0.15 0.99 0.3 lay=-1/1,1.5/0.3,4/0"
       "0.2 0.95 0.5 lay=-2/0,4/1" "0.25 0.95 0.5 lay=1/1,1.5/0" "0.1 0.95 0.5 lay=2/1,6/0 behind")
if [[ -n "${MS_LAMP_LAYERED_GRID:-}" ]]; then
    cp "$MS_LAMP_LAYERED_GRID" "$tmp/grid.jsonl" || die "MS_LAMP_LAYERED_GRID=$MS_LAMP_LAYERED_GRID unreadable"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "$spp" 0 "$1" "$2" "$3" 0 64 36 4 \
            - lamp=10 "${@:4}" >>"$tmp/grid.jsonl" || die "case $c failed"
    done
fi
lc_tag="a lamp under layers' soft top" lc_lamp=2,1,-25 lamp_cost \
    "layered:heights=2,5:densities=0.1,0:albedo=0.9" \
    "layered:heights=2,5:densities=0.1,0:albedo=0.9:phase=hg:g=0.5"
ms_header "A point lamp's multiple scattering in layered fog, against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, 64x36, $spp samples, volume bounces 0 and 128; bench/ms_lamp_blender.py with lay=: the density DENSITY times a factor linear between the knots (height/factor) and constant beyond, homogeneous below and above the knots, marched between them; a black world, the camera at the origin looking along +y (60 degrees), a point lamp of 100 W (radius 0) at (1.5, 10, 1)"
echo "- exrfog: layered:heights=:densities= of the same profile, albedo and HG g, --up-axis z, point:position=1.5,10,1:intensity=100/(4 pi) with scattering=single and =multiple"
ms_errors_note 4
"$py" - "$tmp/grid.jsonl" "$tmp/cost" "$tmp/solves" "$here" <<'PYEOF'
import sys
sys.path.insert(0, sys.argv[4])
import ms_report
rows = ms_report.grid(sys.argv[1])
print("| knots (height/factor) | density | albedo | g | single / Cycles (median) | single vs Cycles' bounces 0 | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered | multiple alone, exrfog / Cycles (frame means) |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows:
    geo = r["lay"].replace(",", " ")
    if r.get("behind"):
        geo += ", the lamp behind the camera"
    print("| %s | %s" % (geo, ms_report.case_cells(r)))
print()
ms_report.summary(rows)
print()
ms_report.cost_table("Cost at 1080p (a point lamp at 2,1,-25 under the soft top of layered fog, 2 threads, medians of 5 runs)",
                     sys.argv[2], sys.argv[3])
PYEOF
