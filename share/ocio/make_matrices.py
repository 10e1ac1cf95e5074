#!/usr/bin/env python3
"""Matrices of exrfog's OpenColorIO config (share/ocio/exrfog-config.ocio).

Plain Python 3 (no numpy). Prints every MatrixTransform of the config as the
YAML line to paste; `make_matrices.py --check exrfog-config.ocio` exits 1 if
the config does not contain each of them verbatim (run by ctest).

Primaries and white points (CIE 1931 xy):
  ACES AP0   R (0.7347, 0.2653)  G (0.0000, 1.0000)  B (0.0001, -0.0770)
  ACES AP1   R (0.713, 0.293)    G (0.165, 0.830)    B (0.128, 0.044)
  ACES white (0.32168, 0.33767)  -- SMPTE ST 2065-1:2012 (AP0) and
             Academy S-2014-004 (ACEScg, AP1); both use the ACES white.
  Rec.709    R (0.64, 0.33)      G (0.30, 0.60)      B (0.15, 0.06)
             -- ITU-R BT.709-6 (also the sRGB primaries, IEC 61966-2-1)
  Rec.2020   R (0.708, 0.292)    G (0.170, 0.797)    B (0.131, 0.046)
             -- ITU-R BT.2020-2
  P3-D65     R (0.680, 0.320)    G (0.265, 0.690)    B (0.150, 0.060)
             -- SMPTE EG 432-1 (Display P3 primaries)
  D65 white  (0.3127, 0.3290)    -- BT.709 / BT.2020 / sRGB

Between different white points the adaptation is von Kries in the Bradford
cone space (the matrix below, as in the ACES "_BFD" transforms and
colour-science's 'Bradford'); it maps the source white exactly onto the
destination white. RGB->XYZ is the usual normalised primary matrix (Y of
the white = 1, SMPTE RP 177).
"""
import sys

AP0 = ((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.0770))
AP1 = ((0.713, 0.293), (0.165, 0.830), (0.128, 0.044))
REC709 = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06))
REC2020 = ((0.708, 0.292), (0.170, 0.797), (0.131, 0.046))
P3 = ((0.680, 0.320), (0.265, 0.690), (0.150, 0.060))
ACES_WHITE = (0.32168, 0.33767)
D65 = (0.3127, 0.3290)

BRADFORD = ((0.8951, 0.2664, -0.1614),
            (-0.7502, 1.7135, 0.0367),
            (0.0389, -0.0685, 1.0296))


def mul(a, b):
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3))
                 for i in range(3))


def mulv(a, v):
    return tuple(sum(a[i][k] * v[k] for k in range(3)) for i in range(3))


def inv(m):
    (a, b, c), (d, e, f), (g, h, i) = m
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return ((( e * i - f * h) / det, -(b * i - c * h) / det, ( b * f - c * e) / det),
            (-(d * i - f * g) / det, ( a * i - c * g) / det, -(a * f - c * d) / det),
            (( d * h - e * g) / det, -(a * h - b * g) / det, ( a * e - b * d) / det))


def xyz(xy):
    x, y = xy
    return (x / y, 1.0, (1.0 - x - y) / y)


def npm(prim, white):
    """RGB -> XYZ for the given primaries and white (white Y = 1)."""
    p = tuple(xyz(c) for c in prim)
    m = tuple(tuple(p[j][i] for j in range(3)) for i in range(3))  # columns = primaries
    s = mulv(inv(m), xyz(white))
    return tuple(tuple(m[i][j] * s[j] for j in range(3)) for i in range(3))


def cat(src, dst):
    """Bradford adaptation XYZ(src white) -> XYZ(dst white)."""
    a = mulv(BRADFORD, xyz(src))
    b = mulv(BRADFORD, xyz(dst))
    d = tuple(tuple((b[i] / a[i]) if i == j else 0.0 for j in range(3)) for i in range(3))
    return mul(inv(BRADFORD), mul(d, BRADFORD))


def rgb_to_rgb(sp, sw, dp, dw):
    m = npm(sp, sw)
    if sw != dw:
        m = mul(cat(sw, dw), m)
    return mul(inv(npm(dp, dw)), m)


def matrices():
    xyz_d65_to_709 = inv(npm(REC709, D65))
    return [
        ("ACEScg (AP1) to ACES2065-1 (AP0), same white", rgb_to_rgb(AP1, ACES_WHITE, AP0, ACES_WHITE)),
        ("Linear Rec.709 to ACES2065-1, Bradford D65 -> ACES white", rgb_to_rgb(REC709, D65, AP0, ACES_WHITE)),
        ("Linear Rec.2020 to ACES2065-1, Bradford D65 -> ACES white", rgb_to_rgb(REC2020, D65, AP0, ACES_WHITE)),
        ("Linear P3-D65 to ACES2065-1, Bradford D65 -> ACES white", rgb_to_rgb(P3, D65, AP0, ACES_WHITE)),
        ("ACES2065-1 to CIE XYZ D65, Bradford ACES white -> D65", mul(cat(ACES_WHITE, D65), npm(AP0, ACES_WHITE))),
        ("CIE XYZ D65 to Rec.709 display RGB, no adaptation", xyz_d65_to_709),
    ]


def yaml(m):
    v = [m[0][0], m[0][1], m[0][2], 0, m[1][0], m[1][1], m[1][2], 0,
         m[2][0], m[2][1], m[2][2], 0, 0, 0, 0, 1]
    return "matrix: [" + ", ".join("%.12g" % x if x not in (0, 1) else "%d" % x for x in v) + "]"


def main(argv):
    if len(argv) == 3 and argv[1] == "--check":
        text = open(argv[2], encoding="utf-8").read()
        bad = [name for name, m in matrices() if yaml(m) not in text]
        for name in bad:
            print("missing or stale: %s\n  %s" % (name, yaml(dict(matrices())[name])))
        print("%d of %d matrices found in %s" % (len(matrices()) - len(bad), len(matrices()), argv[2]))
        return 1 if bad else 0
    if len(argv) != 1:
        print("usage: make_matrices.py [--check CONFIG]", file=sys.stderr)
        return 2
    for name, m in matrices():
        print("# " + name)
        print(yaml(m))
    print("# for reference: ACEScg to Linear Rec.709 (Bradford), row-major")
    for row in rgb_to_rgb(AP1, ACES_WHITE, REC709, D65):
        print("#   %.8f %.8f %.8f" % row)
    print("# Linear Rec.709 to ACEScg (Bradford), row-major")
    for row in rgb_to_rgb(REC709, D65, AP1, ACES_WHITE):
        print("#   %.8f %.8f %.8f" % row)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
