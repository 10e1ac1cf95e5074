#!/bin/sh
# A --depth in any format OpenImageIO reads, truncated at a quarter, a
# half, three quarters and 99 % of its length, is refused with
# "exrfog: FILE: cannot read the depth image ..." and exit 1, and writes
# nothing, in one message of exrfog's own (libpng's raw line folded in);
# the whole file is accepted. A cut that leaves every pixel (a
# PNG missing only its end chunk) may be accepted, but must then give the
# whole file's pixels. (OpenImageIO's readers can return success with
# their errors pending: every error is checked.)
# usage: depth_trunc_check.sh EXRFOG MAKE_SAMPLE TMPDIR   (77: no oiiotool)
exrfog=$1 make_sample=$2 tmp=$3/depth_trunc
here=$(cd "$(dirname "$0")" && pwd)
command -v oiiotool >/dev/null 2>&1 || { echo "no oiiotool: skipped"; exit 77; }
rm -rf "$tmp" && mkdir -p "$tmp" && cd "$tmp" || exit 1
"$make_sample" in.exr --size 160x90 >/dev/null || exit 1
fail=0 n=0
for spec in "z.tif -d float" "zh.tif -d half" "zc.tif -d float --compression zip" \
            "z.png -d uint16" "z.dpx -d uint16"; do
    set -- $spec
    f=$1; shift
    # A smooth depth from 10 to 110 (a ramp), so the whole file fogs.
    oiiotool --pattern fill:topleft=10:topright=60:bottomleft=60:bottomright=110 160x90 1 \
        "$@" -o "$f" 2>/dev/null || { echo "FAIL: oiiotool cannot write $f"; fail=1; continue; }
    "$exrfog" in.exr --depth "$f" -o whole.exr --fog exp:density=0.02 -q 2>err.txt ||
        { echo "FAIL: $f whole: $(cat err.txt)"; fail=1; }
    size=$(wc -c < "$f")
    for frac in 25 50 75 99; do
        head -c $((size * frac / 100)) "$f" > "t_$f"
        rm -f out.exr
        "$exrfog" in.exr --depth "t_$f" -o out.exr --fog exp:density=0.02 2>err.txt
        rc=$?
        n=$((n + 1))
        if [ $rc -eq 0 ]; then
            oiiotool out.exr whole.exr --diff --fail 0 >/dev/null 2>&1 ||
                { echo "FAIL: $f cut to $frac %: accepted with other pixels"; fail=1; }
            continue
        fi
        if [ $rc -ne 1 ] || ! grep -q "^exrfog: t_$f: cannot read the depth image" err.txt; then
            echo "FAIL: $f cut to $frac %: exit $rc: $(head -c 300 err.txt)"; fail=1
        fi
        # One line, exrfog's: a reader's raw lines (libpng's) are folded in.
        [ "$(grep -vc '^exrfog: ' err.txt)" = 0 ] ||
            { echo "FAIL: $f cut to $frac %: raw lines on stderr: $(grep -v '^exrfog: ' err.txt | head -2)"; fail=1; }
        [ -e out.exr ] && { echo "FAIL: $f cut to $frac %: output written"; fail=1; }
    done
done
# fuzz_depth's finding: a 372-byte BMP claiming 13 million pixels a row
# took 1 GB before its truncation was found; now refused unread.
huge="$here/../../fuzz/regressions_depth/huge-row.bmp"
rm -f out.exr
"$exrfog" in.exr --depth "$huge" -o out.exr --fog exp:density=0.02 2>err.txt
rc=$?
{ [ $rc -eq 1 ] && grep -q "far more than the colour image has" err.txt && [ ! -e out.exr ]; } ||
    { echo "FAIL: huge-row.bmp: exit $rc: $(head -c 300 err.txt)"; fail=1; }
[ $fail = 0 ] && echo "depth truncations: $n runs (refused, or the whole pixels), 5 whole files accepted"
exit $fail
