#!/usr/bin/python3
"""Edges of flat renders against the deep answer (issue 45).

edges_deep.py EXRFOG WORKDIR [--shared DIR] [--fog SPEC] [--z closest|filtered]
              [--crop X0,Y0,X1,Y1] [--out-png PREFIX]

Weta's three deep elements (../shared/real-exr/openexr-images/v2/
LowResLeftView: Balls, Leaves, Trunks; point samples, up to two a pixel)
are deep-merged by oiiotool. Their flat render is what a renderer writes
for the same scene: the colour is OpenImageIO's flatten of the merged
samples, and the depth one number per pixel, either the nearest sample's
Z (closest: Arnold's default Z filter, and what a one-sample Z shows) or
the alpha-weighted mean of the samples' Z (filtered). The reference is
exrfog's own exact deep path on the merged samples (--deep flatten: each
sample fogged at its own depth), which the deep tests hold to an
independent reference; the flat runs are exrfog without and with
--edges unmix, the same fog and camera.

Edge pixels are those whose 3x3 window's Z (closest) spans a ratio over
1.05 (the issue's definition). Printed per run: the edge pixels' RMS error
and mean error (max over RGB of |out - reference|), how many are off by
more than 2 % and 10 % of the reference, the interior's largest change
between the two flat runs, and the error output's coverage of the edge
fix's actual error.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio

ap = argparse.ArgumentParser()
ap.add_argument("exrfog")
ap.add_argument("work")
ap.add_argument("--shared", default=os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                 "..", "..", "shared"))
ap.add_argument("--fog", default="exp:density=0.02")
ap.add_argument("--z", default="closest", choices=("closest", "filtered"))
ap.add_argument("--crop", default=None)
ap.add_argument("--out-png", default=None)
ap.add_argument("--quiet", action="store_true")
args = ap.parse_args()

src = os.path.join(args.shared, "real-exr", "openexr-images", "v2", "LowResLeftView")
if not os.path.isdir(src):
    print("no %s: skipped" % src)
    sys.exit(77)
os.makedirs(args.work, exist_ok=True)
W = lambda n: os.path.join(args.work, n)
CAM = ["--fov", "50", "--world-to-camera", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1"]


def sh(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("failed: %s\n%s" % (" ".join(cmd), r.stderr))
    return r


merged = W("merged.exr")
if not os.path.exists(merged):
    sh(["oiiotool", os.path.join(src, "Balls.exr"), os.path.join(src, "Leaves.exr"), "--deepmerge",
        os.path.join(src, "Trunks.exr"), "--deepmerge", "--fullpixels", "-o", merged])
flatc = W("flat_colour.exr")
if not os.path.exists(flatc):
    sh(["oiiotool", merged, "--flatten", "-o", flatc])

# the flat render's depth from the samples
buf = oiio.ImageBuf(merged)
spec = buf.spec()
dd = buf.deepdata()
ch = list(spec.channelnames)
iA, iZ = ch.index("A"), ch.index("Z")
Wd, Hd = spec.width, spec.height
Z = np.full(Wd * Hd, 1e30, dtype=np.float32)
for p in range(dd.pixels):
    n = dd.samples(p)
    if n == 0:
        continue
    zs = [dd.deep_value(p, iZ, s) for s in range(n)]
    if args.z == "closest":
        Z[p] = min(zs)
    else:
        a = [max(dd.deep_value(p, iA, s), 0.0) for s in range(n)]
        # the filtered Z a renderer averages over the pixel's samples: the
        # samples' depths weighted by what each contributes to the colour
        T, wsum, zsum = 1.0, 0.0, 0.0
        for s in sorted(range(n), key=lambda s: zs[s]):
            wsum += T * a[s]
            zsum += T * a[s] * zs[s]
            T *= 1 - a[s]
        Z[p] = zsum / wsum if wsum > 0 else min(zs)
Z = Z.reshape(Hd, Wd)
cb = oiio.ImageBuf(flatc)
col = cb.get_pixels(oiio.FLOAT)[:, :, :4]
flat = W("flat_%s.exr" % args.z)
out_spec = oiio.ImageSpec(Wd, Hd, 5, oiio.HALF)
out_spec.x, out_spec.y = spec.x, spec.y
out_spec.full_x, out_spec.full_y = spec.full_x, spec.full_y
out_spec.full_width, out_spec.full_height = spec.full_width, spec.full_height
out_spec.channelnames = ("R", "G", "B", "A", "Z")
out_spec.channelformats = (oiio.HALF,) * 4 + (oiio.FLOAT,)
out_spec.attribute("compression", "zip")
ob = oiio.ImageBuf(out_spec)
ob.set_pixels(oiio.ROI(), np.concatenate([col, Z[:, :, None]], axis=2).astype(np.float32))
ob.write(flat)

fog = ["--fog", args.fog]
ref, naive, fixed = W("ref.exr"), W("naive_%s.exr" % args.z), W("edges_%s.exr" % args.z)
sh([args.exrfog, merged, "-o", ref, "--deep", "flatten", "-d", "float"] + fog + CAM)
sh([args.exrfog, flat, "-o", naive, "-d", "float"] + fog + CAM)
sh([args.exrfog, flat, "-o", fixed, "-d", "float", "--edges", "unmix", "--aov", "error"] + fog + CAM)


def rgb(path, extra=None):
    b = oiio.ImageBuf(path)
    names = list(b.spec().channelnames)
    px = b.get_pixels(oiio.FLOAT)
    out = px[:, :, [names.index(c) for c in "RGB"]]
    if extra:
        return out, px[:, :, [names.index(c) for c in extra]]
    return out


R = rgb(ref)
N = rgb(naive)
F, E = rgb(fixed, ["fog_error.R", "fog_error.G", "fog_error.B"])

# edge pixels: the 3x3 window of the closest Z spans a ratio over 1.05
Zc = Z.copy()
if args.z != "closest":
    Zc = np.full(Wd * Hd, 1e30, dtype=np.float32)
    for p in range(dd.pixels):
        n = dd.samples(p)
        if n:
            Zc[p] = min(dd.deep_value(p, iZ, s) for s in range(n))
    Zc = Zc.reshape(Hd, Wd)
pad = np.pad(Zc, 1, mode="edge")
win = np.stack([pad[1 + dy:1 + dy + Hd, 1 + dx:1 + dx + Wd] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
zmax, zmin = win.max(axis=0), win.min(axis=0)
edge = zmax > 1.05 * zmin
if args.crop:
    x0, y0, x1, y1 = map(int, args.crop.split(","))
    m = np.zeros_like(edge)
    m[y0:y1, x0:x1] = True
    edge &= m


def report(name, out):
    err = np.abs(out - R).max(axis=2)
    rel = err / np.maximum(np.abs(R).max(axis=2), 1e-3)
    e = err[edge]
    return {"name": name, "rms": float(np.sqrt(np.mean(e ** 2))), "mean": float(e.mean()),
            "over2": int((rel[edge] > 0.02).sum()), "over10": int((rel[edge] > 0.10).sum()),
            "max": float(e.max())}


rn, rf = report("naive", N), report("edges", F)
interior = float(np.abs(F - N).max(axis=2)[~edge & (zmax <= 1.05 * zmin)].max())
actual = np.abs(F - R)
cover = float(np.mean(np.all(E[edge] + 1e-6 >= actual[edge], axis=1)))
res = {"z": args.z, "fog": args.fog, "edge_px": int(edge.sum()), "naive": rn, "edges": rf,
       "interior_change": interior, "cover": cover}
print(json.dumps(res))
if args.out_png:
    for name, img in (("naive", N), ("edges", F)):
        err = np.abs(img - R).max(axis=2)
        vis = np.clip(err / 0.05, 0, 1)
        o = oiio.ImageBuf(oiio.ImageSpec(Wd, Hd, 3, oiio.UINT8))
        o.set_pixels(oiio.ROI(), np.stack([vis, vis, vis], axis=2).astype(np.float32))
        if args.crop:
            x0, y0, x1, y1 = map(int, args.crop.split(","))
            o = oiio.ImageBufAlgo.cut(o, oiio.ROI(x0, x1, y0, y1))
        o.write("%s_%s_%s.png" % (args.out_png, name, args.z))
