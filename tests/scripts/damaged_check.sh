#!/bin/sh
# Every damaged or malicious file of openexr-images/Damaged (fuzzing
# reports against OpenEXR, deep scanline and deep tiled among them) is
# either refused with "exrfog: FILE: ..." and exit 1, or fogged (exit 0):
# never a crash, a hang, a sanitizer report or an output left behind by a
# failure.
# usage: damaged_check.sh EXRFOG SHARED_DIR TMPDIR   (exit 77: skipped)
exrfog=$1 dir=$2/real-exr/openexr-images/Damaged tmp=$3/damaged
[ -d "$dir" ] || { echo "no $dir: skipped"; exit 77; }
rm -rf "$tmp" && mkdir -p "$tmp" || exit 1
fail=0 n=0 refused=0 ran=0

. "$(dirname "$0")/judge.sh"
for f in "$dir"/*; do
    [ -f "$f" ] || continue
    case "$f" in *.rst) continue ;; esac
    for mode in samples; do
        n=$((n + 1))
        out="$tmp/out.exr"
        rm -f "$out"
        timeout 60 "$exrfog" "$f" -o "$out" --fog exp:density=0.1 --fov 40 \
            --world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --deep "$mode" \
            >"$tmp/stdout" 2>"$tmp/stderr"
        judge "$f ($mode)" $?
        ls -A "$tmp" | grep -q '^\.out' && { echo "FAIL: $f ($mode): temporary file left"; fail=1; rm -f "$tmp"/.out*; }
    done
done
# The deep reader on a real file's damage: the Arnold deep render cut
# short at 12 sizes, and 24 copies with bytes overwritten inside its chunks
# (sample tables and data alike).
arnold=$2/real-exr/arnold-deep-representative.exr
if [ -f "$arnold" ]; then
    size=$(stat -c %s "$arnold")
    i=1
    while [ $i -le 36 ]; do
        bad="$tmp/bad.exr"
        if [ $i -le 12 ]; then
            head -c $((size * i / 13)) "$arnold" >"$bad"
        else
            cp "$arnold" "$bad"
            off=$((size / 40 + (size - size / 40) / 25 * (i - 12)))
            printf '\377\377\377\177\000\001' | dd of="$bad" bs=1 seek=$off conv=notrunc 2>/dev/null
        fi
        for mode in samples flatten; do
            n=$((n + 1))
            out="$tmp/out.exr"
            rm -f "$out"
            timeout 120 "$exrfog" "$bad" -o "$out" --fog exp:density=0.1 --deep "$mode" \
                >"$tmp/stdout" 2>"$tmp/stderr"
            judge "damaged Arnold copy $i ($mode)" $?
        done
        i=$((i + 1))
    done
fi
echo "damaged: $n runs: $refused refused, $ran fogged"
exit $fail
