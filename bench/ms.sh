#!/bin/bash
# bench/ms.sh - multiple scattering (issue 44) against Blender Cycles with 128 volume bounces.
#
#   bench/ms.sh [BUILD_DIR] > bench/ms.md
#   MS_GRID=bench/ms_grid.jsonl bench/ms.sh [BUILD_DIR] > bench/ms.md   (re-time the cost alone)
#
# Over a grid of the fog's albedo (0.8, 0.95, 0.99), HG g (0, 0.5, 0.85) and the sun's
# elevation (5, 30, 80 degrees) in a slab of vertical optical depth 2, and the slab's optical
# depth (0.5, 8, 16; albedo 0.95, g 0.5, sun 30 degrees), bench/ms_compare.py renders
# bench/ms_blender.py's scene with Cycles (volume bounces 0 and 128, MS_SPP samples, default
# 4096, 64x36) and runs exrfog on its depth with scattering=single and =multiple. Errors are
# per 8x8 block of pixels (Cycles' noise averaged down), relative to Cycles' radiance; its own
# noise is the block mean's standard error. Then the cost at 1080p: the sun in height fog,
# single against multiple, and the solve's time and size over the grid of g and albedo.
set -u
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bench/ms_lib.sh
. "$here/ms_lib.sh"
ms_setup ms.sh MS_SPP 4096 "${1:-build}"
cases=()
for a in 0.8 0.95 0.99; do
    for g in 0 0.5 0.85; do
        for e in 5 30 80; do
            cases+=("$e 0.1 $a $g")
        done
    done
done
cases+=("30 0.025 0.95 0.5" "30 0.4 0.95 0.5" "30 0.8 0.95 0.5")
# layers whose albedo changes with height (three components: the mixture per depth node)
cases+=("30 0.1 0.95 0.5 25:0.03:0.99:0.5,12:0.07:0.9:0.5,5:0.2:0.8:0.5")
# a uniform sky of radiance 1 in place of the sun (--sky-light ...:scattering=multiple)
for a in 0.8 0.95 0.99; do
    for g in 0 0.85; do
        cases+=("30 0.1 $a $g - sky")
    done
done
cases+=("30 0.025 0.95 0.5 - sky" "30 0.4 0.95 0.5 - sky")
# the camera mid-fog (10 up) and above it looking down (40 up, 20 degrees down)
for c in "30 0.1 0.95 0.5 - sun" "5 0.1 0.95 0.5 - sun" "30 0.1 0.95 0.85 - sun" "30 0.1 0.95 0.5 - sky"; do
    cases+=("$c camz=10" "$c camz=40")
done
if [[ -n "${MS_GRID:-}" ]]; then
    # the grid of an earlier run (its JSON lines), to re-time the cost alone
    cp "$MS_GRID" "$tmp/grid.jsonl" || die "MS_GRID=$MS_GRID unreadable"
else
    for c in "${cases[@]}"; do
        # shellcheck disable=SC2086
        set -- $c
        "$py" "$here/ms_compare.py" "$build/exrfog" blender "$tmp" "$spp" "$1" "$2" "$3" "$4" 20 64 36 8 \
            ${5:+"$5"} ${6:+"$6"} ${7:+"$7"} >>"$tmp/grid.jsonl" || die "case $c failed"
    done
    cp "$tmp/grid.jsonl" "$here/ms_grid.jsonl"
fi
# the cost at 1080p: a sun in height fog, single against multiple, interleaved, from a
# camera 5 up looking 5 degrees down (the horizon and the sky in frame) and from one 60
# up looking 20 degrees down (long rays down through the fog)
fog="height:density=0.05:falloff=0.1:base=0:albedo=0.9:phase=hg:g=0.6"
sun="sun:towards=1,0.3,-1:intensity=3"
for v in low:5,-5,60 high:60,-20,60; do
    name=${v%%:*}
    "$build/make_sample" "$tmp/$name.exr" --size 1920x1080 --view "${v#*:}" >/dev/null || die "make_sample"
    for r in 1 2 3 4 5; do
        for m in single multiple; do
            /usr/bin/time -f "%e" -o "$tmp/t" "$build/exrfog" "$tmp/$name.exr" -o "$tmp/o.exr" \
                --fog "$fog" --light "$sun:scattering=$m$( [[ $m == multiple ]] && echo :ground=0)" \
                --threads 2 || die "exrfog $m"
            echo "$name/$m $(cat "$tmp/t")" >>"$tmp/cost"
        done
        /usr/bin/time -f "%e" -o "$tmp/t" oiiotool "$tmp/$name.exr" -o "$tmp/o2.exr" || die oiiotool
        echo "$name/copy $(cat "$tmp/t")" >>"$tmp/cost"
    done
done
"$build/ms_info" >"$tmp/solves" 2>&1 || die "ms_info"
ms_header "Multiple scattering against Cycles (issue 44)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, $spp samples, 64x36, volume bounces 0 and 128 (max bounces 128, transparent at the default); bench/ms_blender.py's slab (homogeneous, ground z = 0 black, top z = 20, 4 km wide), camera 2 up looking 8 degrees down (or 10 up, or 40 up looking 20 degrees down: above the fog), sun of strength 1 at azimuth 150 degrees"
echo "- exrfog: halfspace:plane=0,0,1,-20 with the same density, albedo and HG g, the sun with scattering=multiple:ground=0 (or --sky-light of a constant map of 1 with scattering=multiple:ground=0 against Cycles' uniform world of strength 1), on the render without fog (black where the sun lights it: the output is the fog's light alone)"
echo "- errors per 8x8 block, relative to Cycles' radiance with every bounce; 'covered': |exrfog - Cycles| within exrfog's error output plus twice Cycles' noise"
echo
"$py" - "$tmp/grid.jsonl" "$tmp/cost" "$tmp/solves" <<'EOF'
import json, sys, statistics as st
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| light | camera up | sun elev | vertical tau | albedo | g | single / Cycles (median) | exrfog single vs Cycles' bounces 0 | median \\|err\\| | 99th \\|err\\| | signed median | Cycles noise | error output (median) | covered |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows:
    sky = r.get("sky")
    print("| %s | %g | %s | %g | %s | %g | %s | %s | %.2f %% | %.2f %% | %+.2f %% | %.2f %% | %.2f %% | %.0f %% |" % (
        "sky" if sky else "sun", r.get("camz", 2.0), "-" if sky else "%g" % r["elev"], r["vertical_tau"],
        r["albedo"] if not r.get("layers") else "layers " + r["layers"], r["g"],
        "-" if sky else "%.3f" % r["single_share_median"],
        "-" if sky else "%+.2f %%" % (100 * r["single_check_median"]), 100 * r["rel_median"],
        100 * r["rel_p99"], 100 * r["rel_signed_median"], 100 * r["noise_rel_median"],
        100 * r["err_rel_median"], 100 * r["covered"]))
for name, sel in (("sun", [r for r in rows if not r.get("sky")]), ("sky", [r for r in rows if r.get("sky")])):
    if not sel:
        continue
    med = st.median([r["rel_median"] for r in sel])
    worst = max(sel, key=lambda r: r["rel_p99"])
    print()
    print("The %s, %d cases: the median of the per-case median errors %.2f %%, the worst 99th percentile %.2f %% (%s); the error output covers >= 99 %% of blocks in %d cases, >= 90 %% in %d." % (
        name, len(sel), 100 * med, 100 * worst["rel_p99"], worst["case"],
        sum(r["covered"] >= 0.99 for r in sel), sum(r["covered"] >= 0.9 for r in sel)))
cost = {}
for l in open(sys.argv[2]):
    k, v = l.split()
    cost.setdefault(k, []).append(float(v))
m = {k: st.median(v) for k, v in cost.items()}
print()
print("### Cost at 1080p (a sun in height fog over ground=0, 2 threads, medians of 5 runs)")
print()
print("| camera | run | wall s | / single | / oiiotool copy |")
print("|---|---|---:|---:|---:|")
for cam, what in (("low", "5 up, 5 degrees down"), ("high", "60 up, 20 degrees down")):
    for k in ("copy", "single", "multiple"):
        v = m[cam + "/" + k]
        print("| %s | %s | %.3f | %.2fx | %.2fx |" % (what, k, v, v / m[cam + "/single"],
                                                    v / m[cam + "/copy"]))
print()
print("### The solve over albedo and g (bench/ms_info: a sun 30 degrees up in height fog)")
print()
print("```")
print(open(sys.argv[3]).read().rstrip())
print("```")
EOF
