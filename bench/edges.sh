#!/bin/bash
# bench/edges.sh - fog at the edges of flat renders (issue 45): --edges
# unmix against renders with the fog inside the scene, against the deep
# file's own flatten, and its cost at 1080p.
#
#   bench/edges.sh [BUILD_DIR] [SHARED_DIR] [OUT_DIR] > bench/edges.md
#
# 1. Blender (Debian's) renders each scene of bench/edges_blender.py (thin
#    poles/fence/wire, leaf cards with alpha textures, a fast pole with
#    motion blur, a shallow depth of field; and the calib scene the error
#    output's constants were set on) at 320x180, 256 samples, fog density
#    0.05 (the thin scene also 0.01 and 0.2), twice:
#    without fog, and with the fog as an emission-absorption volume inside
#    the scene (the truth). bench/edges_eval.py fogs the first with exrfog
#    without and with --edges unmix and scores the edge pixels.
# 2. bench/edges_deep.py: Weta's deep elements (SHARED/real-exr), merged,
#    as a flat render with the nearest sample's Z (closest) and with the
#    mean Z (filtered), against --deep flatten of the merged file; two fog
#    densities.
# 3. The thin scene at 1920x1080 (16 samples), float and half: exrfog
#    without and with --edges, exp and height fog, 8 runs each by perf
#    stat (mean wall time), interleaved.
# Pictures of the error before and after (max over RGB of |out - truth|,
# white at 0.1) go to OUT_DIR (default bench/edges).
set -u
build="${1:-build}"
shared="${2:-../shared}"
out="${3:-bench/edges}"
here="$(cd "$(dirname "$0")" && pwd)"
die() { echo "edges.sh: $*" >&2; exit 1; }
[[ -x "$build/exrfog" ]] || die "$build/exrfog not built"
command -v blender >/dev/null || die "blender not found (apt-get install -y blender)"
command -v perf >/dev/null || die "perf not found"
exrfog="$(cd "$(dirname "$build/exrfog")" && pwd)/exrfog"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-edges.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
t0=$(date +%s)
echo "## exrfog --edges unmix: fog at the edges of flat renders"
echo
echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'); load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "- build: $build, source $(git -C "$here" rev-parse --short HEAD 2>/dev/null)"
echo "- Blender $(blender --version 2>/dev/null | head -1 | cut -d' ' -f2), Cycles CPU, default pixel filter (Blackman-Harris 1.5 px), 320x180, 256 samples; the fog exp:density=0.05 (the thin scene also 0.01 and 0.2) with colour 0.7,0.75,0.8 as an emission-absorption volume around everything, every surface only emitting (each camera sample's colour is then exactly c T + F (1 - T))"
echo "- edge pixels: the depth of their 3x3 window spans a ratio over 1.05 (sky infinitely far); error: max over RGB of |out - truth|; 'off by 2 %': relative to the truth; 'covered': the error output (--aov error) at least the fixed run's actual error, beyond the truth's own noise (its 99th percentile on interior pixels, where the naive run is exact)"
echo
echo "### Against the fog rendered inside the scene"
echo
echo "| scene | edge pixels | naive RMS | --edges RMS | ratio | naive off by 2 % | --edges off by 2 % | ratio | off by 10 %: naive, --edges | interior pixels changed | error output covers |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|"
for vd in thin:0.05 cards:0.05 motion:0.05 dof:0.05 calib:0.05 thin:0.01 thin:0.2; do
    v=${vd%%:*} dens=${vd#*:}
    d="$tmp/$v-$dens"
    mkdir -p "$d"
    blender -b --factory-startup --python "$here/edges_blender.py" -- "$d" "$v" 320 180 256 "$dens" \
        >"$d/log" 2>&1 || die "blender $v $dens"
    grep -q "edges_blender: rendered" "$d/log" || die "blender $v: no render"
    png="$out/$v"
    [[ "$dens" == 0.05 ]] || png="$tmp/$v-$dens"
    /usr/bin/python3 "$here/edges_eval.py" "$exrfog" "$d" --png "$png" >"$d/res.json" || die "eval $v"
    if [[ "$v" == thin && "$dens" == 0.05 ]]; then
        # a crop of the fence and a pole: without --edges | with | the truth
        for k in out_naive out_edges fog; do
            oiiotool "$d/$k.exr" --ch "ViewLayer.Combined.R,ViewLayer.Combined.G,ViewLayer.Combined.B" \
                --cut 60x40+95+95 --resize:filter=box 240x160 --colorconvert linear sRGB \
                -o "$tmp/crop_$k.png" 2>/dev/null || die "crop $k"
        done
        oiiotool "$tmp/crop_out_naive.png" "$tmp/crop_out_edges.png" "$tmp/crop_fog.png" \
            --mosaic:pad=4 3x1 -o "$out/thin_crop.png" 2>/dev/null || die "mosaic"
    fi
    /usr/bin/python3 - "$d/res.json" "$v" "$dens" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1])); n, e = r["naive"], r["edges"]
name = sys.argv[2] + (" (calibration, not a test)" if sys.argv[2] == "calib" else "")
name += ", density %s" % sys.argv[3]
print("| %s | %d | %.4f | %.4f | %.0f %% | %d | %d | %.0f %% | %d, %d | %s | %.1f %% |" % (
    name, r["edge_px"], n["rms"], e["rms"], 100 * r["rms_ratio"], n["over2"], e["over2"],
    100 * r["over2_ratio"], n["over10"], e["over10"],
    "none" if r["interior_change"] == 0 else "%.2g" % r["interior_change"], 100 * r["cover"]))
EOF
done
echo
echo "### Against the deep file's own flatten (Weta's elements, merged)"
echo
echo "| flat Z | fog | edge pixels | naive RMS | --edges RMS | ratio | naive off by 2 % | --edges off by 2 % | ratio | interior change | error output covers |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
for z in closest filtered; do
    for dens in 0.005 0.02; do
        /usr/bin/python3 "$here/edges_deep.py" "$exrfog" "$tmp/weta" --shared "$shared" \
            --fog "exp:density=$dens" --z "$z" >"$tmp/w.json" 2>/dev/null || die "edges_deep $z $dens"
        /usr/bin/python3 - "$tmp/w.json" <<'EOF'
import json, sys
r = json.loads(open(sys.argv[1]).read().strip().splitlines()[-1]); n, e = r["naive"], r["edges"]
print("| %s | %s | %d | %.4f | %.4f | %.0f %% | %d | %d | %.0f %% | %.2g | %.1f %% |" % (
    r["z"], r["fog"], r["edge_px"], n["rms"], e["rms"], 100 * e["rms"] / n["rms"], n["over2"],
    e["over2"], 100 * e["over2"] / max(n["over2"], 1), r["interior_change"], 100 * r["cover"]))
EOF
    done
done
echo
echo "### Cost at 1920x1080 (the thin scene, 16 samples; mean of 8 runs by perf stat, 2 threads)"
echo
d="$tmp/hd"
mkdir -p "$d"
blender -b --factory-startup --python "$here/edges_blender.py" -- "$d" thin 1920 1080 16 0.05 \
    >"$d/log" 2>&1 || die "blender hd"
oiiotool "$d/nofog.exr" -d half -d ViewLayer.Depth.Z=float --compression zip -o "$d/half.exr"
flags=$(/usr/bin/python3 -c "
import json; f=json.load(open('$d/flags.json'))
print(' '.join(['--layer','ViewLayer.Combined','--depth-channel','ViewLayer.Depth.Z','--up-axis','z','--camera-convention','blender','--camera-to-world',','.join(repr(v) for v in f['camera_to_world']),'--fov',repr(f['fov']),'--near',repr(f['near']),'--far',repr(f['far'])]))")
echo "| input | fog | without --edges s | with --edges s | ratio |"
echo "|---|---|---:|---:|---:|"
for inp in nofog half; do
    for fog in "exp:density=0.05" "height:density=0.05:falloff=0.3"; do
        declare -A m
        for e in off unmix; do
            # shellcheck disable=SC2086
            m[$e]=$(perf stat -r 8 "$exrfog" "$d/$inp.exr" -o "$d/o_$e.exr" $flags --fog "$fog" \
                --edges "$e" 2>&1 | awk '/time elapsed/{print $1}')
        done
        awk -v i="$inp" -v f="$fog" -v a="${m[off]}" -v b="${m[unmix]}" \
            'BEGIN{printf "| %s | `%s` | %.3f | %.3f | %.2fx |\n", i == "half" ? "half RGBA + float Z" : "float (Blender'"'"'s 32-bit EXR)", f, a, b, b / a}'
    done
done
echo
echo "- run time $(( $(date +%s) - t0 )) s"
