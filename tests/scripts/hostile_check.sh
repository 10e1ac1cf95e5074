#!/bin/sh
# The hostile campaign's cheap categories, rerun on every build: small
# frames of four kinds (ZIP and PIZ scanline, ZIP tiled, DWAA) cut short at
# 15 lengths and with 6 bytes overwritten at 40 places (pixel data, offset
# tables and headers alike), each fogged: exit 0 with an output, or exit
# 1/2 with an "exrfog: " message and nothing left behind; never a crash, a
# hang or a sanitizer report.
# usage: hostile_check.sh EXRFOG MAKE_SAMPLE TMPDIR   (77: no oiiotool)
exrfog=$1 make_sample=$2 tmp=$3/hostile
command -v oiiotool >/dev/null 2>&1 || { echo "no oiiotool: skipped"; exit 77; }
rm -rf "$tmp" && mkdir -p "$tmp" || exit 1
fail=0 n=0 refused=0 ran=0
. "$(dirname "$0")/judge.sh"
"$make_sample" "$tmp/zip.exr" --size 64x36 --compression zip >/dev/null || exit 1
"$make_sample" "$tmp/piz.exr" --size 64x36 --compression piz >/dev/null || exit 1
oiiotool "$tmp/zip.exr" --tile 16 16 -o "$tmp/tiled.exr" || exit 1
oiiotool "$tmp/zip.exr" --compression dwaa -o "$tmp/dwaa.exr" || exit 1
out="$tmp/out.exr"
for kind in zip piz tiled dwaa; do
    src="$tmp/$kind.exr"
    size=$(wc -c < "$src")
    i=1
    while [ $i -le 55 ]; do
        bad="$tmp/bad.exr"
        if [ $i -le 15 ]; then
            head -c $((size * i / 16)) "$src" > "$bad"
        else
            cp "$src" "$bad"
            # places spread over the whole file, the header's first bytes too
            off=$(( (size - 6) * (i - 16) / 39 ))
            printf '\377\377\377\177\000\001' | dd of="$bad" bs=1 seek=$off conv=notrunc 2>/dev/null
        fi
        n=$((n + 1))
        rm -f "$out"
        timeout 60 "$exrfog" "$bad" -o "$out" --fog exp:density=0.1 --threads 2 \
            >"$tmp/stdout" 2>"$tmp/stderr"
        judge "$kind copy $i" $?
        ls -A "$tmp" | grep -q '^\.out' && { echo "FAIL: $kind copy $i: temporary file left"; fail=1; rm -f "$tmp"/.out*; }
        i=$((i + 1))
    done
done
echo "hostile: $n runs: $refused refused, $ran fogged"
exit $fail
