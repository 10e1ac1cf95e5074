# bench/ms_lib.sh - what bench/ms_lamp.sh and bench/ms_lamp_height.sh share (sourced).

# lamp_cost FOG...: per fog, 5 rounds on the 1080p frame $tmp/f.exr (made
# here): exrfog with a point lamp scattering=single and =multiple on 2
# threads and the oiiotool copy, wall times appended to $tmp/cost as
# "FOG/RUN SECONDS"; the multiple scattering's solve time (--explain) to
# $tmp/solves as "FOG/solve SECONDS s". Needs the globals build, tmp, die.
lamp_cost() {
    "$build/make_sample" "$tmp/f.exr" --size 1920x1080 --view 2,-3,60 >/dev/null || die "make_sample"
    local fog r m
    for fog in "$@"; do
        for r in 1 2 3 4 5; do
            for m in single multiple; do
                /usr/bin/time -f "%e" -o "$tmp/t" "$build/exrfog" "$tmp/f.exr" -o "$tmp/o.exr" --fog "$fog" \
                    --light "point:position=2,3,25:intensity=40:scattering=$m" --threads 2 ||
                    die "exrfog $m"
                echo "$fog/$m $(cat "$tmp/t")" >>"$tmp/cost"
            done
            /usr/bin/time -f "%e" -o "$tmp/t" oiiotool "$tmp/f.exr" -o "$tmp/o2.exr" || die oiiotool
            echo "$fog/copy $(cat "$tmp/t")" >>"$tmp/cost"
        done
        "$build/exrfog" "$tmp/f.exr" --fog "$fog" --explain \
            --light "point:position=2,3,25:intensity=40:scattering=multiple" >"$tmp/explain.txt" 2>&1
        grep 'multiple scattering: solved' "$tmp/explain.txt" | grep -o '[0-9.]* s$' | head -1 |
            sed "s|^|$fog/solve |" >>"$tmp/solves"
    done
}
