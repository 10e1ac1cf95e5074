#!/usr/bin/env python3
"""An independent implementation of exrfog's noise contract (issue 7), in
plain Python, to check src/core/noise.c bit for bit.

noise3 is a transcription of Ken Perlin's Java reference of Improved Noise
(cs.nyu.edu/~perlin/noise/, SIGGRAPH 2002, with the 2003 gradient fix):
his permutation, fade 6t^5 - 15t^4 + 10t^3, grad with
u = h<8 ? x : y; v = h<4 ? y : (h==12||h==14 ? x : z), and lerp a + t(b - a)
nested as in his code. Python floats are IEEE binary64 and CPython never
fuses a multiply and an add, so every value here is what the contract's
operations give, to the last bit. The cell index floor(x) & 255 is taken on
Python's exact integer floor, which is what the contract asks for every
finite x (Java's int cast would saturate past 2^31).

fbm and q follow the issue's text:
  fbm(q) = sum_{i<N} g^i noise3(l^i q + i O) / sum_{i<N} g^i,
  O = (31.416, 27.183, 14.142), l^i and g^i by repeated multiplication from
  1, the sum of g^i n_i accumulated in order i = 0.. and divided by the sum
  of g^i (accumulated the same way);
  q = ((p - offset) - velocity * time) / scale + seed * S componentwise,
  S = (12.9898, 78.233, 37.719).

The two fog densities of the issue (noise, noise-separable) are evaluated
here in exact rational arithmetic (the exponential envelope in 50-digit
decimal), from the doubles a SPEC's numbers parse to: a yardstick for the
model's density at about 1e-15, not a bit pattern. Only l^i, g^i and the sum
of g^i are the contract's doubles (formed by repeated multiplication); q,
l^i q + i O, the noise polynomial and the sums are exact.

Usage:
  perlin_ref.py golden            check the contract's golden values
  perlin_ref.py gen SEED NN NF    NN noise3 and NF fbm records, hex floats:
                                  "n x y z value" and
                                  "f octaves lacunarity gain qx qy qz value"
  perlin_ref.py densities         the spot densities pasted into test_noise.c
"""

import math
import random
import sys
from decimal import Decimal, getcontext
from fractions import Fraction

# Perlin's permutation of 0..255, as printed in his reference.
PERM = [
    151, 160, 137, 91, 90, 15,
    131, 13, 201, 95, 96, 53, 194, 233, 7, 225, 140, 36, 103, 30, 69, 142, 8, 99, 37, 240, 21, 10, 23,
    190, 6, 148, 247, 120, 234, 75, 0, 26, 197, 62, 94, 252, 219, 203, 117, 35, 11, 32, 57, 177, 33,
    88, 237, 149, 56, 87, 174, 20, 125, 136, 171, 168, 68, 175, 74, 165, 71, 134, 139, 48, 27, 166,
    77, 146, 158, 231, 83, 111, 229, 122, 60, 211, 133, 230, 220, 105, 92, 41, 55, 46, 245, 40, 244,
    102, 143, 54, 65, 25, 63, 161, 1, 216, 80, 73, 209, 76, 132, 187, 208, 89, 18, 169, 200, 196,
    135, 130, 116, 188, 159, 86, 164, 100, 109, 198, 173, 186, 3, 64, 52, 217, 226, 250, 124, 123,
    5, 202, 38, 147, 118, 126, 255, 82, 85, 212, 207, 206, 59, 227, 47, 16, 58, 17, 182, 189, 28, 42,
    223, 183, 170, 213, 119, 248, 152, 2, 44, 154, 163, 70, 221, 153, 101, 155, 167, 43, 172, 9,
    129, 22, 39, 253, 19, 98, 108, 110, 79, 113, 224, 232, 178, 185, 112, 104, 218, 246, 97, 228,
    251, 34, 242, 193, 238, 210, 144, 12, 191, 179, 162, 241, 81, 51, 145, 235, 249, 14, 239, 107,
    49, 192, 214, 31, 181, 199, 106, 157, 184, 84, 204, 176, 115, 121, 50, 45, 127, 4, 150, 254,
    138, 236, 205, 93, 222, 114, 67, 29, 24, 72, 243, 141, 128, 195, 78, 66, 215, 61, 156, 180,
]
assert sorted(PERM) == list(range(256))
P = PERM + PERM

OCTAVE_OFFSET = (31.416, 27.183, 14.142)
SEED_DIR = (12.9898, 78.233, 37.719)


def fade(t):
    return t * t * t * (t * (t * 6 - 15) + 10)


def lerp(t, a, b):
    return a + t * (b - a)


def grad(hsh, x, y, z):
    h = hsh & 15
    u = x if h < 8 else y
    v = y if h < 4 else (x if h == 12 or h == 14 else z)
    return (u if (h & 1) == 0 else -u) + (v if (h & 2) == 0 else -v)


def noise3(x, y, z):
    """Perlin's noise(x, y, z). With floats, binary64 as his Java; with
    Fractions, the same polynomial exactly."""
    fx, fy, fz = math.floor(x), math.floor(y), math.floor(z)
    X, Y, Z = fx & 255, fy & 255, fz & 255
    x -= fx
    y -= fy
    z -= fz
    u, v, w = fade(x), fade(y), fade(z)
    A = P[X] + Y
    AA = P[A] + Z
    AB = P[A + 1] + Z
    B = P[X + 1] + Y
    BA = P[B] + Z
    BB = P[B + 1] + Z
    return lerp(w, lerp(v, lerp(u, grad(P[AA], x, y, z),
                                   grad(P[BA], x - 1, y, z)),
                           lerp(u, grad(P[AB], x, y - 1, z),
                                   grad(P[BB], x - 1, y - 1, z))),
                   lerp(v, lerp(u, grad(P[AA + 1], x, y, z - 1),
                                   grad(P[BA + 1], x - 1, y, z - 1)),
                           lerp(u, grad(P[AB + 1], x, y - 1, z - 1),
                                   grad(P[BB + 1], x - 1, y - 1, z - 1))))


def fbm(q, octaves, lacunarity, gain, offset=OCTAVE_OFFSET):
    """The fractal sum in the contract's order. l^i, g^i and their sum are
    always the doubles the contract forms by repeated multiplication (and
    summation) from 1; with Fraction coordinates the rest is exact."""
    exact = isinstance(q[0], Fraction)
    freq, amp, norm = 1.0, 1.0, 0.0
    total = Fraction(0) if exact else 0.0
    for i in range(octaves):
        fr = Fraction(freq) if exact else freq
        u = [fr * q[k] + i * offset[k] for k in range(3)]
        total += (Fraction(amp) if exact else amp) * noise3(u[0], u[1], u[2])
        norm += amp
        freq *= lacunarity
        amp *= gain
    return total / (Fraction(norm) if exact else norm)


def noise_q(p, offset, velocity, time, scale, seed, seed_dir=SEED_DIR):
    return [((p[k] - offset[k]) - velocity[k] * time) / scale + seed * seed_dir[k]
            for k in range(3)]


# ---- golden values ---------------------------------------------------------

GOLDEN = [((3.14, 42.0, 7.0), 0.13691995878400012),
          ((-4.2, 10.0, 6.0), 0.14208000000000043),
          ((0.5, 0.5, 0.5), -0.25),
          ((0.1, 0.1, 0.1), 0.1861607143544832)]


def golden():
    ok = True
    for (x, y, z), want in GOLDEN:
        got = noise3(x, y, z)
        print("noise3(%r, %r, %r) = %r (want %r)" % (x, y, z, got, want))
        ok &= got == want
    for p in [(0.0, 0.0, 0.0), (1.0, -2.0, 3.0), (255.0, 256.0, -257.0), (1e15, -1e15, 2.0 ** 60),
              (-2.0 ** 63, 1e300, -1e300)]:
        ok &= noise3(*p) == 0
    return ok


# ---- random records for the C checker --------------------------------------

def random_coord(rng):
    """Mixed magnitudes and signs, near-integers, up to 1e6."""
    kind = rng.randrange(9)
    if kind == 0:
        return rng.uniform(-1.0, 1.0)
    if kind == 1:
        return rng.uniform(-300.0, 300.0)
    if kind == 2:
        return rng.uniform(-1e6, 1e6)
    if kind == 3:
        return math.copysign(10.0 ** rng.uniform(-12, 6), rng.random() - 0.5)
    if kind == 4:  # near an integer: a few ulps, or a tiny fraction, either side
        k = float(rng.randint(-100000, 100000))
        d = rng.choice([0.0, 1e-15, -1e-15, 1e-9, -1e-9, 2.0 ** -30, -(2.0 ** -30)])
        x = k + d
        for _ in range(rng.randrange(3)):
            x = math.nextafter(x, math.inf if rng.random() < 0.5 else -math.inf)
        return x
    if kind == 5:  # near a multiple of the period 256
        return 256.0 * rng.randint(-4000, 4000) + rng.uniform(-1.0, 1.0)
    if kind == 6:  # halves, quarters: fractions that are exact
        return rng.randint(-4000, 4000) / 4.0
    if kind == 7:
        return float(rng.randint(-1000000, 1000000))
    return rng.uniform(-1e6, 1e6) + rng.choice([0.0, 0.5, 1e-6])


def gen(seed, nn, nf):
    rng = random.Random(seed)
    out = sys.stdout
    for _ in range(nn):
        x, y, z = random_coord(rng), random_coord(rng), random_coord(rng)
        out.write("n %s %s %s %s\n" % (x.hex(), y.hex(), z.hex(), noise3(x, y, z).hex()))
    lacs = [2.0, 2.0, 1.5, 2.5, 3.0, 1.9, 1.01, 4.0]
    gains = [0.5, 0.5, 0.3, 0.7, 1.0, 1.2, 0.05]
    for _ in range(nf):
        octaves = rng.choice([1, 2, 3, 4, 4, 5, 6, 8, 12, 16])
        lac = rng.choice(lacs) if rng.random() < 0.7 else rng.uniform(1.001, 4.0)
        gain = rng.choice(gains) if rng.random() < 0.7 else rng.uniform(0.01, 1.5)
        if lac ** (octaves - 1) * 1e6 > 1e300:
            octaves = 4
        q = [random_coord(rng) for _ in range(3)]
        v = fbm(q, octaves, lac, gain)
        out.write("f %d %s %s %s %s %s %s\n" % (octaves, lac.hex(), gain.hex(), q[0].hex(),
                                                q[1].hex(), q[2].hex(), v.hex()))


# ---- the fog densities, exactly --------------------------------------------

getcontext().prec = 50


def F(x):
    """The exact value of a double (a SPEC number after strtod)."""
    return Fraction(float(x))


def envelope(falloff, up, base, p):
    """e^(-k (up.p - base)) to 50 digits."""
    if falloff == 0:
        return Decimal(1)
    h = sum(F(up[k]) * F(p[k]) for k in range(3)) - F(base)
    e = -F(falloff) * h
    return (Decimal(e.numerator) / Decimal(e.denominator)).exp()


def density(model, sp, p, time=0.0):
    """sigma at world point p (units_per_meter = 1) for a dict of SPEC values,
    and the smallest |1 + c fbm| of its factors (inf outside the box)."""
    if "min" in sp:
        for k in range(3):
            if not (F(sp["min"][k]) <= F(p[k]) <= F(sp["max"][k])):
                return [Decimal(0)] * 3, math.inf
    octaves = sp.get("octaves", 4)
    lac = float(sp.get("lacunarity", 2.0))
    gain = float(sp.get("gain", 0.5))
    c = F(sp.get("contrast", 0.9))
    offs = [F(v) for v in OCTAVE_OFFSET]
    q = noise_q([F(v) for v in p], [F(v) for v in sp.get("offset", (0, 0, 0))],
                [F(v) for v in sp.get("velocity", (0, 0, 0))], F(time), F(sp["scale"]),
                F(sp.get("seed", 0.0)), [F(v) for v in SEED_DIR])
    if model == "noise":
        factors = [1 + c * fbm(q, octaves, lac, gain, offs)]
    else:
        factors = []
        fixed = (F(0.37), F(0.71))
        for axis in sp.get("axes", "xz"):
            a = "xyz".index(axis)
            e = list(fixed)
            e.insert(a, q[a])
            factors.append(1 + c * fbm(e, octaves, lac, gain, offs))
    shape = Fraction(1)
    for f in factors:
        shape *= max(Fraction(0), f)
    env = envelope(sp.get("falloff", 0.0), sp.get("up", (0, 1, 0)), sp.get("base", 0.0), p)
    rho = sp["density"]
    shape_d = Decimal(shape.numerator) / Decimal(shape.denominator)
    sigma = [Decimal(F(r).numerator) / Decimal(F(r).denominator) * env * shape_d for r in rho]
    return sigma, float(min(abs(f) for f in factors))


# Each case: SPEC as test_noise.c parses it, the same values as a dict, time.
CASES = [
    ("noise:density=0.02:scale=10", "noise", {"density": (0.02, 0.02, 0.02), "scale": 10.0}, 0.0),
    ("noise:density=0.01,0.02,0.03:scale=3.5:octaves=6:lacunarity=2.3:gain=0.6:contrast=2.5"
     ":offset=100,-20,5:velocity=1,2,-3:seed=7:falloff=0.05:base=-2:up=0,0,1"
     ":min=-50,-60,-70:max=80,90,100", "noise",
     {"density": (0.01, 0.02, 0.03), "scale": 3.5, "octaves": 6, "lacunarity": 2.3, "gain": 0.6,
      "contrast": 2.5, "offset": (100, -20, 5), "velocity": (1, 2, -3), "seed": 7.0,
      "falloff": 0.05, "base": -2.0, "up": (0, 0, 1), "min": (-50, -60, -70),
      "max": (80, 90, 100)}, 2.5),
    ("noise-separable:density=0.05:scale=20:contrast=0.8", "noise-separable",
     {"density": (0.05, 0.05, 0.05), "scale": 20.0, "contrast": 0.8}, 0.0),
    ("noise-separable:density=0.04,0.05,0.06:scale=7:axes=xyz:octaves=3:lacunarity=2.7"
     ":gain=0.45:contrast=1.6:offset=-3,4,5.5:velocity=0.5,0,-1:seed=3:falloff=0.1:base=1",
     "noise-separable",
     {"density": (0.04, 0.05, 0.06), "scale": 7.0, "axes": "xyz", "octaves": 3,
      "lacunarity": 2.7, "gain": 0.45, "contrast": 1.6, "offset": (-3, 4, 5.5),
      "velocity": (0.5, 0, -1), "seed": 3.0, "falloff": 0.1, "base": 1.0}, -1.25),
    ("noise-separable:density=0.03:scale=5:axes=y", "noise-separable",
     {"density": (0.03, 0.03, 0.03), "scale": 5.0, "axes": "y"}, 0.0),
]

# Inside and outside the box of case 2 and on its corners; (35.78, 5.43, -53.5)
# and (-66.8, 90.68, 78.9) are where the clamp binds in cases 2 and 4.
POINTS = [(0.0, 0.0, 0.0), (12.3, -4.56, 7.89), (-33.25, 18.5, 61.125), (79.9, 89.5, -69.0),
          (80.0, 90.0, 100.0), (-50.0, -60.0, -70.0), (80.5, 0.0, 0.0), (3.75, -1.5, 2.25),
          (-41.0, 5.0, 33.3), (35.78, 5.43, -53.5), (-66.8, 90.68, 78.9)]


def c_string(text, indent):
    """A C string literal, split into pieces of at most 80 characters."""
    parts = [text[i:i + 80] for i in range(0, len(text), 80)]
    return ("\n" + " " * indent).join('"%s"' % part for part in parts)


def densities():
    """The C tables of test_noise.c: POINTS, then one entry per case with its
    SPEC, time and sigma per point and channel."""
    print("static const double POINTS[%d][3] = {" % len(POINTS))
    for p in POINTS:
        print("    { %r, %r, %r }," % p)
    print("};")
    print()
    print("static const density_case CASES[%d] = {" % len(CASES))
    for spec, model, sp, time in CASES:
        print("    { %s,\n      %r,\n      {" % (c_string(spec, 6), time))
        for p in POINTS:
            s, margin = density(model, sp, p, time)
            # margin: the smallest |1 + c fbm| of the factors; far from 0,
            # so the clamp's side is not a matter of rounding.
            assert margin > 1e-3, (spec, p, margin)
            print("          { %s }," % ", ".join("%.20eL" % v for v in s))
        print("      } },")
    print("};")


def main(argv):
    if len(argv) >= 2 and argv[1] == "golden":
        return 0 if golden() else 1
    if len(argv) == 5 and argv[1] == "gen":
        gen(int(argv[2]), int(argv[3]), int(argv[4]))
        return 0
    if len(argv) >= 2 and argv[1] == "densities":
        densities()
        return 0
    sys.stderr.write(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
