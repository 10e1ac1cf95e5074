#!/usr/bin/python3
"""A chain of overlapping deep samples past what one read may decode (issue
42 item 12).

deep_chain_check.py EXRFOG MAKE_SAMPLE MAKE_DEEP TMP

make_deep writes 150x16 pixels (deep scanline ZIPS, one row a chunk) of
10,000 samples each, every sample 0.002 deep and starting 0.001 after the
one before: 24 million samples whose 16 rows decode into 144 million
values, past the 2^27 that one read of exrfog's may hold (before this
test, refused as "probably corrupt"). They are now read a chunk at a
time. --deep flatten with exp fog is checked against a closed form
computed here, and the run's peak memory is bounded; a single row past
the hard limit is refused at once with the figure and nothing written.

The reference: the tidy rule splits the chain at every front and back; on
each interval the samples that cover it are homogeneous media of
extinction -ln(1 - a) / length and unpremultiplied colour c / a; with the
fog (density s, colour F) they form one medium, composited front to back,
after the fog from the camera to the first front and with the fog alone
to infinity behind the last back. Z and ZBack are the file's floats.
"""
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np

exrfog, make_sample, make_deep, tmp = sys.argv[1:5]
try:
    import OpenImageIO as oiio
except ImportError:
    print("OpenImageIO's Python module is missing: skipped")
    sys.exit(77)

failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


W, H, N, FOV, DENS = 150, 16, 10000, 60.0, 0.02
FOG = (0.7, 0.75, 0.8)
flat = os.path.join(tmp, "chain_flat.exr")
deep = os.path.join(tmp, "chain_deep.exr")
out = os.path.join(tmp, "chain_out.exr")
for f in (out,):
    if os.path.exists(f):
        os.remove(f)
subprocess.run([make_sample, flat, "--size", "%dx%d" % (W, H)], check=True,
               stdout=subprocess.DEVNULL)
subprocess.run([make_deep, flat, deep, str(N), "chain"], check=True)

# The camera is given on the command line (identity pose, looking down -Z,
# horizontal field of view FOV), so the rays are known here.
cam = ["--world-to-camera", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1", "--fov", str(FOV)]
t0 = time.time()
r = subprocess.run([exrfog, deep, "-o", out, "--deep", "flatten", "-d", "float",
                    "--fog", "exp:density=%g" % DENS] + cam, capture_output=True, text=True)
took = time.time() - t0
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
check(r.returncode == 0, "24 million chained samples in 16 rows: --deep flatten runs (%s)"
      % r.stderr.strip()[:300])
print("  %.1f s, peak memory %.0f MB (the samples alone: %.0f MB as doubles)"
      % (took, peak, W * H * N * 6 * 8 / 2**20))
check(peak < 700, "memory stays bounded (%.0f MB; the rows whole would need 1.1 GB)" % peak)

# the file's values: make_deep's doubles rounded to float (Z) and half (colour)
i = np.arange(N, dtype=np.float64)
z = (4 + 0.001 * i).astype(np.float32).astype(np.float64)
zb = ((4 + 0.001 * i).astype(np.float64) + 0.002).astype(np.float32).astype(np.float64)
a = float(np.float16(0.0004))
c = a                                           # R = G = B = A: colour / alpha = 1
bounds = np.unique(np.concatenate([z, zb]))
# Each sample's extinction per unit Z is -ln(1 - a) over its own length (the
# split gives a piece the alpha of its share of that length); an interval's
# media: the sum over the samples that cover it, the fronts at or before
# its start less the backs at or before it (prefix sums over both sorted
# lists, in the order make_deep wrote them: both increase).
kap = -math.log1p(-a) / (zb - z)
assert np.all(np.diff(z) > 0) and np.all(np.diff(zb) > 0)
cz = np.concatenate([[0.0], np.cumsum(kap)])
czb = np.concatenate([[0.0], np.cumsum(kap)])
starts = bounds[:-1]
kap_sum = cz[np.searchsorted(z, starts, side="right")] - czb[np.searchsorted(zb, starts, side="right")]
length_z = np.diff(bounds)


def reference(x, y):
    sx = (2 * (x + 0.5) / W - 1) * math.tan(math.radians(FOV) / 2)
    sy = -(2 * (y + 0.5) / H - 1) * math.tan(math.radians(FOV) / 2) * H / W
    k = math.sqrt(sx * sx + sy * sy + 1)        # distance per unit of planar Z
    L = np.zeros(3)
    T = math.exp(-DENS * k * bounds[0])
    L += (1 - T) * np.array(FOG)
    tf = DENS * k * length_z                    # fog's depth per interval
    tv = kap_sum * length_z                     # the media's (planar Z: their own extinction per Z)
    tt = tf + tv
    em = -np.expm1(-tt)
    # front to back: transmittance before each interval
    Tb = T * np.exp(-np.concatenate([[0.0], np.cumsum(tt)[:-1]]))
    for ch in range(3):
        L[ch] += np.sum(Tb * em * (tf * FOG[ch] + tv * (c / a)) / tt)
    T = T * math.exp(-np.sum(tt))
    L += T * np.array(FOG)                      # the fog alone to infinity
    return list(L)


if r.returncode == 0:
    inp = oiio.ImageInput.open(out)
    chans = inp.spec().channelnames
    px = inp.read_image(oiio.FLOAT)
    inp.close()
    worst = 0.0
    for (x, y) in ((0, 0), (75, 8), (149, 15), (10, 3), (140, 12)):
        ref = reference(x, y)
        got = [float(px[y][x][chans.index(n)]) for n in "RGB"]
        for ch in range(3):
            worst = max(worst, abs(got[ch] - ref[ch]) / ref[ch])
        print("  pixel (%d, %d): %s against %s" % (x, y, ["%.7f" % v for v in got],
                                                 ["%.7f" % v for v in ref[:3]]))
    check(worst <= 1e-5, "the chain's flatten against the closed form (worst %.2e)" % worst)

# one row of 256 pixels x 100,000 samples: one chunk past the hard limit
flat1 = os.path.join(tmp, "chain_flat1.exr")
deep1 = os.path.join(tmp, "chain_row.exr")
out1 = os.path.join(tmp, "chain_row_out.exr")
if os.path.exists(out1):
    os.remove(out1)
subprocess.run([make_sample, flat1, "--size", "256x1"], check=True, stdout=subprocess.DEVNULL)
subprocess.run([make_deep, flat1, deep1, "100000", "chain"], check=True)
t0 = time.time()
r = subprocess.run([exrfog, deep1, "-o", out1, "--deep", "fog", "--fog", "exp:density=0.02"] +
                   cam, capture_output=True, text=True)
check(r.returncode == 1 and "25600000 deep samples" in r.stderr and "GiB" in r.stderr and
      not os.path.exists(out1) and time.time() - t0 < 5,
      "one row past the limit: refused at once with the figure, nothing written (%s)"
      % r.stderr.strip())

if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
print("all passed")
