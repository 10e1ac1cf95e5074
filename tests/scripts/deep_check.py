#!/usr/bin/python3
"""Deep fog against an independent composite (issue 24).

The reference reads the input's samples with OpenImageIO and solves the
transfer equation along each pixel's ray from first principles: a volume
sample is a medium of extinction -ln(1 - A)/(ZBack - Z) and source c/A, a
point sample an "over" at its depth, the fog a medium of the model's
density (closed forms) and colour F. Between consecutive depths every
medium is sliced finely (16 slices) and each slice integrated exactly as a
homogeneous mix. The camera comes from the header (worldToCamera and
CameraFov, planar Z) through OpenImageIO, not through exrfog.

Checked, per scene (exp and height fog):
  exrfog --deep flatten                       vs the reference
  oiiotool --flatten of exrfog --deep samples  vs the reference
  oiiotool --deepmerge INPUT FOG --flatten     vs the reference (FOG: --deep fog)
and that every output reads back in OpenImageIO and exrheader, with
maxSamplesPerPixel equal to the largest count.

Multi-part input (with EXR_PARTS, tests/refs/exr_parts.cpp: the OpenEXR C++
library writes a flat part and a deep one into one file, which OIIO
refuses to write, and reads every output part back): the fogged part
equals the single-part run exactly, every other part its input exactly.

usage: deep_check.py EXRFOG SHARED_DIR TMPDIR [EXR_PARTS]   (exit 77: skipped)
"""
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import time

try:
    import numpy as np
    import OpenImageIO as oiio
except ImportError:
    print("OpenImageIO python module missing: skipped")
    sys.exit(77)

exrfog, shared, tmp = sys.argv[1:4]
exr_parts = sys.argv[4] if len(sys.argv) > 4 else None
src = os.path.join(shared, "real-exr", "arnold-deep-representative.exr")
if not os.path.exists(src):
    print("no", src, ": skipped")
    sys.exit(77)

FOG_COLOR = (0.7, 0.75, 0.8)
failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def inv4(m):
    """Inverse of a 4x4 (rows) by Gauss-Jordan."""
    a = [list(r) + [1.0 if i == j else 0.0 for j in range(4)] for i, r in enumerate(m)]
    for c in range(4):
        p = max(range(c, 4), key=lambda r: abs(a[r][c]))
        a[c], a[p] = a[p], a[c]
        d = a[c][c]
        a[c] = [v / d for v in a[c]]
        for r in range(4):
            if r != c:
                f = a[r][c]
                a[r] = [x - f * y for x, y in zip(a[r], a[c])]
    return [r[4:] for r in a]


inp = oiio.ImageBuf(src)
spec = inp.spec()
W, H = spec.width, spec.height
w2c = spec.getattribute("worldToCamera")
M = [[w2c[4 * i + j] for j in range(4)] for i in range(4)]   # row vectors: p_cam = p M
C = inv4(M)                                                  # camera -> world
fov = math.radians(spec.getattribute("CameraFov"))
org = C[3][:3]
tanh = math.tan(fov / 2)


# Which way the camera looks in its own space: the unit point ahead has a
# positive homogeneous w under worldToNDC (this Arnold file's camera space
# looks down +Z).
w2n = spec.getattribute("worldToNDC")
N = [[w2n[4 * i + j] for j in range(4)] for i in range(4)]


def ahead_w(s):
    p = [sum((0.0, 0.0, s, 1.0)[j] * C[j][i] for j in range(4)) for i in range(4)]
    return sum(p[i] * N[i][3] for i in range(4))


FWD = 1.0 if ahead_w(1.0) > 0 else -1.0


def pixel_ray(x, y):
    """World direction of pixel (x, y) and the distance per unit of planar Z."""
    sx = (2 * (x + 0.5) / W - 1) * tanh
    sy = -(2 * (y + 0.5) / H - 1) * tanh * H / W
    dc = (sx, sy, FWD)
    k = math.sqrt(sx * sx + sy * sy + 1)
    d = [sum(dc[j] * C[j][i] for j in range(3)) for i in range(3)]
    n = math.sqrt(sum(v * v for v in d))
    return [v / n for v in d], k


def fog_tau(model, o, d, a, b):
    """Optical depth of the fog over distances [a, b) (b may be inf)."""
    if model[0] == "exp":
        return model[1] * (b - a)
    rho, kf, base = model[1:]
    oy, dy = o[1], d[1]
    e0 = rho * math.exp(-kf * (oy - base))
    if abs(kf * dy) < 1e-12:
        return e0 * (b - a)
    fa = math.exp(-kf * dy * a)
    fb = 0.0 if b == math.inf and dy > 0 else (math.inf if b == math.inf else math.exp(-kf * dy * b))
    return e0 * (fa - fb) / (kf * dy)


GL8 = [(-0.9602898564975363, 0.1012285362903763), (-0.7966664774136267, 0.2223810344533745),
       (-0.5255324099163290, 0.3137066458778873), (-0.1834346424956498, 0.3626837833783620),
       (0.1834346424956498, 0.3626837833783620), (0.5255324099163290, 0.3137066458778873),
       (0.7966664774136267, 0.2223810344533745), (0.9602898564975363, 0.1012285362903763)]


def lamp_term(lamp, d, a, b, kappa):
    """A point lamp's single scattering in exp fog over distances [a, b)
    of the pixel's ray (b may be inf): int e^-(kappa (t - a)) sigma p I
    e^-(sigma r) / r^2 dt, r the distance to the lamp, p = 1/(4 pi) (iso,
    albedo 1), kappa the extinction of everything there (fog and input
    media). Gauss-Legendre (8 nodes) on pieces bisected until each is at
    most half its least distance to the lamp (the integrand's poles are
    that far off the real axis); an infinite end in doubling pieces until
    what is left is below 1e-14 of the sum."""
    sig, pos, inten = lamp
    w = [pos[k] - org[k] for k in range(3)]
    ts = sum(w[k] * d[k] for k in range(3))
    h2 = max(0.0, sum(v * v for v in w) - ts * ts)

    def f(t):
        r2 = (t - ts) ** 2 + h2
        r = math.sqrt(r2)
        return math.exp(-kappa * (t - a) - sig * r) * sig * inten / (4 * math.pi) / r2

    def dmin(t0, t1):
        u = min(max(ts, t0), t1) - ts
        return math.sqrt(u * u + h2)

    def piece(t0, t1):
        if t1 - t0 > 0.5 * dmin(t0, t1):
            m = 0.5 * (t0 + t1)
            return piece(t0, m) + piece(m, t1)
        c, hw = 0.5 * (t0 + t1), 0.5 * (t1 - t0)
        return hw * sum(wt * f(c + hw * xx) for xx, wt in GL8)

    if b < math.inf:
        return piece(a, b)
    tot, t0, step = 0.0, a, max(1.0, abs(ts - a))
    while True:
        v = piece(t0, t0 + step)
        tot += v
        t0 += step
        step *= 2
        if t0 > ts and v <= 1e-14 * tot:
            return tot


def reference(model, x, y, samples, what="all", fog_on=True, lamp=None):
    """Flat RGBA of pixel (x, y): samples = [(z, zb, rgba)] in file Z.
    what: "all" (the fogged flatten), "in" (only the input's light, as the
    fog attenuates it: the fog's own source left out), "cov" (the input's
    coverage as the fog attenuates it: every input sample's source 1, so a
    point sample adds its alpha); fog_on=False: no fog at all. lamp: (sigma,
    position, intensity) of a point lamp lighting an exp fog of that
    density (lamp_term), white."""
    d, k = pixel_ray(x, y)
    pts, vols, bounds = [], [], {0.0}
    for z, zb, c in samples:
        if zb > z:
            vols.append((z * k, zb * k, c))
            bounds.update((z * k, zb * k))
        else:
            pts.append((z * k, c))
            bounds.add(z * k)
    bounds = sorted(bounds)
    L = [0.0, 0.0, 0.0]
    T = 1.0          # of everything (grey: A only in this file)
    for i, a in enumerate(bounds):
        for zp, c in pts:
            if zp == a:
                for ch in range(3):
                    L[ch] += T * (c[3] if what == "cov" else c[ch])
                T *= 1 - c[3]
        if i + 1 == len(bounds):
            break
        b = bounds[i + 1]
        media = [(-math.log1p(-c[3]) / (zb - z), c, zb - z) for z, zb, c in vols
                 if z <= a and zb >= b]
        for s in range(16):
            sa, sb = a + (b - a) * s / 16, a + (b - a) * (s + 1) / 16
            tf = fog_tau(model, org, d, sa, sb) if fog_on else 0.0
            tt = tf + sum(kap * (sb - sa) for kap, c, v in media)
            # a volume of alpha 0 only emits: its colour spread over its
            # length (the spec's split of such a sample, c x)
            glow = [sum(c[ch] * (sb - sa) / v for kap, c, v in media if c[3] == 0)
                    if what == "all" else 0.0 for ch in range(3)]
            if tt <= 0:
                for ch in range(3):
                    L[ch] += T * glow[ch]
                continue
            em = 1 - math.exp(-tt) if tt < math.inf else 1.0
            lt = lamp_term(lamp, d, sa, sb, tt / (sb - sa)) if lamp and what == "all" else 0.0
            for ch in range(3):
                srcw = tf * FOG_COLOR[ch] if what == "all" else 0.0
                for kap, c, v in media:
                    srcw += kap * (sb - sa) * (1.0 if what == "cov" else
                                               c[ch] / c[3] if c[3] > 0 else 0)
                L[ch] += T * (em * (srcw + glow[ch]) / tt + lt)
            T *= 1 - em
    # the tail: fog alone to infinity
    tf = fog_tau(model, org, d, bounds[-1], math.inf) if fog_on else 0.0
    em = 1 - math.exp(-tf) if tf < math.inf else 1.0
    lt = lamp_term(lamp, d, bounds[-1], math.inf, lamp[0]) if lamp and what == "all" else 0.0
    for ch in range(3):
        L[ch] += T * (em * FOG_COLOR[ch] + lt) if what == "all" else 0.0
    T *= 1 - em
    return L + [1 - T]


def samples_of(buf):
    dd = buf.deepdata()
    chans = buf.spec().channelnames
    ix = {n: chans.index(n) for n in ("R", "G", "B", "A", "Z")}
    izb = chans.index("ZBack") if "ZBack" in chans else None
    out = []
    for p in range(dd.pixels):
        s = []
        for j in range(dd.samples(p)):
            z = dd.deep_value(p, ix["Z"], j)
            zb = dd.deep_value(p, izb, j) if izb is not None else z
            s.append((z, zb, [dd.deep_value(p, ix[n], j) for n in "RGBA"]))
        out.append(s)
    return out


def read_flat(path):
    """(channel names, pixels) read past OpenImageIO's image cache: a file
    rewritten within the same second (a fast build) would come back stale
    through ImageBuf."""
    inp_ = oiio.ImageInput.open(path)
    chans, px = inp_.spec().channelnames, inp_.read_image(oiio.FLOAT)
    inp_.close()
    return chans, px


def flat_pixels(path):
    chans, px = read_flat(path)
    idx = [chans.index(n) for n in "RGBA"]
    return [[float(px[y][x][i]) for i in idx] for y in range(H) for x in range(W)]


def flat_pixels_any(path):
    chans, px = read_flat(path)
    idx = [chans.index(n) for n in "RGBA"]
    return [[float(r[i]) for i in idx] for row in px for r in row]


def run(args):
    r = subprocess.run([exrfog] + args, capture_output=True, text=True)
    if r.returncode != 0:
        print(" ".join(args), "->", r.returncode, r.stderr)
    return r.returncode


def oiiotool(args):
    return subprocess.run(["oiiotool"] + args, capture_output=True, text=True).returncode


input_samples = samples_of(inp)
def reference_any(model, x, y, samples):
    """reference(), and for per-channel fog ("exp3", d_r, d_g, d_b) each
    channel from its own grey fog (A: not compared, see below)."""
    if model[0] != "exp3":
        return reference(model, x, y, samples)
    return [reference(("exp", model[1 + ch]), x, y, samples)[ch] for ch in range(3)] + [None]


for name, spec_text, model in (
    ("exp", "exp:density=0.05", ("exp", 0.05)),
    ("height", "height:density=0.4:falloff=0.5:base=-1", ("height", 0.4, 0.5, -1.0)),
    ("chromatic exp", "exp:density=0.02,0.05,0.1", ("exp3", 0.02, 0.05, 0.1)),
):
    outs = {}
    for mode in ("samples", "fog", "flatten"):
        outs[mode] = os.path.join(tmp, "deep_%s_%s.exr" % (name, mode))
        check(run([src, "--fog", spec_text, "--deep", mode, "-o", outs[mode]]) == 0,
              "%s --deep %s runs" % (name, mode))
    # --deep flatten's Z is the input's nearest sample (issue 42: the fog's
    # samples start at the camera and once made it 0 everywhere), read from
    # the input by OIIO's deep API; inf where the pixel holds no sample
    zin = oiio.ImageBuf(src)
    zdd, zci = zin.deepdata(), zin.spec().channelnames.index("Z")
    zf = oiio.ImageBuf(outs["flatten"])
    zpx = zf.get_pixels(oiio.FLOAT)
    zo = zf.spec().channelnames.index("Z")
    zbad = 0
    for p in range(zdd.pixels):
        n = zdd.samples(p)
        want = min(zdd.deep_value(p, zci, j) for j in range(n)) if n else float("inf")
        got = float(zpx[p // W][p % W][zo])
        if not (got == want or abs(got - want) <= 1e-6 * max(1.0, abs(want))):
            zbad += 1
    check(zbad == 0, "%s --deep flatten: Z is the nearest input sample (%d pixels differ)"
          % (name, zbad))
    flat_s = os.path.join(tmp, "deep_%s_samples_flat.exr" % name.replace(" ", "_"))
    flat_m = os.path.join(tmp, "deep_%s_merge_flat.exr" % name)
    check(oiiotool([outs["samples"], "--flatten", "-o", flat_s]) == 0, "oiiotool flattens samples")
    # (OIIO merges only equal channel lists: the chromatic element has
    # AR/AG/AB and the input has not)
    if model[0] != "exp3":
        check(oiiotool([src, outs["fog"], "--deepmerge", "--flatten", "-o", flat_m]) == 0,
              "oiiotool deep-merges the fog element")
    # every deep output: maxSamplesPerPixel = the largest count, and
    # OpenEXR's own tool reads the header
    for mode in ("samples", "fog") if model[0] != "exp3" else ():
        b = oiio.ImageBuf(outs[mode])
        dd = b.deepdata()
        mx = max(dd.samples(p) for p in range(dd.pixels))
        hdr = subprocess.run(["exrheader", outs[mode]], capture_output=True, text=True)
        check(hdr.returncode == 0 and ("maxSamplesPerPixel (type int): %d" % mx) in hdr.stdout,
              "%s %s: exrheader shows maxSamplesPerPixel %d" % (name, mode, mx))
    if model[0] == "exp3":
        for mode in ("samples", "fog"):
            cn = oiio.ImageBuf(outs[mode]).spec().channelnames
            check(all(c in cn for c in ("AR", "AG", "AB")),
                  "chromatic fog: --deep %s writes AR, AG, AB (%s)" % (mode, ",".join(cn)))
    # every output read in full by the OpenEXR C++ library (tests/refs/exr_parts.cpp)
    for mode, path in outs.items():
        if exr_parts and os.path.exists(exr_parts):
            rb = subprocess.run([exr_parts, "read", path], capture_output=True, text=True)
            check(rb.returncode == 0, "%s --deep %s: the OpenEXR library reads it (%s)"
                  % (name, mode, rb.stderr.strip()))
    # exrfog/history names the mode and the tolerance, defaults included
    hist_out = os.path.join(tmp, "deep_history.exr")
    if name == "exp" and run([src, "--fog", spec_text, "-o", hist_out]) == 0:
        h = oiio.ImageBuf(hist_out).spec().get_string_attribute("exrfog/history")
        check("(deep: --deep samples --deep-tol 0.001)" in h,
              "exrfog/history records the deep mode and tolerance (%s)" % h)
    results = {"flatten": flat_pixels(outs["flatten"])}
    if model[0] != "exp3":
        results["samples+oiio flatten"] = flat_pixels(flat_s)
        results["fog element+oiio deepmerge"] = flat_pixels(flat_m)
    else:
        # OpenImageIO 2.4.7's flatten mishandles AR/AG/AB (alphas above 1
        # come out): the samples are flattened here, by the spec's "over"
        # with R over AR, G over AG, B over AB
        b = oiio.ImageBuf(outs["samples"])
        cn = b.spec().channelnames
        dd = b.deepdata()
        ic = [cn.index(c) for c in ("R", "G", "B", "AR", "AG", "AB", "Z", "ZBack")]
        mine = []
        for p in range(dd.pixels):
            acc, al = [0.0] * 3, [0.0] * 3
            ss = sorted(range(dd.samples(p)),
                        key=lambda j: (dd.deep_value(p, ic[6], j), dd.deep_value(p, ic[7], j)))
            for j in ss:
                for ch in range(3):
                    a = dd.deep_value(p, ic[3 + ch], j)
                    acc[ch] += (1 - al[ch]) * dd.deep_value(p, ic[ch], j)
                    al[ch] += (1 - al[ch]) * a
            mine.append(acc + [0.0])
        results["samples+flatten here"] = mine
        # --deep-grey-alpha: every sample's alphas the least, the rest folded
        # into colour, so that "over" with A alone (Nuke, Gaffer) gives every
        # channel its own fog
        grey = os.path.join(tmp, "deep_grey_samples.exr")
        check(run([src, "--fog", spec_text, "--deep", "samples", "--deep-grey-alpha",
                   "-o", grey]) == 0, "--deep-grey-alpha runs")
        b = oiio.ImageBuf(grey)
        cn = b.spec().channelnames
        dd = b.deepdata()
        ic = [cn.index(c) for c in ("R", "G", "B", "A", "Z", "ZBack")]
        amix = 0.0
        mine_a = []
        for p in range(dd.pixels):
            acc, al = [0.0] * 3, 0.0
            ss = sorted(range(dd.samples(p)),
                        key=lambda j: (dd.deep_value(p, ic[4], j), dd.deep_value(p, ic[5], j)))
            for j in ss:
                a = dd.deep_value(p, ic[3], j)
                for ch in range(3):
                    acc[ch] += (1 - al) * dd.deep_value(p, ic[ch], j)
                for c in ("AR", "AG", "AB"):
                    if c in cn:
                        amix = max(amix, abs(dd.deep_value(p, cn.index(c), j) - a))
                al += (1 - al) * a
            mine_a.append(acc + [None])
        check(amix == 0, "--deep-grey-alpha: AR, AG, AB equal A (%g)" % amix)
        results["grey alpha+flatten with A alone"] = mine_a
    worst = {k: 0.0 for k in results}
    n = 0
    for y in range(0, H, 2):
        for x in range(0, W, 2):
            p = y * W + x
            ref = reference_any(model, x, y, input_samples[p])
            n += 1
            for k, got in results.items():
                for ch in range(4):
                    # half output: 2^-10 relative, plus the rounding of up to
                    # a few hundred half samples summed. Chromatic fog's A is
                    # the mean of AR/AG/AB per sample, not a transmittance.
                    if ref[ch] is None or got[p][ch] is None:
                        continue
                    e = abs(got[p][ch] - ref[ch]) / (1e-3 + abs(ref[ch]))
                    worst[k] = max(worst[k], e)
    for k, e in worst.items():
        print("%s: %s: worst relative error %.2e over %d pixels" % (name, k, e, n))
        check(e < 4e-3, "%s: %s within 4e-3 of the reference (%.2e)" % (name, k, e))

# --deep flatten --aov (issue 24): the AOVs against the reference's parts,
# per pixel (every 3rd each way):
#   fog.RGB = the fogged flatten less the input's light as the fog
#             attenuates it; fog.A = its alpha less the input's own
#   fog_T   = the input's coverage as the fog attenuates it over the input's
#             own coverage (where it covers nothing: the fog's own T)
#   fog_distance.Z = the nearest sample's Z times the ray's distance per Z,
#   fog_P   = the camera plus the ray to there
for spec_text, model in (("exp:density=0.05", ("exp", 0.05)),
                         ("height:density=0.4:falloff=0.5:base=-1", ("height", 0.4, 0.5, -1.0))):
    out = os.path.join(tmp, "deep_aov.exr")
    check(run([src, "--fog", spec_text, "--deep", "flatten", "--aov", "fog,T,error,P,distance",
               "-o", out]) == 0, "--deep flatten --aov runs (%s)" % spec_text)
    b = oiio.ImageBuf(out)
    # the parameters name the deep mode once (issue 42: it stood twice)
    par = b.spec().get_string_attribute("exrfog/parameters")
    check(par.count("--deep flatten") == 1 and par.count("--deep-tol") == 1,
          "exrfog/parameters names --deep flatten once: %s" % par)
    cn = b.spec().channelnames
    px = b.get_pixels(oiio.FLOAT)
    need = ["fog.R", "fog.G", "fog.B", "fog.A", "fog_T.R", "fog_T.G", "fog_T.B",
            "fog_error.R", "fog_P.X", "fog_P.Y", "fog_P.Z", "fog_distance.Z"]
    check(all(c in cn for c in need), "AOV channels present (%s)" % ",".join(cn))
    if not all(c in cn for c in need):
        continue
    ix = {c: cn.index(c) for c in need + ["R", "G", "B", "A"]}
    worst = {"fog": 0.0, "T": 0.0, "P": 0.0, "identity": 0.0}
    n = 0
    for y in range(0, H, 3):
        for x in range(0, W, 3):
            p = y * W + x
            smp = input_samples[p]
            allp = reference(model, x, y, smp)
            inp_ = reference(model, x, y, smp, "in")
            cov = reference(model, x, y, smp, "cov")
            own = reference(model, x, y, smp, "cov", fog_on=False)
            v = px[y][x]
            for ch in range(3):
                e = abs(v[ix["fog." + "RGB"[ch]]] - (allp[ch] - inp_[ch]))
                worst["fog"] = max(worst["fog"], e / (1e-3 + abs(allp[ch])))
            worst["fog"] = max(worst["fog"], abs(v[ix["fog.A"]] - (allp[3] - own[3])) / (1e-3 + allp[3]))
            if own[0] > 0:
                tref = cov[0] / own[0]
            else:
                tref = 1 - allp[3]
            for c in ("fog_T.R", "fog_T.G", "fog_T.B"):
                worst["T"] = max(worst["T"], abs(v[ix[c]] - tref))
            d, k = pixel_ray(x, y)
            if smp:
                zmin = min(z for z, zb, c in smp) * k
                for a, c in enumerate(("fog_P.X", "fog_P.Y", "fog_P.Z")):
                    worst["P"] = max(worst["P"], abs(v[ix[c]] - (org[a] + d[a] * zmin)) / (1 + abs(zmin)))
                worst["P"] = max(worst["P"], abs(v[ix["fog_distance.Z"]] - zmin) / (1 + zmin))
            else:
                check(math.isinf(v[ix["fog_distance.Z"]]), "an empty pixel's distance is inf")
            # closed forms: no error
            check(v[ix["fog_error.R"]] == 0, "closed-form fog: fog_error is 0")
            n += 1
    print("--deep flatten --aov %s: %d pixels, worst fog %.2e (relative), T %.2e, P %.2e"
          % (spec_text, n, worst["fog"], worst["T"], worst["P"]))
    check(worst["fog"] < 4e-3, "%s: fog AOV within 4e-3 of the reference" % spec_text)
    check(worst["T"] < 2e-3, "%s: fog_T within 2e-3 of the reference" % spec_text)
    check(worst["P"] < 1e-5, "%s: fog_P and fog_distance at the nearest sample" % spec_text)

# Multi-part input: a deep part beside a flat one (and two deep parts).
def deep_values(path, sub):
    b = oiio.ImageBuf(path, sub, 0)
    dd = b.deepdata()
    cn = b.spec().channelnames
    return [(cn[c], dd.samples(p), [dd.deep_value(p, c, j) for j in range(dd.samples(p))])
            for p in range(dd.pixels) for c in range(len(cn))]


def flat_values(path, sub):
    b = oiio.ImageBuf(path, sub, 0)
    return b.spec().channelnames, b.get_pixels(oiio.FLOAT)


if exr_parts and os.path.exists(exr_parts):
    flat_src = os.path.join(shared, "real-exr", "arnold-representative-flat.exr")
    mixed = os.path.join(tmp, "mixed_parts.exr")
    check(subprocess.run([exr_parts, "mix", mixed, flat_src, src]).returncode == 0,
          "exr_parts writes a flat and a deep part into one file")
    fogs = "height:density=0.4:falloff=0.5:base=-1"
    single = {m: os.path.join(tmp, "single_%s.exr" % m) for m in ("samples", "flatten")}
    for m, out in single.items():
        check(run([src, "--fog", fogs, "--deep", m, "-o", out]) == 0, "single-part %s runs" % m)
    single_flat = os.path.join(tmp, "single_flatpart.exr")
    check(run([flat_src, "--fog", fogs, "-o", single_flat]) == 0, "the flat file alone runs")
    for m in ("samples", "flatten", "flat part"):
        out = os.path.join(tmp, "mixed_out_%s.exr" % m.replace(" ", "_"))
        args = [mixed, "--fog", fogs, "--layer", "part0" if m == "flat part" else "part1", "-o", out]
        if m != "flat part":
            args += ["--deep", m]
        check(run(args) == 0, "multi-part input, %s: runs" % m)
        rb = subprocess.run([exr_parts, "read", out], capture_output=True, text=True)
        lines = rb.stdout.split("\n")
        check(rb.returncode == 0 and len([l for l in lines if l]) == 2,
              "multi-part %s: the OpenEXR library reads both parts back (%s%s)"
              % (m, rb.stdout.strip(), rb.stderr.strip()))
        # part 0: the flat part, as it was or fogged as the flat file alone
        ca, pa = flat_values(out, 0)
        cb, pb = flat_values(single_flat if m == "flat part" else flat_src, 0)
        check(list(ca) == list(cb) and (pa == pb).all(),
              "multi-part %s: the flat part is %s" % (m, "fogged as alone" if m == "flat part"
                                                      else "copied exactly"))
        # part 1: the deep part, fogged as alone or copied
        if m == "flatten":
            ca, pa = flat_values(out, 1)
            cb, pb = flat_values(single["flatten"], 0)
            check(list(ca) == list(cb) and (pa == pb).all(),
                  "multi-part flatten: the deep part flattens as alone")
        else:
            ref_path = single["samples"] if m == "samples" else src
            check(deep_values(out, 1) == deep_values(ref_path, 0),
                  "multi-part %s: the deep part is %s" % (m, "fogged as alone" if m == "samples"
                                                          else "copied exactly"))
        hdr = subprocess.run(["exrheader", out], capture_output=True, text=True)
        names = [l for l in hdr.stdout.split("\n") if l.startswith("name (type string)")]
        check(hdr.returncode == 0 and len(names) == 2,
              "multi-part %s: exrheader lists both parts (%s)" % (m, names))
    # a truncated multi-part file: refused naming it, whichever part is fogged,
    # and nothing written
    data = open(mixed, "rb").read()
    trunc = os.path.join(tmp, "mixed_trunc.exr")
    with open(trunc, "wb") as fh:
        fh.write(data[:len(data) * 2 // 3])
    for layer in ("part0", "part1"):
        out = os.path.join(tmp, "mixed_trunc_out.exr")
        if os.path.exists(out):
            os.remove(out)
        r = subprocess.run([exrfog, trunc, "--layer", layer, "--fog", fogs, "-o", out],
                           capture_output=True, text=True)
        check(r.returncode == 1 and r.stderr.startswith("exrfog: " + trunc + ": ") and
              "truncated or corrupt" in r.stderr and not os.path.exists(out),
              "truncated multi-part file, --layer %s: exit 1 naming it, nothing written (%d %s)"
              % (layer, r.returncode, r.stderr.strip()))
    # cut anywhere, the reason never ends empty (issue 47: OpenEXRCore keeps
    # no message for a chunk whose offset is the end of the file, and
    # "...corrupt): " followed): cut at 7 lengths and at chunk starts, read
    # from the offset tables (headers: attributes name, type, size, value;
    # an empty name ends one, an empty header the list; then per part
    # chunkCount offsets of 8 bytes)
    def chunk_starts(b):
        at, counts = 8, []
        while b[at] != 0:
            while b[at] != 0:
                name_end = b.index(0, at)
                type_end = b.index(0, name_end + 1)
                size = int.from_bytes(b[type_end + 1:type_end + 5], "little")
                if b[at:name_end] == b"chunkCount":
                    counts.append(int.from_bytes(b[type_end + 5:type_end + 9], "little"))
                at = type_end + 5 + size
            at += 1
        at += 1
        total = sum(counts)
        return [int.from_bytes(b[at + 8 * i:at + 8 * i + 8], "little") for i in range(total)]
    starts = chunk_starts(data)
    cuts = sorted(set([len(data) * k // 8 for k in range(1, 8)] + starts[1::max(1, len(starts) // 10)]))
    empty = []
    for n in cuts:
        with open(trunc, "wb") as fh:
            fh.write(data[:n])
        for layer in ("part0", "part1"):
            r = subprocess.run([exrfog, trunc, "--layer", layer, "--fog", fogs, "-o",
                                os.path.join(tmp, "mixed_trunc_out.exr")],
                               capture_output=True, text=True)
            if r.returncode != 1 or r.stderr.rstrip().endswith(":"):
                empty.append((n, layer, r.returncode, r.stderr.strip()))
    check(not empty, "truncated multi-part files at %d lengths: exit 1 with a reason (%s)"
          % (len(cuts), empty[:2]))
    # two deep parts (OIIO writes those): the chosen one fogged, the other copied
    two = os.path.join(tmp, "two_deep.exr")
    check(oiiotool([src, "--attrib", "name", "left", src, "--attrib", "name", "right",
                    "--siappend", "-o", two]) == 0, "oiiotool writes two deep parts")
    # (OIIO writes float channels: the single-part yardstick is its float copy,
    # whose alpha takes more optical depth per fog sample than half)
    src_f = os.path.join(tmp, "src_float.exr")
    single_f = os.path.join(tmp, "single_float_samples.exr")
    check(oiiotool([src, "-o", src_f]) == 0 and run([src_f, "--fog", fogs, "-o", single_f]) == 0,
          "the float copy alone runs")
    out = os.path.join(tmp, "two_deep_out.exr")
    check(run([two, "--fog", fogs, "--layer", "right", "-o", out]) == 0, "two deep parts run")
    check(deep_values(out, 0) == deep_values(src_f, 0), "two deep parts: left copied exactly")
    check(deep_values(out, 1) == deep_values(single_f, 0),
          "two deep parts: right fogged as alone")
    # --deep flatten of a multi-part file's deep part to TIFF and PNG
    # (issue 47: "cannot read the fogged frame back" with an empty reason,
    # after the run): the deliverable equals the single-part file's
    for ext in ("tif", "png"):
        mo, so_ = os.path.join(tmp, "mixed_deliver." + ext), os.path.join(tmp, "single_deliver." + ext)
        ok = run([mixed, "--fog", fogs, "--layer", "part1", "--deep", "flatten", "-o", mo]) == 0
        ok &= run([src, "--fog", fogs, "--deep", "flatten", "-o", so_]) == 0
        check(ok and flat_pixels_any(mo) == flat_pixels_any(so_),
              "multi-part --deep flatten to %s = the single part's" % ext)
    print("multi-part deep input: checked")
else:
    print("no exr_parts: multi-part checks skipped")

# The holdout property: a fog sample split at any fraction x by the deep
# rule, 1 - (1 - alpha)^x, against the exact transmittance of the fog over
# the same part of the ray, weighted by T from the camera to the sample:
# within --deep-tol (the default, 1e-3). The exact part is computed here:
# closed forms for height, layered (piecewise linear in height, integrated
# piece by piece) and box (the length inside), and for noise a fine
# Gauss-Legendre quadrature of the density from tests/refs/perlin_ref.py's
# independent Perlin noise (floats), 8 nodes per eighth of the finest cell.
import random
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "refs"))
import perlin_ref


def tau_exact(model, d, a, b):
    """The fog's optical depth over distances [a, b) of direction d."""
    kind = model[0]
    if kind in ("exp", "height"):
        return fog_tau(model, org, d, a, b)
    if kind == "layered":
        hs, ds = model[1], model[2]
        def dens(y):
            if y <= hs[0]:
                return ds[0]
            if y >= hs[-1]:
                return ds[-1]
            for i in range(len(hs) - 1):
                if y <= hs[i + 1]:
                    w = (y - hs[i]) / (hs[i + 1] - hs[i])
                    return ds[i] * (1 - w) + ds[i + 1] * w
        cuts = [a, b]
        if d[1] != 0:
            cuts += [t for t in ((h - org[1]) / d[1] for h in hs) if a < t < b]
        cuts.sort()
        return sum((t1 - t0) * 0.5 * (dens(org[1] + d[1] * t0) + dens(org[1] + d[1] * t1))
                   for t0, t1 in zip(cuts, cuts[1:]))
    if kind == "box":
        lo, hi, rho = model[1], model[2], model[3]
        t0, t1 = a, b
        for k in range(3):
            if d[k] == 0:
                if not (lo[k] < org[k] < hi[k]):
                    return 0.0
                continue
            ta, tb = (lo[k] - org[k]) / d[k], (hi[k] - org[k]) / d[k]
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        return rho * max(0.0, t1 - t0)
    # noise: (rho, scale, octaves, contrast)
    rho, scale, octaves, c = model[1:]
    step = scale / 2 ** (octaves - 1) / 8
    n = max(1, int(math.ceil((b - a) / step)))
    h = (b - a) / n
    tot = 0.0
    for i in range(n):
        m0 = a + (i + 0.5) * h
        for x, w in GL8:
            t = m0 + 0.5 * h * x
            p = [org[k] + d[k] * t for k in range(3)]
            q = perlin_ref.noise_q(p, (0, 0, 0), (0, 0, 0), 0.0, scale, 0.0)
            f = perlin_ref.fbm(q, octaves, 2.0, 0.5)
            tot += 0.5 * h * w * rho * max(0.0, 1 + c * f)
    return tot


rnd = random.Random(24)
for spec_text, model, step in (
        ("height:density=0.4:falloff=0.5:base=-1", ("height", 0.4, 0.5, -1.0), 7),
        ("height:density=2:falloff=3:base=-2", ("height", 2.0, 3.0, -2.0), 7),
        ("layered:heights=-1,0,1:densities=0.05,0.5,0.1", ("layered", [-1, 0, 1], [0.05, 0.5, 0.1]), 7),
        ("box:min=-1,-1,-1:max=1,0.5,2:density=0.6", ("box", [-1, -1, -1], [1, 0.5, 2], 0.6), 7),
        # a profile of 100 knots going up and down (more features than fit
        # a fixed buffer: every knot must still cut the fog)
        ("layered:heights=%s:densities=%s" % (",".join(repr(-2 + i * 0.05) for i in range(100)),
                                             ",".join(repr(0.3 + 0.25 * math.sin(i * 0.7))
                                                      for i in range(100))),
         ("layered", [-2 + i * 0.05 for i in range(100)],
          [0.3 + 0.25 * math.sin(i * 0.7) for i in range(100)]), 29),
        ("noise:density=0.3:scale=2:octaves=2", ("noise", 0.3, 2.0, 2, 0.9), 97)):
    el = os.path.join(tmp, "deep_holdout.exr")
    check(run([src, "--fog", spec_text, "--deep", "fog", "-o", el]) == 0, "holdout element runs")
    fs = samples_of(oiio.ImageBuf(el))
    worst, worst_rule, nsplit = 0.0, 0.0, 0
    for p in range(0, W * H, step):
        x, y = p % W, p // W
        d, k = pixel_ray(x, y)
        T = 1.0
        for z, zb, c in fs[p]:
            a_, b_ = z * k, zb * k
            if c[3] >= 1 or b_ <= a_ or T < 1e-3:
                break
            tab = tau_exact(model, d, a_, b_)
            for _ in range(3 if model[0] != "noise" else 1):
                f = rnd.random()
                exact = math.exp(-tau_exact(model, d, a_, a_ + f * (b_ - a_)))
                # the placement rule alone (the slab's exact tau), and what a
                # reader gets from the stored half alpha
                worst_rule = max(worst_rule, T * abs(math.exp(-f * tab) - exact))
                worst = max(worst, T * abs((1 - c[3]) ** f - exact))
                nsplit += 1
            T *= 1 - c[3]
    print("holdout %s: %d splits, worst T|dT| %.2e from the placement, %.2e with half alpha"
          % (spec_text[:60], nsplit, worst_rule, worst))
    check(worst_rule <= 1e-3, "holdout splits of %s: placement within --deep-tol" % spec_text)
    # half alpha (11 bits) adds its rounding, amplified by e^(tau-1)/tau <= 1.36 at tau 2
    check(worst <= 1e-3 + 1e-3, "holdout splits of %s within --deep-tol + half rounding" % spec_text)

# Multiple scattering in every deep mode (issue 44): a sun with
# scattering=multiple over a half-space layer, a sky light of a constant
# map carried through it, a point lamp in exp fog (its multiple
# scattering beside the dense output of its single scattering) and one in
# height fog (ms.h's local mode: inside the dense output's integrand), and
# a spot in exp fog (its cone's share read at every node, inside the cone
# and out). Each deep sample gathers its own share of the
# solve, so the three ways to a flat image (--deep flatten, --deep samples
# flattened by OIIO, the fog element deep-merged by OIIO) must agree within
# half precision; and the multiple scattering must take effect: the sun's
# and the lamp's add light, the sky's replaces its unattenuated single
# scattering (a test of the plumbing, not the values: test_ms, test_lms and
# blender_ms hold those).
env1 = os.path.join(tmp, "env_one.exr")
eb = oiio.ImageBuf(oiio.ImageSpec(64, 32, 3, oiio.FLOAT))
eb.set_pixels(oiio.ROI(), np.ones((32, 64, 3), np.float32))
check(eb.write(env1), "writes a constant environment")
ms_fog_layer = ["--fog", "halfspace:plane=0,1,0,-3:density=0.1:albedo=0.95:phase=hg:g=0.6"]
lamp_fog = ["--fog", "exp:density=0.05:albedo=0.95:phase=hg:g=0.6"]
height_fog = ["--fog", "height:density=0.1:falloff=0.3:base=-1:albedo=0.95:phase=hg:g=0.6"]
lamp_ms = ["--light", "point:position=0.5,1,3:intensity=5:scattering=multiple"]
for what, light in (("sun", ["--light", "sun:towards=0.3,1,0.5:intensity=2:scattering=multiple"]),
                    ("sky", ["--sky-light", env1 + ":scattering=multiple"]),
                    ("lamp", lamp_ms), ("lamp in height fog", lamp_ms),
                    ("spot", ["--light", "spot:position=0.5,1,3:aim=0,-1,1:cone=120:blend=0.2:"
                              "intensity=5:scattering=multiple"])):
    ms_fog = (lamp_fog if what in ("lamp", "spot") else
              height_fog if what == "lamp in height fog" else ms_fog_layer)
    mo = {}
    for mode in ("samples", "fog", "flatten"):
        mo[mode] = os.path.join(tmp, "deep_ms_%s_%s.exr" % (what.replace(" ", "_"), mode))
        check(run([src] + ms_fog + light + ["--deep", mode, "-o", mo[mode]]) == 0,
              "multiple scattering (%s): --deep %s runs" % (what, mode))
    single = os.path.join(tmp, "deep_ms_%s_single.exr" % what.replace(" ", "_"))
    single_light = [a.replace("scattering=multiple", "scattering=single") for a in light]
    check(run([src] + ms_fog + single_light + ["--deep", "flatten", "-o", single]) == 0,
          "single scattering (%s): --deep flatten runs" % what)
    fs = os.path.join(tmp, "deep_ms_%s_samples_flat.exr" % what.replace(" ", "_"))
    fm = os.path.join(tmp, "deep_ms_%s_merge_flat.exr" % what.replace(" ", "_"))
    check(oiiotool([mo["samples"], "--flatten", "-o", fs]) == 0, "oiiotool flattens the samples")
    check(oiiotool([src, mo["fog"], "--deepmerge", "--flatten", "-o", fm]) == 0,
          "oiiotool deep-merges the fog element")
    base = flat_pixels(mo["flatten"])
    one = flat_pixels(single)
    gain = max(base[p][0] - one[p][0] for p in range(W * H))
    change = max(abs(base[p][0] - one[p][0]) for p in range(W * H))
    print("multiple scattering (%s) in deep: adds up to %.3f to a pixel, changes one by up to "
          "%.3f" % (what, gain, change))
    if what != "sky":
        check(gain > 0.01, "multiple scattering (%s) adds light on deep input" % what)
    else:
        check(change > 0.01, "multiple scattering (sky) replaces the unattenuated sky on deep input")
    for name, path in (("samples + oiio flatten", fs), ("fog element + oiio deepmerge", fm)):
        got = flat_pixels(path)
        worst = max(abs(got[p][ch] - base[p][ch]) / (1e-2 + abs(base[p][ch]))
                    for p in range(W * H) for ch in range(4))
        print("multiple scattering (%s): %s against --deep flatten: %.2e" % (what, name, worst))
        check(worst < 4e-3, "multiple scattering (%s): %s within half precision of --deep "
              "flatten" % (what, name))

# Lit fog in every deep mode (issue 25): a white point lamp of 5 W/sr in
# front of the Arnold frame's objects (camera at z 7.26, objects about the
# origin) lights exp fog of density 0.05. Every mode's flatten against the
# reference, whose fog source adds the lamp's single scattering
# integrated here (lamp_term), every 5th pixel each way. Then the holdout
# property for colour: a fog sample of the --deep fog element split at a
# random fraction x by the deep rule, c (1 - (1 - alpha)^x) / alpha,
# against the exact colour of that part of the ray (the ambient share and
# the lamp's light over it, seen from the sample's front), weighted by T
# from the camera: within --deep-tol (1e-3) of the pixel's light (the
# lamp's over the whole ray), the placement alone (exact alpha and colour
# of the sample, computed here) and as stored (half: plus 2^-9 of the
# sample's colour).
SIG_LIT = 0.05
LAMP = (SIG_LIT, (1.5, 1.0, 3.0), 5.0)
lit_args = ["--fog", "exp:density=0.05", "--light", "point:position=1.5,1,3:intensity=5"]
louts = {}
for mode in ("samples", "fog", "flatten"):
    louts[mode] = os.path.join(tmp, "deep_lit_%s.exr" % mode)
    check(run([src] + lit_args + ["--deep", mode, "-o", louts[mode]]) == 0,
          "lit --deep %s runs" % mode)
lflat_s = os.path.join(tmp, "deep_lit_samples_flat.exr")
lflat_m = os.path.join(tmp, "deep_lit_merge_flat.exr")
check(oiiotool([louts["samples"], "--flatten", "-o", lflat_s]) == 0, "oiiotool flattens lit samples")
check(oiiotool([src, louts["fog"], "--deepmerge", "--flatten", "-o", lflat_m]) == 0,
      "oiiotool deep-merges the lit fog element")
lres = {"flatten": flat_pixels(louts["flatten"]), "samples+oiio flatten": flat_pixels(lflat_s),
        "fog element+oiio deepmerge": flat_pixels(lflat_m)}
unlit = flat_pixels(os.path.join(tmp, "deep_exp_flatten.exr"))
worst = {k: 0.0 for k in lres}
n, lamp_share = 0, 0.0
for y in range(0, H, 5):
    for x in range(0, W, 5):
        p = y * W + x
        ref = reference(("exp", SIG_LIT), x, y, input_samples[p], lamp=LAMP)
        n += 1
        lamp_share = max(lamp_share, (lres["flatten"][p][0] - unlit[p][0]) / max(1e-3, ref[0]))
        for k, got in lres.items():
            for ch in range(4):
                e = abs(got[p][ch] - ref[ch]) / (1e-3 + abs(ref[ch]))
                worst[k] = max(worst[k], e)
for k, e in worst.items():
    print("lit exp: %s: worst relative error %.2e over %d pixels" % (k, e, n))
    check(e < 4e-3, "lit exp: %s within 4e-3 of the reference (%.2e)" % (k, e))
print("lit exp: the lamp's light is up to %.0f %% of a pixel" % (100 * lamp_share))
check(lamp_share > 0.3, "lit exp: the lamp lights the fog (%.2f of a pixel at most)" % lamp_share)

# --deep flatten --aov light: the lamp's layer against the reference's own
# lamp term (the reference with the lamp less the reference without), and
# the ambient layer against the reference without it less the input as the
# fog attenuates it (the fog AOV of the unlit run): the layers through the
# interleaved media of the Arnold frame.
lay = os.path.join(tmp, "deep_lit_layers.exr")
check(run([src] + lit_args + ["--deep", "flatten", "--aov", "fog,light", "-d", "float", "-o", lay])
      == 0, "lit --deep flatten --aov light runs")
lb = oiio.ImageBuf(lay)
lch = lb.spec().channelnames
lpx = lb.get_pixels(oiio.FLOAT)
check(run([src, "--fog", "exp:density=0.05", "--deep", "flatten", "--aov", "fog", "-d", "float",
           "-o", os.path.join(tmp, "deep_unlit_fog_aov.exr")]) == 0, "unlit --deep flatten --aov fog runs")
upx = oiio.ImageBuf(os.path.join(tmp, "deep_unlit_fog_aov.exr")).get_pixels(oiio.FLOAT)
uch = oiio.ImageBuf(os.path.join(tmp, "deep_unlit_fog_aov.exr")).spec().channelnames
wl, wa, nl = 0.0, 0.0, 0
for y in range(0, H, 7):
    for x in range(0, W, 7):
        p = y * W + x
        with_l = reference(("exp", SIG_LIT), x, y, input_samples[p], lamp=LAMP)
        without = reference(("exp", SIG_LIT), x, y, input_samples[p])
        for ch, c in enumerate("RGB"):
            want = with_l[ch] - without[ch]
            got = float(lpx[y, x, lch.index("fog_light.point1." + c)])
            wl = max(wl, abs(got - want) / (1e-3 + abs(with_l[ch])))
            amb = float(lpx[y, x, lch.index("fog_ambient." + c)])
            wa = max(wa, abs(amb - float(upx[y, x, uch.index("fog." + c)])) /
                     (1e-3 + abs(with_l[ch])))
        nl += 1
print("lit exp, --aov light on deep input: the lamp's layer within %.2e of the reference's lamp "
      "term, the ambient within %.2e of the unlit run's fog, %d pixels" % (wl, wa, nl))
check(wl < 4e-3, "deep --aov light: the lamp's layer against the reference (%.2e)" % wl)
check(wa < 1e-6, "deep --aov light: the ambient equals the unlit fog (%.2e)" % wa)

lfs = samples_of(oiio.ImageBuf(louts["fog"]))
worst_rule, worst_half, nsplit = 0.0, 0.0, 0
for p in range(0, W * H, 13):
    x, y = p % W, p // W
    d, k = pixel_ray(x, y)
    scale = lamp_term(LAMP, d, 0.0, math.inf, SIG_LIT)
    T = 1.0
    for z, zb, c in lfs[p]:
        a_, b_ = z * k, zb * k
        # (the last sample carries the fog to infinity: alpha 1, not split)
        if c[3] >= 1 or b_ <= a_ or T < 1e-3:
            break
        tau = SIG_LIT * (b_ - a_)
        al = -math.expm1(-tau)
        c_exact = FOG_COLOR[0] * al + lamp_term(LAMP, d, a_, b_, SIG_LIT)
        for _ in range(3):
            f = rnd.random()
            part = (FOG_COLOR[0] * -math.expm1(-f * tau) +
                    lamp_term(LAMP, d, a_, a_ + f * (b_ - a_), SIG_LIT))
            worst_rule = max(worst_rule, T * abs(c_exact * -math.expm1(-f * tau) / al - part) / scale)
            # (the rule for a sample whose alpha is 0: its colour times x)
            rule = c[0] * (1 - (1 - c[3]) ** f) / c[3] if c[3] > 0 else c[0] * f
            # stored: the tolerance plus half's rounding of the colour and
            # alpha (2^-11 each, the ratio's doubled): a ratio to that sum
            worst_half = max(worst_half, T * abs(rule - part) /
                             (1e-3 * scale + 2 ** -9 * T * abs(c[0])))
            nsplit += 1
        T *= 1 - c[3]
print("lit holdout: %d splits, worst T|dC| / the pixel's light %.2e from the placement; "
      "as stored (half), T|dC| at most %.2f of the tolerance plus half's rounding"
      % (nsplit, worst_rule, worst_half))
check(nsplit > 1000, "lit holdout: splits tried (%d)" % nsplit)
check(worst_rule <= 1e-3, "lit holdout: placement within --deep-tol (%.2e)" % worst_rule)
check(worst_half <= 1, "lit holdout: as stored within --deep-tol + half rounding (%.2f)"
      % worst_half)

# Lit deep fog with shafts: the sample frame (a 200 x 100 crop) deepened by
# OpenImageIO (one opaque point sample per pixel; the sky an alpha-0 sample
# far away), a sun through make_sample's own depth render from the sun as
# its shadow map, and a lamp. The flat image's run (float) is held to the
# reference in test_light and test_shadow; the deep runs must give its
# pixels: --deep flatten, and --deep samples flattened by OpenImageIO, whose
# fog samples are cut at the lit intervals' ends and split for the colour
# contract (within 1e-6: float rounding of the summed samples).
sample_exr = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "samples", "sample.exr")
make_sample = os.path.join(os.path.dirname(os.path.abspath(exrfog)), "make_sample")
if os.path.exists(sample_exr) and os.path.exists(make_sample):
    cflat, cdeep = os.path.join(tmp, "lit_crop.exr"), os.path.join(tmp, "lit_crop_deep.exr")
    smap = os.path.join(tmp, "lit_sunmap.exr")
    check(oiiotool([sample_exr, "--crop", "200x100+220+200", "-o", cflat]) == 0 and
          oiiotool([sample_exr, "--crop", "200x100+220+200", "--deepen", "-o", cdeep]) == 0,
          "oiiotool crops and deepens the sample")
    check(subprocess.run([make_sample, smap, "--sun-view", "0.2,0.3,-1", "--size", "256x256"],
                         capture_output=True).returncode == 0, "make_sample --sun-view")
    # a spot's perspective map: make_sample's own view from 6 units up, the
    # spot at that camera and aimed along its axis (row vectors: position
    # -t R^T, axis R's third column), so its samples take the dense output
    # with a shadow map's lit pieces
    spmap = os.path.join(tmp, "lit_spotmap.exr")
    check(subprocess.run([make_sample, spmap, "--view", "6,-30,70", "--size", "256x256"],
                         capture_output=True).returncode == 0, "make_sample --view (spot map)")
    wm = oiio.ImageBuf(spmap).spec().getattribute("worldToCamera")
    spos = [-(wm[12] * wm[4 * j] + wm[13] * wm[4 * j + 1] + wm[14] * wm[4 * j + 2]) for j in range(3)]
    saim = [wm[4 * j + 2] for j in range(3)]
    spot_light = ("spot:position=%r,%r,%r:aim=%r,%r,%r:cone=60:blend=0.1:intensity=400:shadow=%s"
                  % tuple(spos + saim + [spmap]))
    # a sky for the sky light's layer: a gradient and a bright lobe
    genv = os.path.join(tmp, "lit_crop_env.exr")
    gy, gx = np.mgrid[0:32, 0:64]
    th, ph = np.pi * (gy + 0.5) / 32, np.pi - 2 * np.pi * (gx + 0.5) / 64
    up = np.cos(th)[..., None]
    lobe = np.exp(-(1 - np.sin(th) * np.cos(ph)) / 0.05)[..., None]
    gimg = (np.where(up > 0, 0.3 + 0.6 * up, 0.05) * np.array([0.6, 0.8, 1.0]) +
            4 * lobe * np.array([1, 0.8, 0.5])).astype(np.float32)
    gb = oiio.ImageBuf(oiio.ImageSpec(64, 32, 3, oiio.FLOAT))
    gb.set_pixels(oiio.ROI(0, 64, 0, 32, 0, 1, 0, 3), gimg)
    check(gb.write(genv), "gradient environment written")
    # a spot's multiple scattering is read along the quadrature a shadow map
    # cuts, which would shadow it with the single scattering: refused, with
    # the way out, and nothing written
    refused = os.path.join(tmp, "lit_spot_ms_shadow.exr")
    r = subprocess.run([exrfog, cflat, "-o", refused, "--fog", "exp:density=0.05:albedo=0.9",
                        "--light", spot_light + ":scattering=multiple"],
                       capture_output=True, text=True)
    check(r.returncode == 2 and "a spot's multiple scattering is read along the quadrature a "
          "shadow map cuts" in r.stderr and "scattering=single" in r.stderr and
          not os.path.exists(refused),
          "a spot's multiple scattering with a shadow map is refused (%d: %s)"
          % (r.returncode, r.stderr.strip()))
    for what, lit in (("sun with a shadow map", ["--light", "sun:towards=0.2,0.3,-1:intensity=3:shadow=" + smap]),
                      ("sun with penumbrae", ["--light", "sun:towards=0.2,0.3,-1:intensity=3:angle=6:"
                                              "penumbra=8:shadow=" + smap]),
                      ("lamp", ["--light", "point:position=1,2,-9:intensity=40"]),
                      ("spot with a shadow map", ["--light", spot_light]),
                      ("lamp and sky light", ["--light", "point:position=1,2,-9:intensity=40",
                                              "--sky-light", genv]),
                      ("sky light alone", ["--sky-light", genv])):
        fogl = ["--fog", "height:density=0.05:falloff=0.3:base=0:phase=hg:g=0.6"] + lit
        if what.startswith(("lamp", "sky")):
            fogl[1] = "exp:density=0.05:phase=hg:g=0.5"
        o_flat = os.path.join(tmp, "lit_crop_flat.exr")
        o_df = os.path.join(tmp, "lit_crop_df.exr")
        o_ds = os.path.join(tmp, "lit_crop_ds.exr")
        o_dsf = os.path.join(tmp, "lit_crop_dsf.exr")
        ok = (run([cflat, "-o", o_flat, "-d", "float"] + fogl) == 0 and
              run([cdeep, "-o", o_df, "--deep", "flatten"] + fogl) == 0 and
              run([cdeep, "-o", o_ds, "--deep", "samples"] + fogl) == 0 and
              oiiotool([o_ds, "--flatten", "-o", o_dsf]) == 0)
        check(ok, "lit crop (%s): flat and deep runs" % what)
        if ok:
            want = flat_pixels_any(o_flat)
            if what == "sun with a shadow map":
                hard_flat = want
            elif what == "sun with penumbrae":
                # (the crop's rays do cross penumbrae: else this proves nothing)
                moved = sum(1 for ra, rb in zip(want, hard_flat) for u, v in zip(ra, rb)
                            if abs(u - v) > 1e-4)
                print("lit crop, sun with penumbrae: %d values differ from the hard shadow's"
                      % moved)
                check(moved > 50, "lit crop: the penumbrae change the crop (%d values)" % moved)
            for name, path in (("--deep flatten", o_df), ("--deep samples + OIIO flatten", o_dsf)):
                got = flat_pixels_any(path)
                e = max(abs(u - v) / (1e-3 + abs(v)) for ra, rb in zip(got, want)
                        for u, v in zip(ra, rb))
                print("lit crop, %s: %s against the flat run, worst %.2e" % (what, name, e))
                check(e <= 1e-6, "lit crop (%s): %s equals the flat run (%.2e)" % (what, name, e))
        # the light layers and lit fractions of --deep flatten: at one opaque
        # sample a pixel, the flat run's (held to the references in
        # test_light and test_shadow)
        aovs = ["--aov", "fog,light" + (",lit" if what.startswith("sun") else ""), "-d",
                "float"]
        a_flat, a_deep = os.path.join(tmp, "lit_crop_aovf.exr"), os.path.join(tmp, "lit_crop_aovd.exr")
        ok = (run([cflat, "-o", a_flat] + fogl + aovs) == 0 and
              run([cdeep, "-o", a_deep, "--deep", "flatten"] + fogl + aovs) == 0)
        check(ok, "lit crop (%s): --aov light,lit runs, flat and deep" % what)
        if ok:
            # (past the image cache: these two paths are rewritten for every
            # light case, within a second on a fast build)
            na, pa = read_flat(a_flat)
            nb, pb = read_flat(a_deep)
            names = [c for c in na if c.startswith(("fog_light.", "fog_lit.", "fog_ambient."))]
            check(len(names) >= 6 and all(c in nb for c in names) and
                  ("sky" not in what or "fog_light.sky.R" in names),
                  "lit crop (%s): the deep run writes the flat run's layers (%s)" % (what, names))
            e = max(float(abs(pa[..., na.index(c)] - pb[..., nb.index(c)]).max()) for c in names
                    if c in nb)
            print("lit crop, %s: --deep flatten's %d light channels against the flat run's, "
                  "worst %.2e" % (what, len(names), e))
            check(e <= 1e-6, "lit crop (%s): deep light layers equal the flat run's (%.2e)"
                  % (what, e))
    # Lit noise fog on deep input (a 40 x 20 crop: a few ms a pixel): the
    # flatten's one fog piece per pixel is the flat run's ray (the same
    # pixels), and --deep samples cuts the fog into samples whose light is
    # integrated over each on its own, at the noise's tolerance (2^-12 of
    # the light; the pixel within 2e-4 of it).
    nflat, ndeep = os.path.join(tmp, "noise_crop.exr"), os.path.join(tmp, "noise_crop_deep.exr")
    check(oiiotool([sample_exr, "--crop", "40x20+300+250", "-o", nflat]) == 0 and
          oiiotool([sample_exr, "--crop", "40x20+300+250", "--deepen", "-o", ndeep]) == 0,
          "oiiotool crops and deepens the sample (noise)")
    fogn = ["--fog", "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0",
            "--light", "sun:towards=0.3,0.4,-1:intensity=3"]
    o_flat, o_df = os.path.join(tmp, "noise_flat.exr"), os.path.join(tmp, "noise_df.exr")
    o_ds, o_dsf = os.path.join(tmp, "noise_ds.exr"), os.path.join(tmp, "noise_dsf.exr")
    ok = (run([nflat, "-o", o_flat, "-d", "float"] + fogn) == 0 and
          run([ndeep, "-o", o_df, "--deep", "flatten"] + fogn) == 0 and
          run([ndeep, "-o", o_ds, "--deep", "samples"] + fogn) == 0 and
          oiiotool([o_ds, "--flatten", "-o", o_dsf]) == 0)
    check(ok, "lit noise crop: flat and deep runs")
    if ok:
        want = flat_pixels_any(o_flat)
        for name, path, lim in (("--deep flatten", o_df, 1e-6),
                                ("--deep samples + OIIO flatten", o_dsf, 2e-4)):
            got = flat_pixels_any(path)
            e = max(abs(u - v) / (1e-3 + abs(v)) for ra, rb in zip(got, want)
                    for u, v in zip(ra, rb))
            print("lit noise crop: %s against the flat run, worst %.2e" % (name, e))
            check(e <= lim, "lit noise crop: %s within %.0e of the flat run (%.2e)"
                  % (name, lim, e))
else:
    print("no sample or make_sample: the lit crop skipped")

# The sky light on deep input: a constant environment K scatters K albedo
# per unit alpha into every fog sample whatever the phase (the phase
# integrates to 1), so --sky-light of it must equal fog whose colour is the
# default plus K (half outputs: the same halves, or one ulp apart).
env = os.path.join(tmp, "deep_env.exr")
K = (0.2, 0.3, 0.4)
eb = oiio.ImageBuf(oiio.ImageSpec(64, 32, 3, oiio.FLOAT))
oiio.ImageBufAlgo.fill(eb, K)
check(eb.write(env), "constant environment written")
sky_a = os.path.join(tmp, "deep_sky_a.exr")
sky_b = os.path.join(tmp, "deep_sky_b.exr")
check(run([src, "--fog", "exp:density=0.05:phase=hg:g=0.7", "--sky-light", env, "--deep",
           "flatten", "-o", sky_a]) == 0, "deep --sky-light runs")
check(run([src, "--fog", "exp:density=0.05:color=%s" %
           ",".join(repr(FOG_COLOR[i] + K[i]) for i in range(3)), "--deep", "flatten",
           "-o", sky_b]) == 0, "deep with the sky's colour runs")
pa, pb = flat_pixels(sky_a), flat_pixels(sky_b)
dsky = max(abs(u - v) / (1e-3 + abs(v)) for ra, rb in zip(pa, pb) for u, v in zip(ra, rb))
print("deep sky light: constant environment against its colour, worst %.2e" % dsky)
check(dsky <= 2 ** -10, "deep sky light equals the colour it adds (%.2e)" % dsky)

# Deep tiled input (RenderMan writes it by default): the same file tiled by
# OpenImageIO (tiles of 32 x 32, and 64 x 20 whose height is not a chunk's)
# gives exactly the scanline input's results, flat and deep.
# (OpenImageIO writes float channels either way: the reference is its
# scanline copy, so both inputs hold the same values.)
ref_flat = os.path.join(tmp, "tile_ref_flat.exr")
ref_deep = os.path.join(tmp, "tile_ref_deep.exr")
scan = os.path.join(tmp, "tile_ref_scan.exr")
check(oiiotool([src, "-o", scan]) == 0, "oiiotool copies the deep file")
check(run([scan, "--fog", "height:density=0.4:falloff=0.5:base=-1", "--deep", "flatten",
           "-o", ref_flat]) == 0 and
      run([scan, "--fog", "height:density=0.4:falloff=0.5:base=-1", "-o", ref_deep]) == 0,
      "scanline runs for the tiled comparison")
for tw, th in ((32, 32), (64, 20)):
    tiled = os.path.join(tmp, "tiled_%dx%d.exr" % (tw, th))
    check(oiiotool([src, "--tile", str(tw), str(th), "-o", tiled]) == 0, "oiiotool tiles the deep file")
    tf, td = tiled + ".flat.exr", tiled + ".deep.exr"
    check(run([tiled, "--fog", "height:density=0.4:falloff=0.5:base=-1", "--deep", "flatten",
               "-o", tf]) == 0 and
          run([tiled, "--fog", "height:density=0.4:falloff=0.5:base=-1", "-o", td]) == 0,
          "tiled %dx%d input runs" % (tw, th))
    same_flat = flat_pixels_any(tf) == flat_pixels_any(ref_flat)
    a, b = samples_of(oiio.ImageBuf(td)), samples_of(oiio.ImageBuf(ref_deep))
    print("deep tiled %dx%d: flat %s, deep samples %s" % (tw, th, "identical" if same_flat else "DIFFER",
                                                      "identical" if a == b else "DIFFER"))
    check(same_flat and a == b, "tiled %dx%d = scanline, flat and deep" % (tw, th))

# Usage: what deep input does not take is refused (exit 2), never ignored.
flat = os.path.join(shared, "real-exr", "arnold-representative-flat.exr")
for args, want in (([src, "--deep", "bogus"], 2), ([src, "--deep-tol", "0"], 2),
                   ([src, "--deep-tol", "1e-17"], 2), ([src, "--deep-tol", "1e-300"], 2),
                   ([src, "--depth", flat], 2),
                   ([src, "--aov", "T"], 2), ([flat, "--deep", "fog"], 2),
                   ([src, "--deep", "samples", "--aov", "light", "--light",
                     "point:position=1,1,3:intensity=1"], 2),
                   ([src, "--deep", "flatten", "--aov", "lit", "--light",
                     "point:position=1,1,3:intensity=1"], 2),
                   ([src, "--deep", "flatten", "--aov", "lit", "--sky-light", env], 2)):
    r = subprocess.run([exrfog] + args + ["--fog", "exp:density=0.1", "-o",
                                          os.path.join(tmp, "u.exr")], capture_output=True, text=True)
    check(r.returncode == want and r.stderr.startswith("exrfog: ") and
          not os.path.exists(os.path.join(tmp, "u.exr")),
          "%s -> exit %d with a message (got %d: %s)" % (args[1:], want, r.returncode, r.stderr.strip()))
# The floor is named (issue 42: 1e-17 and 1e-300 ran past 120 s), and a fine
# tolerance above it is warned with its cost before the work, once.
r = subprocess.run([exrfog, src, "--deep-tol", "1e-17", "--fog", "exp:density=0.1", "-o",
                    os.path.join(tmp, "u.exr")], capture_output=True, text=True)
check("below 1e-09" in r.stderr, "--deep-tol 1e-17 names the floor: %s" % r.stderr.strip())
r = subprocess.run([exrfog, src, "--deep-tol", "1e-7", "--deep", "flatten", "--fog",
                    "exp:density=0.1", "-o", os.path.join(tmp, "tol.exr")],
                   capture_output=True, text=True)
check(r.returncode == 0 and r.stderr.count("warning: --deep-tol 1e-07 asks for about 100 times") == 1,
      "--deep-tol 1e-7 is warned of its cost once: %s" % r.stderr.strip())
# The deep pass's cost is timed on a sample of its pixels before the work
# (issue 42 item 13, a timed prediction): --stats gives it, within a factor
# of 3 of the run's own CPU time (a lamp in height fog, flattened, one
# thread: 0.97 s predicted, 1.01 s taken in Release on an idle machine; a
# test beside it can slow either), and a frame predicted
# past two minutes is warned about at once (noise fog past a lamp: about
# 640 s of one thread), then stopped with nothing written.
before = resource.getrusage(resource.RUSAGE_CHILDREN)
r = subprocess.run([exrfog, src, "--deep", "flatten", "--fog", "height:density=0.05:falloff=0.3",
                    "--light", "point:position=0,3,-20:intensity=50", "--stats", "--threads", "1",
                    "-o", os.path.join(tmp, "pred.exr")], capture_output=True, text=True)
after = resource.getrusage(resource.RUSAGE_CHILDREN)
cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
m = re.search(r"fog predicted before the pass at ([0-9.e+-]+) s", r.stderr)
check(r.returncode == 0 and m and cpu > 0.05 and cpu / 3 < float(m.group(1)) < cpu * 3,
      "deep prediction %s s against %.3f s of CPU" % (m.group(1) if m else None, cpu))
out = os.path.join(tmp, "costly.exr")
if os.path.exists(out):
    os.remove(out)
p = subprocess.Popen([exrfog, src, "--deep", "samples", "--fog", "noise:density=0.05:scale=3:octaves=4",
                      "--light", "point:position=0,3,-20:intensity=50", "--threads", "1", "-o", out],
                     stderr=subprocess.PIPE, text=True)
said = ""
for line in p.stderr:
    said += line
    if "predicted" in line:
        break
p.terminate()
said += p.stderr.read()
p.wait()
check("warning: this deep frame is predicted to take about" in said and
      "lit fog integrates every light" in said and not os.path.exists(out),
      "a costly deep frame is warned about before the work: %s" % said.strip())
# A deep image given as a shadow map is named as such (issue 47: "damaged
# or out of memory" before).
r = subprocess.run([exrfog, flat, "--fog", "height:density=0.05:falloff=0.3", "--light",
                    "sun:towards=0.2,0.3,-1:intensity=3:shadow=" + src, "-o",
                    os.path.join(tmp, "u.exr")], capture_output=True, text=True)
check(r.returncode == 1 and "is a deep image" in r.stderr,
      "a deep shadow map: %d %s" % (r.returncode, r.stderr.strip()))
# --deep flatten writes any format (issue 23's deliverables): a PNG of the
# flattened frame is its EXR encoded by the sRGB formula (straight alpha);
# the deep modes are EXR only.
fe, fp = os.path.join(tmp, "flat_any.exr"), os.path.join(tmp, "flat_any.png")
check(run([src, "-o", fe, "--deep", "flatten", "--fog", "exp:density=0.1"]) == 0 and
      run([src, "-o", fp, "--deep", "flatten", "--fog", "exp:density=0.1"]) == 0,
      "--deep flatten to EXR and to PNG")
pe, pp = oiio.ImageBuf(fe).get_pixels(oiio.FLOAT), oiio.ImageBuf(fp).get_pixels(oiio.FLOAT)
worst = 0
for y in range(len(pe)):
    for x in range(len(pe[y])):
        a = float(pe[y][x][3])
        for k in range(3):
            v = float(pe[y][x][k]) / a if 0 < a < 1 else float(pe[y][x][k])
            v = min(max(v, 0.0), 1.0)
            enc = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
            worst = max(worst, abs(round(float(pp[y][x][k]) * 255) - round(enc * 255)))
check(worst <= 1, "--deep flatten PNG = its EXR sRGB-encoded (worst %d codes)" % worst)
# Unsorted input (issue 24's "messy samples, tidied first"): the Arnold
# frame with every pixel's samples shuffled (OpenImageIO writes it). Its
# --deep flatten equals the sorted file's exactly, and its --deep samples
# output is tidy: OpenImageIO's flatten (which assumes sorted samples, and
# gets the shuffled input itself wrong in most pixels) of it equals that of
# the sorted file's.
mb = oiio.ImageBuf(src)
mspec, mdd = mb.spec(), mb.deepdata()
messy = oiio.ImageBuf(mspec)
rng = random.Random(7)
for p in range(mdd.pixels):
    n = mdd.samples(p)
    order = list(range(n))
    rng.shuffle(order)
    x, y = mspec.x + p % mspec.width, mspec.y + p // mspec.width
    messy.set_deep_samples(x, y, 0, n)
    for s2, s0 in enumerate(order):
        for c in range(mdd.channels):
            messy.set_deep_value(x, y, 0, c, s2, mdd.deep_value(p, c, s0))
mpath = os.path.join(tmp, "messy.exr")
check(messy.write(mpath), "OpenImageIO writes the shuffled deep file")
mf, sfl = os.path.join(tmp, "messy_flat.exr"), os.path.join(tmp, "sorted_flat.exr")
ms, ssm = os.path.join(tmp, "messy_samples.exr"), os.path.join(tmp, "sorted_samples.exr")
for a, b, mode in ((mpath, mf, "flatten"), (src, sfl, "flatten"), (mpath, ms, "samples"),
                   (src, ssm, "samples")):
    check(run([a, "-o", b, "--deep", mode, "--fog", "exp:density=0.1"]) == 0, "%s %s runs" % (a, mode))
check(flat_pixels_any(mf) == flat_pixels_any(sfl), "--deep flatten of shuffled samples = of sorted")
oa, ob = os.path.join(tmp, "messy_samples_flat.exr"), os.path.join(tmp, "sorted_samples_flat.exr")
check(oiiotool([ms, "--flatten", "-o", oa]) == 0 and oiiotool([ssm, "--flatten", "-o", ob]) == 0,
      "oiiotool flattens both")
worst = max(abs(p - q) / max(abs(q), 1e-3) for u, v in zip(flat_pixels_any(oa), flat_pixels_any(ob))
            for p, q in zip(u, v))
check(worst <= 2 ** -10, "--deep samples of shuffled input is tidy (OIIO's flatten agrees within %.2g)"
      % worst)

# Heavily overlapping samples (issue 42 item 12: 6,000 nested volumes a
# pixel took 3.6 GB and 36 s, the split making n^2 pieces). Three pixels of
# the Arnold frame's header hold 200 nested volumes each (one with a point
# sample inside them, one with volumes of alpha 0): --deep flatten and
# OpenImageIO's flatten of --deep samples against the reference (the
# spec's split and merge per boundary interval). 6,000 nested volumes a
# pixel run in seconds; with an id channel (whose first-non-zero rule
# needs the pieces) they are refused before any work with the count, and
# nothing is written.
def nested_file(path, nest, with_id):
    sp = oiio.ImageSpec(mspec)
    names = ["R", "G", "B", "A", "Z", "ZBack"] + (["id"] if with_id else [])
    sp.nchannels = len(names)
    sp.channelnames = tuple(names)
    sp.channelformats = (oiio.HALF,) * 4 + (oiio.FLOAT,) * 2 + ((oiio.UINT,) if with_id else ())
    sp.deep = True
    buf = oiio.ImageBuf(sp)
    smp = {}
    for k, (px, py) in enumerate(((40, 30), (75, 50), (110, 70))):
        lst = []
        for j in range(nest):
            a = 0.0 if k == 2 and j % 3 == 0 else 0.0004 + 0.0002 * (j % 5)
            c = [a * (0.2 + 0.1 * ((j + ch) % 4)) for ch in range(3)] if a > 0 else \
                [0.0005, 0.0002, 0.0001]
            lst.append((4.0 + j * 0.0005, 20.0 + k - j * 0.0005, c + [a]))
        if k == 1:
            lst.append((6.0, 6.0, [0.1, 0.05, 0.02, 0.3]))
        buf.set_deep_samples(px, py, 0, len(lst))
        for j, (z, zb, c) in enumerate(lst):
            for ch, v in enumerate(c + [z, zb]):
                buf.set_deep_value(px, py, 0, ch, j, v)
            if with_id:
                buf.set_deep_value_uint(px, py, 0, 6, j, 7)
        # the reference reads what the file holds: half colours
        smp[(px, py)] = [(z, zb, [float(np.float16(v)) for v in c]) for z, zb, c in lst]
    check(buf.write(path), "OpenImageIO writes the nested deep file")
    return smp


nest_path = os.path.join(tmp, "nested.exr")
nest_smp = nested_file(nest_path, 200, False)
nf_out, ns_out = os.path.join(tmp, "nested_flat.exr"), os.path.join(tmp, "nested_samples.exr")
ok = run([nest_path, "-o", nf_out, "--deep", "flatten", "-d", "float", "--fog", "exp:density=0.02"]) == 0
ok &= run([nest_path, "-o", ns_out, "--deep", "samples", "-d", "float", "--fog", "exp:density=0.02"]) == 0
check(ok, "200 nested volumes a pixel: --deep flatten and samples run")
nsf = os.path.join(tmp, "nested_samples_flat.exr")
check(oiiotool([ns_out, "--flatten", "-o", nsf]) == 0, "oiiotool flattens the nested samples")
if ok:
    fa, fb = flat_pixels_any(nf_out), flat_pixels_any(nsf)
    worst = 0.0
    for (px, py), lst in nest_smp.items():
        ref = reference(("exp", 0.02), px, py, lst)
        p = py * W + px
        for got in (fa[p], fb[p]):
            for ch in range(4):
                worst = max(worst, abs(got[ch] - ref[ch]) / max(abs(ref[ch]), 1e-3))
    print("nested volumes (200 a pixel): worst relative difference from the reference %.2e"
          % worst)
    check(worst <= 1e-4, "nested volumes against the reference (%.2e)" % worst)
big = os.path.join(tmp, "nested6000.exr")
nested_file(big, 6000, False)
for mode in ("flatten", "fog", "samples"):
    t0 = time.time()
    ok = run([big, "-o", os.path.join(tmp, "nested6000_%s.exr" % mode), "--deep", mode,
              "--fog", "exp:density=0.02"]) == 0
    check(ok and time.time() - t0 < 20, "6,000 nested volumes a pixel: --deep %s in %.1f s"
          % (mode, time.time() - t0))
nid_path, nid_out = os.path.join(tmp, "nested_id.exr"), os.path.join(tmp, "nested_id_out.exr")
nested_file(nid_path, 6000, True)
t0 = time.time()
r = subprocess.run([exrfog, nid_path, "-o", nid_out, "--deep", "flatten", "--fog", "exp:density=0.02"],
                   capture_output=True, text=True)
m = re.search(r"make (\d+) pieces", r.stderr)
check(r.returncode == 1 and m and int(m.group(1)) >= 36000000 and "overlap" in r.stderr and
      not os.path.exists(nid_out) and time.time() - t0 < 10,
      "6,000 nested volumes with an id channel: refused up front with the count (%s)"
      % r.stderr.strip())

# Deep tiles past exrfog's 4096 (legal in OpenEXR): refused with that
# limit and a way out, not as "an invalid tile size" (issue 47).
big_tiles = os.path.join(tmp, "tiles4097.exr")
tsp = oiio.ImageSpec(4100, 10, 5, "half")
tsp.channelnames = ("R", "G", "B", "A", "Z")
tsp.channelformats = (oiio.HALF,) * 4 + (oiio.FLOAT,)
tsp.deep = True
tsp.tile_width = tsp.tile_height = 4097
tdd = oiio.DeepData()
tdd.init(4100 * 10, 5, tsp.channelformats, tsp.channelnames)
tout = oiio.ImageOutput.create(big_tiles)
check(tout.open(big_tiles, tsp) and tout.write_deep_image(tdd) and tout.close(),
      "OpenImageIO writes deep tiles of 4097^2")
r = subprocess.run([exrfog, big_tiles, "-o", os.path.join(tmp, "tiles4097_out.exr"), "--deep",
                    "flatten", "--fog", "exp:density=0.1", "--fov", "50", "--world-to-camera",
                    "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1"], capture_output=True, text=True)
check(r.returncode == 1 and "tiles of 4097 x 4097" in r.stderr and "at most 4096" in r.stderr,
      "deep tiles of 4097^2: the limit named (%s)" % r.stderr.strip())

# Non-numbers in a deep sample (issue 47): an alpha of +inf made the
# flattened pixel NaN with exit 0, and a ZBack of NaN was reported by its
# valid Z. Each is refused (exit 1) naming the channel, with no output.
bad_src = oiio.ImageBuf(src)
for chan, val, want in (("A", float("inf"), "whose A is inf"),
                        ("ZBack", float("nan"), "whose ZBack is nan")):
    bb = oiio.ImageBuf()
    bb.copy(bad_src)
    bsp, bdd = bb.spec(), bb.deepdata()
    bp = next(p for p in range(bdd.pixels) if bdd.samples(p) > 0)
    bx, by = bsp.x + bp % bsp.width, bsp.y + bp // bsp.width
    bb.set_deep_value(bx, by, 0, bsp.channelnames.index(chan), 0, val)
    bpath, bout = os.path.join(tmp, "bad_%s.exr" % chan), os.path.join(tmp, "bad_%s_out.exr" % chan)
    check(bb.write(bpath), "OpenImageIO writes a deep file with %s = %g" % (chan, val))
    for mode in ("flatten", "samples"):
        r = subprocess.run([exrfog, bpath, "-o", bout, "--deep", mode, "--fog", "exp:density=0.1"],
                           capture_output=True, text=True)
        check(r.returncode == 1 and want in r.stderr and ("pixel (%d, %d)" % (bx, by)) in r.stderr
              and not os.path.exists(bout),
              "a deep sample with %s = %g is refused, named (--deep %s: %s)"
              % (chan, val, mode, r.stderr.strip()))

# A flat frame in a deep sequence (issue 47): it stopped the sequence as a
# usage error (exit 2) even under --keep-going. It is that frame's failure:
# --keep-going writes the others and exits 1 naming it.
seqd = os.path.join(tmp, "mixseq")
os.makedirs(seqd, exist_ok=True)
for f in os.listdir(seqd):
    os.remove(os.path.join(seqd, f))
shutil.copy(src, os.path.join(seqd, "in.0001.exr"))
check(oiiotool([src, "--flatten", "-o", os.path.join(seqd, "in.0002.exr")]) == 0, "flat frame made")
shutil.copy(src, os.path.join(seqd, "in.0003.exr"))
r = subprocess.run([exrfog, os.path.join(seqd, "in.#.exr"), "-o", os.path.join(seqd, "out.#.exr"),
                    "--frames", "1-3", "--deep", "flatten", "--fog", "exp:density=0.1",
                    "--keep-going"], capture_output=True, text=True)
outs_seq = sorted(f for f in os.listdir(seqd) if f.startswith("out."))
check(r.returncode == 1 and outs_seq == ["out.0001.exr", "out.0003.exr"] and
      "this frame is flat" in r.stderr and "frames failed: 2" in r.stderr,
      "a flat frame in a deep sequence fails alone under --keep-going (%d, %s, %s)"
      % (r.returncode, outs_seq, r.stderr.strip()))

# -d on deep input as on flat: --deep flatten -d float writes float colour
# (the half flatten's values to half precision), -d half never demotes Z,
# NAME=TYPE overrides win, and the deep modes take it too.
ff = os.path.join(tmp, "flat_float.exr")
check(run([src, "-o", ff, "--deep", "flatten", "-d", "float", "--fog", "exp:density=0.1"]) == 0,
      "--deep flatten -d float runs")
sf = oiio.ImageBuf(ff).spec()
check(all(str(sf.channelformat(i)) == "float" for i in range(sf.nchannels)),
      "--deep flatten -d float: every channel float")
pf = oiio.ImageBuf(ff).get_pixels(oiio.FLOAT)
worst = max(abs(float(pf[y][x][k]) - float(pe[y][x][k])) / max(abs(float(pf[y][x][k])), 1e-3)
            for y in range(len(pf)) for x in range(len(pf[y])) for k in range(4))
check(worst <= 2 ** -10, "--deep flatten -d float = the half flatten to half precision (%.2g)" % worst)
sd = os.path.join(tmp, "samples_types.exr")
check(run([src, "-o", sd, "--deep", "samples", "-d", "half", "-d", "A=float",
           "--fog", "exp:density=0.1"]) == 0, "--deep samples -d half -d A=float runs")
ss = oiio.ImageInput.open(sd).spec()
types = {ss.channelnames[i]: str(ss.channelformat(i)) for i in range(ss.nchannels)}
check(types.get("R") == "half" and types.get("A") == "float" and types.get("Z") == "float" and
      types.get("ZBack") == "float", "--deep samples -d half -d A=float: %s" % types)
r = subprocess.run([exrfog, src, "-o", os.path.join(tmp, "u.png"), "--fog", "exp:density=0.1"],
                   capture_output=True, text=True)
check(r.returncode == 2 and "deep output is EXR" in r.stderr, "deep samples to PNG refused")
r = subprocess.run([exrfog, src, "--fog", "exp:density=0.1", "--explain"], capture_output=True, text=True)
tot, mx = sum(len(v) for v in input_samples), max(len(v) for v in input_samples)
check(r.returncode == 0 and ("deep scanline: %d samples over %d pixels" % (tot, W * H)) in r.stdout
      and ("at most %d per pixel" % mx) in r.stdout,
      "--explain states the deep samples as OpenImageIO counts them (%d, max %d)" % (tot, mx))

# The merge property on Weta's deep elements (no camera: given by flags):
# merge the three, make one fog element from the merge, deep-merge it back
# and flatten (OpenImageIO); it must equal --deep flatten of the merge.
weta = os.path.join(shared, "real-exr", "openexr-images", "v2", "LowResLeftView")
if os.path.isdir(weta):
    cam = ["--fov", "50", "--world-to-camera", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1"]
    merged = os.path.join(tmp, "weta_merge.exr")
    merged6 = os.path.join(tmp, "weta_merge6.exr")
    fog = os.path.join(tmp, "weta_fog.exr")
    flat = os.path.join(tmp, "weta_flat.exr")
    back = os.path.join(tmp, "weta_back.exr")
    e = [os.path.join(weta, n + ".exr") for n in ("Balls", "Leaves", "Trunks")]
    check(oiiotool([e[0], e[1], "--deepmerge", e[2], "--deepmerge", "-o", merged]) == 0,
          "oiiotool merges the Weta elements")
    for mode, out in (("fog", fog), ("flatten", flat)):
        check(run([merged, "--fog", "height:density=0.05:falloff=0.2:base=0", "--deep", mode,
                   "-o", out] + cam) == 0, "Weta merge --deep %s runs" % mode)
    # OIIO merges images with equal channel lists: ZBack = Z (point samples)
    check(oiiotool([merged, "--ch", "R,G,B,A,Z,ZBack=Z", "-o", merged6]) == 0, "ZBack added")
    check(oiiotool([merged6, fog, "--deepmerge", "--flatten", "-o", back]) == 0,
          "the fog element deep-merges back")
    a, b = flat_pixels_any(flat), flat_pixels_any(back)
    worst = max(abs(x - y) for pa, pb in zip(a, b) for x, y in zip(pa, pb))
    print("Weta merge property: largest difference %.2e over %d pixels" % (worst, len(a)))
    check(len(a) == len(b) and worst <= 2e-3, "Weta: fog element merged back = --deep flatten")
    # Every model, deep against flat: where a pixel holds one point sample,
    # the deep composite (fog in front, the sample, fog behind what it does
    # not cover) is algebraically the flat path's premultiplied composite
    # (T c + (1 - T) a F + (1 - a)(1 - Tinf) F), so --deep flatten of the
    # element must give what exrfog's flat path gives on OIIO's flatten of
    # it, model by model (noise: each within its own tolerance).
    balls = e[0]
    bflat = os.path.join(tmp, "balls_flat.exr")
    check(oiiotool([balls, "--flatten", "-o", bflat]) == 0, "oiiotool flattens Balls")
    bs = samples_of(oiio.ImageBuf(balls))
    bspec = oiio.ImageBuf(balls).spec()
    single = [i for i, v in enumerate(bs) if len(v) == 1]
    for spec_text in ("exp:density=0.02", "height:density=0.08:falloff=0.3:base=-2",
                      "layered:heights=-5,0,5:densities=0.1,0.04,0.01",
                      "box:min=-40,-20,-300:max=40,10,-50:density=0.03",
                      "halfspace:plane=0,1,0,2:density=0.05",
                      "noise:density=0.03:scale=20:octaves=3",
                      "exp:density=0.01,0.02,0.04"):
        dflat = os.path.join(tmp, "balls_deep_flat.exr")
        fflat = os.path.join(tmp, "balls_flat_fog.exr")
        aovs = ["--aov", "fog,T,error,distance"]
        ok = run([balls, "--fog", spec_text, "--deep", "flatten", "-o", dflat] + aovs + cam) == 0
        ok &= run([bflat, "--fog", spec_text, "-o", fflat] + aovs + cam) == 0
        check(ok, "Balls, %s: both paths run" % spec_text)
        if not ok:
            continue
        a, b = flat_pixels_any(dflat), flat_pixels_any(fflat)
        worst = 0.0
        for i in single:
            for ch in range(4):
                worst = max(worst, abs(a[i][ch] - b[i][ch]) / (1e-3 + abs(b[i][ch])))
        print("Balls, %s: deep vs flat at %d one-sample pixels: worst relative %.2e"
              % (spec_text, len(single), worst))
        check(worst <= 2e-3, "Balls, %s: deep flatten = flat path (%.2e)" % (spec_text, worst))
        # --aov: at one opaque point sample the deep AOVs are the flat ones
        # (fog, T, the error estimate, the distance)
        ba, bb = oiio.ImageBuf(dflat), oiio.ImageBuf(fflat)
        ca, cb = ba.spec().channelnames, bb.spec().channelnames
        pa, pb = ba.get_pixels(oiio.FLOAT), bb.get_pixels(oiio.FLOAT)
        names = ["fog.R", "fog.G", "fog.B", "fog.A", "fog_T.R", "fog_T.G", "fog_T.B",
                 "fog_error.R", "fog_distance.Z"]
        if not all(c in ca and c in cb for c in names):
            check(False, "Balls, %s: AOV channels in both outputs" % spec_text)
            continue
        wa = bspec.width
        worst_aov, nop, err_seen = 0.0, 0, 0.0
        for i in single:
            if bs[i][0][2][3] < 1:
                continue
            y, x = divmod(i, wa)
            va, vb = pa[y][x], pb[y][x]
            for c in names:
                u, v = va[ca.index(c)], vb[cb.index(c)]
                worst_aov = max(worst_aov, abs(u - v) / (1e-6 + abs(v)))
            err_seen = max(err_seen, va[ca.index("fog_error.R")])
            nop += 1
        print("Balls, %s: deep vs flat AOVs at %d opaque one-sample pixels: worst relative %.2e"
              "%s" % (spec_text, nop, worst_aov,
                      ", largest fog_error %.2e" % err_seen if "noise" in spec_text else ""))
        check(nop > 1000 and worst_aov <= 1e-5,
              "Balls, %s: deep flatten AOVs = flat AOVs (%.2e)" % (spec_text, worst_aov))
        if "noise" in spec_text:
            check(err_seen > 0, "Balls, noise: fog_error reports the noise's estimate")
else:
    print("no Weta elements: merge property skipped")

if failures:
    print(len(failures), "failure(s)")
    sys.exit(1)
print("deep_check: all passed")
