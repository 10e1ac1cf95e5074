#!/bin/bash
# bench/ms_lamp_cost.sh - what a lamp's multiple scattering costs at 1080p over the shots of
# bench/ms_lamp_height.sh, ms_lamp_box.sh and ms_spot.sh (issue 44's lamp target: 3x the lamp's
# single scattering), without the error output (no AOV: the estimate's reads are skipped) and
# against a base build's exrfog in the same run.
#
#   bench/ms_lamp_cost.sh [BUILD_DIR [BASE_EXRFOG]] > report.md
#
# Per shot, 3 rounds interleaved: scattering=single, the base's scattering=multiple (when
# given), this build's scattering=multiple and the oiiotool copy, 2 threads; medians.
set -u
build="${1:-build}"
base="${2:-}"
die() { echo "ms_lamp_cost.sh: $*" >&2; exit 1; }
[[ -x "$build/exrfog" && -x "$build/make_sample" ]] || die "$build/exrfog or make_sample not built"
[[ -z "$base" || -x "$base" ]] || die "$base: not an executable"
tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-ms-lamp-cost.XXXXXX")" || die "mktemp failed"
trap 'rm -rf "$tmp"' EXIT
load0="$(cut -d' ' -f1-3 /proc/loadavg)"
"$build/make_sample" "$tmp/f1.exr" --size 1920x1080 --view 2,-3,60 >/dev/null || die make_sample
"$build/make_sample" "$tmp/f2.exr" --size 1920x1080 --view 60,-20,60 >/dev/null || die make_sample
H="height:density=0.1:falloff=0.1:albedo=0.9"
HG="$H:phase=hg:g=0.5"
SP="spot:position=2,3,25:aim=0,-1,0.2:cone=40:blend=0.2:intensity=40"
BX="box:min=-10,0,-35:max=14,10,-15:density=0.1:albedo=0.9"
# tag|fog|frame|light
shots=("camera 2 up, lamp behind|$H|f1|point:position=2,3,25:intensity=40"
       "camera 2 up, lamp ahead|$H|f1|point:position=2,3,-15:intensity=40"
       "camera 2 up, lamp ahead|$HG|f1|point:position=2,3,-15:intensity=40"
       "camera 60 up, 20 degrees down|$H|f2|point:position=2,3,25:intensity=40"
       "a lamp in a box|$BX|f1|point:position=2,3,-25:intensity=40"
       "a lamp in a box|$BX:phase=hg:g=0.5|f1|point:position=2,3,-25:intensity=40"
       "a spot behind aimed down|exp:density=0.05:albedo=0.9|f1|$SP"
       "a spot behind aimed down|exp:density=0.05:albedo=0.9:phase=hg:g=0.5|f1|$SP"
       "a spot behind aimed down|$HG|f1|$SP")
timed() {   # KEY EXE ARGS...: appends "KEY SECONDS" to $tmp/t.txt
    local key=$1
    shift
    /usr/bin/time -f "%e" -o "$tmp/t" "$@" >/dev/null 2>"$tmp/err" || die "$* failed: $(cat "$tmp/err")"
    echo "$key|$(cat "$tmp/t")" >>"$tmp/t.txt"
}
for s in "${shots[@]}"; do
    IFS='|' read -r tag fog frame light <<<"$s"
    for _ in 1 2 3; do
        timed "$s|single" "$build/exrfog" "$tmp/$frame.exr" -o "$tmp/o.exr" --fog "$fog" --light "$light:scattering=single" --threads 2
        [[ -n "$base" ]] && timed "$s|base" "$base" "$tmp/$frame.exr" -o "$tmp/o.exr" --fog "$fog" --light "$light:scattering=multiple" --threads 2
        timed "$s|multiple" "$build/exrfog" "$tmp/$frame.exr" -o "$tmp/o.exr" --fog "$fog" --light "$light:scattering=multiple" --threads 2
        timed "$s|copy" oiiotool "$tmp/$frame.exr" -o "$tmp/o2.exr"
    done
done
echo "## A lamp's multiple scattering: cost at 1080p (issue 44)"
echo
echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $load0 before, $(cut -d' ' -f1-3 /proc/loadavg) after"
echo "- build: $build, source $(git -C "$(dirname "$0")" rev-parse --short HEAD 2>/dev/null)${base:+; base: $base}"
echo "- make_sample's frame (its camera looks along -z: a lamp at z = 25 is behind it), 2 threads, no AOV (the error output's estimate not computed), medians of 3 rounds interleaved"
echo
/usr/bin/python3 - "$tmp/t.txt" "$base" <<'PYEOF'
import collections, statistics as st, sys
d = collections.OrderedDict()
for l in open(sys.argv[1]):
    tag, fog, frame, light, run, t = l.rstrip("\n").split("|")
    d.setdefault((tag, fog, light), {}).setdefault(run, []).append(float(t))
base = bool(sys.argv[2])
print("| shot | fog | light | copy s | single s |" + (" base multiple s |" if base else "") + " multiple s |" + (" base / single |" if base else "") + " / single |")
print("|---|---|---|---:|---:|" + ("---:|" if base else "") + "---:|" + ("---:|" if base else "") + "---:|")
for (tag, fog, light), v in d.items():
    m = {k: st.median(x) for k, x in v.items()}
    row = "| %s | `%s` | `%s` | %.2f | %.2f |" % (tag, fog, light, m["copy"], m["single"])
    if base:
        row += " %.2f |" % m["base"]
    row += " %.2f |" % m["multiple"]
    if base:
        row += " %.2fx |" % (m["base"] / m["single"])
    print(row + " %.2fx |" % (m["multiple"] / m["single"]))
PYEOF
