# bench/ms_lib.sh - what bench/ms.sh, ms_lamp.sh and ms_lamp_height.sh share (sourced).

# ms_setup NAME SPP_VAR DEFAULT_SPP [BUILD_DIR]: the globals build (default
# build), spp (the variable SPP_VAR or the default), py, tmp (removed on
# exit), load0 and die (messages prefixed NAME); checks exrfog, make_sample
# and Blender.
ms_setup() {
    ms_name=$1
    local sv=$2
    build="${4:-build}"
    spp="${!sv:-$3}"
    die() { echo "$ms_name: $*" >&2; exit 1; }
    [[ -x "$build/exrfog" ]] || die "$build/exrfog not built"
    [[ -x "$build/make_sample" ]] || die "$build/make_sample not built"
    command -v blender >/dev/null || die "blender not found (apt-get install -y blender)"
    py=/usr/bin/python3
    tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-${ms_name%.sh}.XXXXXX")" || die "mktemp failed"
    trap 'rm -rf "$tmp"' EXIT
    load0="$(cut -d' ' -f1-3 /proc/loadavg)"
}

# ms_header TITLE: the report's title and its date, machine (with the load
# ms_setup read and the load now) and build lines (needs here).
ms_header() {
    echo "## $1"
    echo
    echo "- date: $(date -u '+%Y-%m-%d %H:%M UTC')"
    echo "- machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $load0 before, $(cut -d' ' -f1-3 /proc/loadavg) after"
    echo "- build: $build, source $(git -C "$here" rev-parse --short HEAD 2>/dev/null)"
}

# lamp_cost FOG...: per fog, 5 rounds on a 1080p frame made here from the
# view lc_view (make_sample's --view; default 2,-3,60, a camera 2 up
# looking 3 degrees down, along -z): exrfog with a point lamp at lc_lamp (default
# 2,3,25: behind the camera) scattering=single and =multiple on 2 threads and the
# oiiotool copy, wall times appended to $tmp/cost as "KEY/RUN SECONDS"; the
# multiple scattering's solve time (--explain) to $tmp/solves as
# "KEY/solve SECONDS s". KEY is the fog, after "lc_tag: " when lc_tag is
# set. lc_light replaces the lamp's spec (scattering= is added). Needs the
# globals build, tmp, die.
lamp_cost() {
    local view="${lc_view:-2,-3,60}" lamp="${lc_lamp:-2,3,25}" fog key r m
    local light="${lc_light:-point:position=$lamp:intensity=40}"
    "$build/make_sample" "$tmp/f.exr" --size 1920x1080 --view "$view" >/dev/null || die "make_sample"
    for fog in "$@"; do
        key="${lc_tag:+$lc_tag: }$fog"
        for r in 1 2 3 4 5; do
            for m in single multiple; do
                /usr/bin/time -f "%e" -o "$tmp/t" "$build/exrfog" "$tmp/f.exr" -o "$tmp/o.exr" --fog "$fog" \
                    --light "$light:scattering=$m" --threads 2 ||
                    die "exrfog $m"
                echo "$key/$m $(cat "$tmp/t")" >>"$tmp/cost"
            done
            /usr/bin/time -f "%e" -o "$tmp/t" oiiotool "$tmp/f.exr" -o "$tmp/o2.exr" || die oiiotool
            echo "$key/copy $(cat "$tmp/t")" >>"$tmp/cost"
        done
        "$build/exrfog" "$tmp/f.exr" --fog "$fog" --explain \
            --light "$light:scattering=multiple" >"$tmp/explain.txt" 2>&1
        grep 'multiple scattering: solved' "$tmp/explain.txt" | grep -o '[0-9.]* s$' | head -1 |
            sed "s/^/$key\/solve /" >>"$tmp/solves"
    done
}

# ms_errors_note BLOCK: the report's line on how errors are counted, and a blank line.
ms_errors_note() {
    echo "- errors per $1x$1 block, relative to Cycles' radiance with every bounce; 'covered': |exrfog - Cycles| within exrfog's error output plus twice Cycles' noise"
    echo
}
