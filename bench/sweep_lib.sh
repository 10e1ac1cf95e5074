# bench/sweep_lib.sh - what the before/after sweeps share (sourced by
# lit_quad_sweep.sh and ms_sweep.sh).

# sweep_setup NAME PREFIX DEFAULT_SIZE BEFORE AFTER [BUILD_DIR]: the
# globals before, after, build, size (PREFIX_SIZE or the default), rounds
# (PREFIX_ROUNDS or 2), die, and tmp (removed on exit)
sweep_setup() {
    local name=$1 prefix=$2
    local sz=${prefix}_SIZE rd=${prefix}_ROUNDS
    sweep_name=$name
    (($# >= 5)) || die "usage: $name BEFORE_EXRFOG AFTER_EXRFOG [BUILD_DIR]"
    before=$4
    after=$5
    build="${6:-build}"
    size="${!sz:-$3}"
    rounds="${!rd:-2}"
    for b in "$before" "$after" "$build/make_sample"; do [[ -x "$b" ]] || die "$b missing"; done
    tmp="$(mktemp -d "${TMPDIR:-/tmp}/exrfog-$name.XXXXXX")" || die "mktemp failed"
    trap 'rm -rf "$tmp"' EXIT
}
die() { echo "$sweep_name: $*" >&2; exit 1; }

# make_sample frames, one per "name:height,pitch,fov", into $tmp/name.exr
sweep_frames() {
    local v
    for v in "$@"; do
        "$build/make_sample" "$tmp/${v%%:*}.exr" --size "$size" --view "${v#*:}" >/dev/null ||
            die "make_sample ${v%%:*}"
    done
}

# the median of the numbers on stdin (spaces or lines)
median() { tr ' ' '\n' | grep . | sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }

# the largest |after - before| / max(|before|, 1e-3) over two float
# outputs' RGB
max_rel_diff() {
    /usr/bin/python3 - "$1" "$2" <<'PY'
import sys
import numpy as np
import OpenImageIO as oiio
b = oiio.ImageBuf(sys.argv[1]).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)
a = oiio.ImageBuf(sys.argv[2]).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)
print("%.2g" % float((np.abs(a - b) / np.maximum(np.abs(b), 1e-3)).max()))
PY
}
