#!/usr/bin/python3
"""Scores exrfog's fog at the edges of a flat render against the render
with the fog inside the scene (issue 45; bench/edges_blender.py makes them).

edges_eval.py EXRFOG DIR [--png PREFIX] [--json]

DIR holds nofog.exr (Combined and Depth), fog.exr (the truth) and
flags.json. exrfog fogs nofog.exr twice with the same constant fog
(exp:density, the truth's colour), without and with --edges unmix, the
camera by flags. Edge pixels: the depth of their 3x3 window spans a ratio
over 1.05 (the issue's definition; sky counts as infinitely far). Per run:
the edge pixels' RMS error (max over RGB of |out - truth|), mean error,
the count off by more than 2 % and 10 % of the truth, the interior's
largest change between the two runs (0: untouched), and the share of edge
pixels whose error output (--aov error) covers the fixed run's actual
error beyond the truth's own sampling noise (estimated from the two
interior runs' residual, which has none from edges)."""
import json
import os
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio

exrfog, d = sys.argv[1], sys.argv[2]
png = sys.argv[sys.argv.index("--png") + 1] if "--png" in sys.argv else None
flags = json.load(open(os.path.join(d, "flags.json")))
layer = flags["layer"]
common = ["--layer", layer + ".Combined", "--depth-channel", layer + ".Depth.Z",
          "--up-axis", "z", "--camera-convention", "blender", "--camera-to-world",
          ",".join(repr(v) for v in flags["camera_to_world"]), "--fov", repr(flags["fov"]),
          "--near", repr(flags["near"]), "--far", repr(flags["far"]),
          "--fog", "exp:density=%r" % flags["density"],
          "--fog-color", ",".join(repr(c) for c in flags["fog_color"]), "-d", "float"]
src = os.path.join(d, "nofog.exr")
naive, fixed = os.path.join(d, "out_naive.exr"), os.path.join(d, "out_edges.exr")
for out, extra in ((naive, []), (fixed, ["--edges", "unmix", "--aov", "error"])):
    r = subprocess.run([exrfog, src, "-o", out] + common + extra, capture_output=True, text=True)
    if r.returncode:
        sys.exit("exrfog failed: %s" % r.stderr)


def read(path, names):
    b = oiio.ImageBuf(path)
    ch = list(b.spec().channelnames)
    px = b.get_pixels(oiio.FLOAT)
    return px[:, :, [ch.index(n) for n in names]].astype(np.float64)


rgb = [layer + ".Combined." + c for c in "RGB"]
T = read(os.path.join(d, "fog.exr"), rgb)
N = read(naive, rgb)
F = read(fixed, rgb)
E = read(fixed, [layer + ".FogError." + c for c in "RGB"])
Z = read(src, [layer + ".Depth.Z"])[:, :, 0]
Z = np.where(Z > 1e9, np.inf, Z)
H, W = Z.shape
pad = np.pad(Z, 1, mode="edge")
win = np.stack([pad[1 + dy:1 + dy + H, 1 + dx:1 + dx + W] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
with np.errstate(invalid="ignore"):
    edge = win.max(axis=0) > 1.05 * win.min(axis=0)
inner = ~edge
# the truth's own noise: the naive run is exact away from edges
noise = np.abs(N - T).max(axis=2)[inner]
noise99 = float(np.percentile(noise, 99)) if noise.size else 0.0


def score(out):
    err = np.abs(out - T).max(axis=2)
    rel = err / np.maximum(np.abs(T).max(axis=2), 1e-3)
    e = err[edge]
    return {"rms": float(np.sqrt(np.mean(e ** 2))), "mean": float(e.mean()),
            "over2": int((rel[edge] > 0.02).sum()), "over10": int((rel[edge] > 0.10).sum()),
            "max": float(e.max())}


sn, sf = score(N), score(F)
actual = np.abs(F - T)[edge]
cover = float(np.mean(np.all(E[edge] + noise99 >= actual, axis=1)))
res = {"variant": flags.get("variant"), "samples": flags.get("samples"), "size": [W, H],
       "edge_px": int(edge.sum()), "naive": sn, "edges": sf,
       "rms_ratio": sf["rms"] / sn["rms"], "over2_ratio": sf["over2"] / max(sn["over2"], 1),
       "interior_change": float(np.abs(F - N).max(axis=2)[inner].max()),
       "interior_noise99": noise99, "cover": cover}
print(json.dumps(res))
if png:
    for name, img in (("naive", N), ("edges", F)):
        err = np.abs(img - T).max(axis=2)
        vis = np.clip(err / 0.1, 0, 1)
        o = oiio.ImageBuf(oiio.ImageSpec(W, H, 3, oiio.UINT8))
        o.set_pixels(oiio.ROI(), np.stack([vis] * 3, axis=2).astype(np.float32))
        o.write("%s_%s.png" % (png, name))
