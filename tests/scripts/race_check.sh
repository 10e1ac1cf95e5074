#!/bin/sh
# The temporary-file race of the hostile campaign, for every output path:
# while exrfog runs (a slow noise fog), an attacker who can write OUTPUT's
# directory keeps replacing every temporary file there with a symlink to a
# file of someone else's. That file must come out untouched, and OUTPUT
# must never end up as the attacker's link: exrfog finishes with its own
# file or fails naming the replacement. EXR, TIFF and PNG (through
# OpenImageIO), DWAA (through the C++ library), and a --preview.
# usage: race_check.sh EXRFOG MAKE_SAMPLE TMPDIR
exrfog=$1 make_sample=$2 tmp=$3/race
rm -rf "$tmp" && mkdir -p "$tmp/out" || exit 1
cd "$tmp" || exit 1
"$make_sample" in.exr --size 160x90 >/dev/null || exit 1
printf 'not yours\n' > victim.txt
fail=0 swaps=0
for target in out/f.exr out/f.tif out/f.png "out/f.exr --compression dwaa" "out/g.exr --preview out/p.png"; do
    set -- $target
    out=$1; shift
    rm -f out/* out/.[!.]* 2>/dev/null
    "$exrfog" in.exr -o "$out" "$@" --threads 1 \
        --fog noise:density=0.05:scale=2:octaves=4:method=exact 2>err.txt &
    pid=$!
    while kill -0 $pid 2>/dev/null; do
        for t in out/.*exrfog-*; do
            [ -f "$t" ] && [ ! -L "$t" ] || continue
            mv "$t" "$t.stolen" 2>/dev/null && ln -s "$tmp/victim.txt" "$t" && swaps=$((swaps + 1))
        done
    done
    wait $pid
    rc=$?
    [ "$(cat victim.txt)" = "not yours" ] || { echo "FAIL: $target: the victim was written"; fail=1; }
    printf 'not yours\n' > victim.txt
    if [ -L "$out" ]; then
        echo "FAIL: $target: OUTPUT is the attacker's link"; fail=1
    elif [ $rc -eq 0 ]; then
        [ -f "$out" ] || { echo "FAIL: $target: exit 0 without OUTPUT"; fail=1; }
    else
        grep -q "^exrfog: .*replaced" err.txt ||
            { echo "FAIL: $target: exit $rc without naming the replacement: $(head -c 300 err.txt)"; fail=1; }
    fi
done
[ $swaps -gt 0 ] || { echo "FAIL: no temporary file was ever replaced (the race was not run)"; fail=1; }
[ $fail = 0 ] && echo "race: $swaps temporary files replaced by links; no victim written, no link left as OUTPUT"
exit $fail
