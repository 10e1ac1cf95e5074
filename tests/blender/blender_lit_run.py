"""ctest blender_lit: lit fog against Blender Cycles. Renders
tests/blender/blender_lit.py's scene without fog (with depth), and with the fog
box with the sun on and off; runs exrfog on the fog-free render with the
same camera, fog and sun, and with the sun off. Cycles lets the emissive
surfaces light its fog too (exrfog's lights are only --light), so the
comparison is of what the sun adds: Cycles(sun) - Cycles(no sun) against
exrfog(lit) - exrfog(unlit), up to Cycles' own noise (256 samples per
pixel). Then the same with shafts: the ball casts shadows in Cycles, and
exrfog reads them from Cycles' own depth render of the scene along the
sunlight (an orthographic second camera; its matrices written into the
map's header here, as a renderer that exports its camera would). Exits 77
(skipped) without Blender. A spot (cosine=1: Cycles 3.x's spots fall as
cos alpha inside the cone) whose shadow map is Cycles' own perspective
depth render from the spot. And a point lamp, its radiant intensity read
off Cycles' render of a white Lambertian plane (Blender's watts are not
W/sr: the plane measures the factor), compared the same way."""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

exrfog = os.environ["EXRFOG_BIN"]
src = os.environ["EXRFOG_SOURCE_DIR"]
blender = shutil.which("blender")
if not blender:
    print("blender_lit: Blender is not installed (skipped)")
    sys.exit(77)
import numpy as np
import OpenImageIO as oiio


def run(args, env=None):
    r = subprocess.run(args, capture_output=True, text=True, env=env)
    if r.returncode:
        print(r.stdout[-3000:], r.stderr[-3000:], file=sys.stderr)
        raise SystemExit("blender_lit: FAILED: " + " ".join(args[:4]))
    return r


def write_map(src, dst, cam, c2n):
    """Cycles' depth render src with its camera (cam: Blender's camera to
    world) written into dst's header in OpenEXR's convention (row vectors,
    +Z forward: Blender's camera looks down its -Z), worldToNDC = worldToCamera
    times c2n: what a renderer that exports its camera writes."""
    B = np.array(cam["c2w"]).reshape(4, 4)
    c2w = np.zeros((4, 4))
    c2w[0, :3], c2w[1, :3], c2w[2, :3], c2w[3, :3] = B[:3, 0], B[:3, 1], -B[:3, 2], B[:3, 3]
    c2w[3, 3] = 1
    w2c = np.linalg.inv(c2w)
    buf = oiio.ImageBuf(src)
    spec = buf.spec()
    z = buf.get_pixels(oiio.FLOAT)[..., spec.channelindex("Z")].copy()
    out = oiio.ImageSpec(spec.width, spec.height, 1, oiio.FLOAT)
    out.channelnames = ("Z",)
    out.attribute("worldToCamera", oiio.TypeDesc("matrix"), tuple(w2c.flatten()))
    out.attribute("worldToNDC", oiio.TypeDesc("matrix"), tuple((w2c @ c2n).flatten()))
    mb = oiio.ImageBuf(out)
    mb.set_pixels(oiio.ROI(0, spec.width, 0, spec.height, 0, 1, 0, 1), z[..., None])
    if not mb.write(dst):
        raise SystemExit("blender_lit: FAILED: cannot write the map: " + mb.geterror())


def rgb(path):
    return oiio.ImageBuf(path).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


said = {}


def operator_light(name):
    """The --light SPEC the add-on's "Render shadow map" gave in run name,
    after checking it wrote the map, its camera file and the SPEC into
    Extra options."""
    out = said[name]
    light = [l[len("blender_lit: light "):] for l in out.splitlines()
             if l.startswith("blender_lit: light ")]
    extra = [l for l in out.splitlines() if l.startswith("blender_lit: extra ")]
    if "FINISHED" not in out or not light or not extra or light[0] not in extra[0]:
        raise SystemExit("blender_lit: FAILED: the shadow map operator in %s: %s" % (name, out[-2000:]))
    m = re.search(r":shadow=([^:]+):shadow-camera=([^:]+)$", light[0])
    if not m or not os.path.exists(m.group(1)) or not os.path.exists(m.group(2)):
        raise SystemExit("blender_lit: FAILED: the operator's map or camera file: " + light[0])
    return light[0]


with tempfile.TemporaryDirectory() as d:
    env = dict(os.environ, BLENDER_USER_CONFIG=d + "/cfg", BLENDER_USER_SCRIPTS=d + "/scripts")
    scene = os.path.join(src, "tests", "blender", "blender_lit.py")
    for name, mode, spp, sun, extra in (("plain", "plain", 4, 3, ""), ("lit", "fog", 256, 3, ""),
                                        ("dark", "fog", 256, 0, ""),
                                        ("plainS", "plain", 4, 3, "shadow"),
                                        ("shafts", "fog", 256, 3, "shadow"),
                                        ("softS", "fog", 256, 3, "shadow soft"),
                                        ("darkS", "fog", 256, 0, "shadow"),
                                        ("sunmap", "sunmap", 1, 3, "shadow"),
                                        ("lampfog", "fog", 256, 300, "lamp"),
                                        ("calib", "plain", 16, 300, "calib"),
                                        ("spotfog", "fog", 256, 40000, "spot shadow"),
                                        ("spotmap", "spotmap", 1, 40000, "shadow"),
                                        ("opsun", "opmap", 1, 3, "shadow"),
                                        ("opspot", "opmap", 1, 40000, "spot shadow")):
        r = run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python", scene,
                 "--", "%s/%s.exr" % (d, name), mode, str(spp), str(sun)] + extra.split(),
                env)
        if "blender_lit: rendered" not in r.stdout:
            raise SystemExit("blender_lit: FAILED: Blender did not render " + name)
        said[name] = r.stdout
    cam = json.load(open(d + "/plain.exr.json"))
    common = ["--camera-convention", "blender", "--camera-to-world",
              ",".join(repr(v) for v in cam["c2w"]), "--fov", repr(cam["fov"]),
              "--near", repr(cam["near"]), "--far", repr(cam["far"]), "--fog-color", "0,0,0",
              "--fog", "box:min=-30,-30,-1:max=30,30,6:density=0.08:albedo=0.75:phase=hg:g=0.5"]
    run([exrfog, d + "/plain.exr", "-o", d + "/ef_lit.exr", "--light",
         "sun:towards=%r,%r,%r:intensity=3" % tuple(cam["towards"])] + common)
    run([exrfog, d + "/plain.exr", "-o", d + "/ef_dark.exr"] + common)
    cyc = rgb(d + "/lit.exr") - rgb(d + "/dark.exr")
    ef = rgb(d + "/ef_lit.exr") - rgb(d + "/ef_dark.exr")
    diff = cyc - ef
    mean_rel = (cyc.mean() - ef.mean()) / ef.mean()
    rows = np.abs(cyc.mean(axis=(1, 2)) - ef.mean(axis=(1, 2))) / ef.mean(axis=(1, 2))
    print("blender_lit: the sun's light: Cycles mean %.5f, exrfog %.5f (%+.2f %%); row means "
          "within %.2f %%; per pixel |diff| mean %.5f, p99.9 %.5f"
          % (cyc.mean(), ef.mean(), 100 * mean_rel, 100 * rows.max(), np.abs(diff).mean(),
             np.percentile(np.abs(diff), 99.9)))
    if not (abs(mean_rel) < 0.01 and rows.max() < 0.03):
        raise SystemExit("blender_lit: FAILED: exrfog's sun light differs from Cycles'")
    if not ef.mean() > 0.05:
        raise SystemExit("blender_lit: FAILED: the sun added almost nothing")
    # shafts: the sun's map of the scene (orthographic, NDC y down)
    sm = json.load(open(d + "/sunmap.exr.json"))
    s = 1.0 / sm["ortho_scale"]
    write_map(d + "/sunmap.exr", d + "/map.exr", sm,
              np.array([[s, 0, 0, 0], [0, -s, 0, 0], [0, 0, 1e-3, 0], [0.5, 0.5, 0, 1]]))
    camS = json.load(open(d + "/plainS.exr.json"))
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_shafts.exr", "--light",
         "sun:towards=%r,%r,%r:intensity=3:shadow=%s/map.exr" % (tuple(camS["towards"]) + (d,))]
        + common)
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_darkS.exr"] + common)
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_unshadowed.exr", "--light",
         "sun:towards=%r,%r,%r:intensity=3" % tuple(camS["towards"])] + common)
    cyc_s = rgb(d + "/shafts.exr") - rgb(d + "/darkS.exr")
    ef_s = rgb(d + "/ef_shafts.exr") - rgb(d + "/ef_darkS.exr")
    ef_u = rgb(d + "/ef_unshadowed.exr") - rgb(d + "/ef_darkS.exr")
    diff = cyc_s - ef_s
    mean_rel = (cyc_s.mean() - ef_s.mean()) / ef_s.mean()
    rows = np.abs(cyc_s.mean(axis=(1, 2)) - ef_s.mean(axis=(1, 2))) / ef_s.mean(axis=(1, 2))
    shade = 1 - ef_s.mean() / ef_u.mean()
    print("blender_lit: with the ball's shafts: Cycles mean %.5f, exrfog %.5f (%+.2f %%); row "
          "means within %.2f %%; per pixel |diff| mean %.5f, p99.9 %.5f; the shadow takes "
          "%.1f %% of the sun's light" % (cyc_s.mean(), ef_s.mean(), 100 * mean_rel,
                                          100 * rows.max(), np.abs(diff).mean(),
                                          np.percentile(np.abs(diff), 99.9), 100 * shade))
    if not (abs(mean_rel) < 0.01 and rows.max() < 0.03):
        raise SystemExit("blender_lit: FAILED: exrfog's shafts differ from Cycles'")
    if not shade > 0.02:
        raise SystemExit("blender_lit: FAILED: the ball's shadow took almost nothing")
    # The add-on's one-step sun map (issue 42 item 4): Cycles' depth from an
    # orthographic camera back along the sunlight, its camera in a camera
    # file (no header matrices), read by shadow-camera=. Its camera is the
    # test's own map's (the sun moved to that centre, the same width, size
    # and distance): the shafts come out as the header-stamped map's.
    op_sun = operator_light("opsun")
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_opsun.exr", "--light", op_sun] + common)
    ef_o = rgb(d + "/ef_opsun.exr") - rgb(d + "/ef_darkS.exr")
    op_rel = (ef_o.mean() - ef_s.mean()) / ef_s.mean()
    print("blender_lit: the add-on's sun map (%s): the shafts' mean %+.4f %% from the "
          "header-stamped map's, largest |diff| %.2e (of %.3f)"
          % (op_sun, 100 * op_rel, np.abs(ef_o - ef_s).max(), ef_s.max()))
    if not (abs(op_rel) < 1e-3 and np.abs(ef_o - ef_s).max() < 0.01 * ef_s.max()):
        raise SystemExit("blender_lit: FAILED: the add-on's sun map gives other shafts")
    # penumbrae: Cycles' sun 3 degrees wide against angle=3 (32 directions,
    # filtered), as a whole and in what the penumbra changes from the hard
    # shadow, after a 7 x 7 box blur (Cycles' noise), where the soft and hard
    # exrfog differ by more than a quarter of their largest difference. The
    # map holds the wall's face only (thin plates), so the gap's sides block
    # less of the disc than Cycles' solid wall: a residual, not a match.
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_soft.exr", "--light",
         "sun:towards=%r,%r,%r:intensity=3:angle=3:penumbra=32:shadow=%s/map.exr"
         % (tuple(camS["towards"]) + (d,))] + common)
    cyc_p = rgb(d + "/softS.exr") - rgb(d + "/darkS.exr")
    ef_p = rgb(d + "/ef_soft.exr") - rgb(d + "/ef_darkS.exr")

    def blur(a, r=3):
        c = np.cumsum(np.cumsum(np.pad(a.sum(axis=2), ((r + 1, r), (r + 1, r))), 0), 1)
        k = 2 * r + 1
        return (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)

    bc, bs, bh = blur(cyc_p), blur(ef_p), blur(ef_s)
    dsh = np.abs(bs - bh)
    pen = dsh > 0.25 * dsh.max()
    e_soft, e_hard = np.abs(bc - bs)[pen].mean(), np.abs(bc - bh)[pen].mean()
    # what the penumbra changes, in each renderer: soft less hard (the two
    # Cycles renders' own offsets cancel)
    dC, dE = (bc - blur(cyc_s))[pen], (bs - bh)[pen]
    corr = np.corrcoef(dC, dE)[0, 1]
    e_chg, e_none = np.abs(dC - dE).mean(), np.abs(dC).mean()
    mean_rel = (cyc_p.mean() - ef_p.mean()) / ef_p.mean()
    rows = np.abs(cyc_p.mean(axis=(1, 2)) - ef_p.mean(axis=(1, 2))) / ef_p.mean(axis=(1, 2))
    print("blender_lit: a sun 3 degrees wide through the same map (angle=3, 32 directions): "
          "Cycles mean %.5f, exrfog %.5f (%+.2f %%); row means within %.2f %%; in the %d "
          "penumbra pixels (7x7 means; soft and hard differ by up to %.5f there) |Cycles - "
          "exrfog| %.5f, the hard shadow's %.5f; the change from hard to soft: Cycles' "
          "against exrfog's correlate %.3f, differ by %.5f against %.5f for no change"
          % (cyc_p.mean(), ef_p.mean(), 100 * mean_rel, 100 * rows.max(), int(pen.sum()),
             dsh.max(), e_soft, e_hard, corr, e_chg, e_none))
    if not (abs(mean_rel) < 0.015 and rows.max() < 0.03 and pen.sum() > 100 and
            corr > 0.75 and e_chg < 0.75 * e_none):
        raise SystemExit("blender_lit: FAILED: exrfog's penumbrae differ from Cycles'")
    # a point lamp: its radiant intensity read off Cycles' own render of a
    # white Lambertian plane 2 units behind it (radiance I / (pi d^2) at the
    # foot of the perpendicular), then what it adds to the fog, as for the sun
    # Blender's point lamp of P watts is I = P / (4 pi) W/sr; the plane checks it
    cal = rgb(d + "/calib.exr")
    measured = np.pi * 2.0 ** 2 * cal.max(axis=(0, 1))[1]
    inten = 300 / (4 * np.pi)
    if not abs(measured / inten - 1) < 0.02:
        raise SystemExit("blender_lit: FAILED: Cycles' lamp is %.3f W/sr by its own plane, "
                         "not P / (4 pi) = %.3f" % (measured, inten))
    run([exrfog, d + "/plain.exr", "-o", d + "/ef_lamp.exr", "--light",
         "point:position=1.5,4,2:intensity=%r" % inten] + common)
    cyc_l = rgb(d + "/lampfog.exr") - rgb(d + "/dark.exr")
    ef_l = rgb(d + "/ef_lamp.exr") - rgb(d + "/ef_dark.exr")
    # within 3 pixels of the lamp's image the halo changes across a pixel
    # far more than Cycles' pixel filter leaves as it is: compared apart
    py, px = np.unravel_index(np.argmax(ef_l[..., 1]), ef_l.shape[:2])
    yy, xx = np.mgrid[0:ef_l.shape[0], 0:ef_l.shape[1]]
    keep = (yy - py) ** 2 + (xx - px) ** 2 > 9
    c_k, e_k = np.where(keep[..., None], cyc_l, 0), np.where(keep[..., None], ef_l, 0)
    mean_rel = lamp_rel = (cyc_l.mean() - ef_l.mean()) / ef_l.mean()
    # Cycles' volume sampling of a point lamp is noisy at 256 samples (a few
    # fireflies per row): bands of 4 rows
    cb = c_k.sum(axis=(1, 2)).reshape(-1, 4).sum(axis=1)
    eb = e_k.sum(axis=(1, 2)).reshape(-1, 4).sum(axis=1)
    rows = lamp_rows = np.abs(cb - eb) / eb
    diff = (cyc_l - ef_l)[keep]
    print("blender_lit: a point lamp of 300 W (I = P/(4 pi) = %.3f W/sr; Cycles' white plane "
          "reads %.3f): Cycles mean %.5f, exrfog %.5f (%+.2f %%); away from its image, bands "
          "of 4 rows within %.2f %%, per pixel |diff| mean %.5f, p99.9 %.5f; within 3 pixels "
          "of it (Cycles' pixel filter spreads the peak) Cycles %.4f, exrfog %.4f"
          % (inten, measured, cyc_l.mean(), ef_l.mean(), 100 * mean_rel, 100 * rows.max(),
             np.abs(diff).mean(), np.percentile(np.abs(diff), 99.9), cyc_l[~keep].mean(),
             ef_l[~keep].mean()))
    # a spot with a perspective shadow map: the ball's shadow under it, from
    # Cycles' own depth render by a camera at the spot (its matrices in the
    # map's header, as for the sun; NDC y down, w = the camera's z)
    sm = json.load(open(d + "/spotmap.exr.json"))
    k = 0.5 / np.tan(np.radians(sm["fov"]) / 2)
    write_map(d + "/spotmap.exr", d + "/spotmap_h.exr", sm,
              np.array([[k, 0, 0, 0], [0, -k, 0, 0], [0.5, 0.5, 1, 1], [0, 0, -0.01, 0]]))
    # cosine=1: Cycles 3.x spots fall as cos alpha inside the cone too
    spot = "spot:position=-1,2,5.5:aim=0,0,-1:cone=70:cosine=1:intensity=%r" % (40000 / (4 * np.pi))
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_spot.exr", "--light",
         spot + ":shadow=%s/spotmap_h.exr" % d] + common)
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_spot_un.exr", "--light", spot] + common)
    cyc_p = rgb(d + "/spotfog.exr") - rgb(d + "/darkS.exr")
    ef_p = rgb(d + "/ef_spot.exr") - rgb(d + "/ef_darkS.exr")
    ef_pu = rgb(d + "/ef_spot_un.exr") - rgb(d + "/ef_darkS.exr")
    mean_rel = (cyc_p.mean() - ef_p.mean()) / ef_p.mean()
    cb = cyc_p.sum(axis=(1, 2)).reshape(-1, 4).sum(axis=1)
    eb = ef_p.sum(axis=(1, 2)).reshape(-1, 4).sum(axis=1)
    lit_rows = eb > 0.1 * eb.max()   # the bands the cone lights
    rows = np.abs(cb - eb)[lit_rows] / eb[lit_rows]
    shade = 1 - ef_p.mean() / ef_pu.mean()
    print("blender_lit: a 40 kW spot with a perspective shadow map: Cycles mean %.5f, exrfog "
          "%.5f (%+.2f %%); lit bands of 4 rows within %.2f %%; per pixel |diff| mean %.5f, p99.9 "
          "%.5f; the ball's shadow takes %.1f %% of the spot's light"
          % (cyc_p.mean(), ef_p.mean(), 100 * mean_rel, 100 * rows.max(),
             np.abs(cyc_p - ef_p).mean(), np.percentile(np.abs(cyc_p - ef_p), 99.9),
             100 * shade))
    if os.environ.get("BLENDER_LIT_KEEP"):
        for f in ("spotfog.exr", "darkS.exr", "ef_spot.exr", "ef_darkS.exr", "spotmap_h.exr"):
            shutil.copy(d + "/" + f, os.environ["BLENDER_LIT_KEEP"] + "/" + f)
    if not (abs(mean_rel) < 0.02 and rows.max() < 0.06 and shade > 0.03):
        raise SystemExit("blender_lit: FAILED: exrfog's shadowed spot differs from Cycles'")
    # The add-on's spot map: perspective from the spot over its 70-degree
    # cone (the test's own map spans 90), its SPEC (cone, blend, power over
    # 4 pi, cosine=1 on Blender 3) from the light itself: against Cycles as
    # the header-stamped map is.
    op_spot = operator_light("opspot")
    run([exrfog, d + "/plainS.exr", "-o", d + "/ef_opspot.exr", "--light", op_spot] + common)
    ef_q = rgb(d + "/ef_opspot.exr") - rgb(d + "/ef_darkS.exr")
    q_rel = (cyc_p.mean() - ef_q.mean()) / ef_q.mean()
    qb = ef_q.sum(axis=(1, 2)).reshape(-1, 4).sum(axis=1)
    q_rows = np.abs(cb - qb)[lit_rows] / qb[lit_rows]
    q_shade = 1 - ef_q.mean() / ef_pu.mean()
    print("blender_lit: the add-on's spot map (%s): Cycles mean %.5f, exrfog %.5f (%+.2f %%); "
          "lit bands within %.2f %%; the shadow takes %.1f %%"
          % (op_spot, cyc_p.mean(), ef_q.mean(), 100 * q_rel, 100 * q_rows.max(), 100 * q_shade))
    if not (abs(q_rel) < 0.02 and q_rows.max() < 0.06 and q_shade > 0.03):
        raise SystemExit("blender_lit: FAILED: the add-on's spot map differs from Cycles'")
    if os.environ.get("BLENDER_LIT_KEEP"):
        for f in ("lampfog.exr", "dark.exr", "ef_lamp.exr", "ef_dark.exr", "calib.exr"):
            shutil.copy(d + "/" + f, os.environ["BLENDER_LIT_KEEP"] + "/" + f)
    if not (abs(lamp_rel) < 0.01 and lamp_rows.max() < 0.06):
        raise SystemExit("blender_lit: FAILED: exrfog's point lamp differs from Cycles'")
    if os.environ.get("BLENDER_LIT_KEEP"):
        for f in ("shafts.exr", "darkS.exr", "ef_shafts.exr", "ef_darkS.exr", "map.exr"):
            shutil.copy(d + "/" + f, os.environ["BLENDER_LIT_KEEP"] + "/" + f)
    dark_c, dark_e = rgb(d + "/dark.exr"), rgb(d + "/ef_dark.exr")
    print("blender_lit: unlit: Cycles mean %.5f, exrfog %.5f (the surfaces light Cycles' fog)"
          % (dark_c.mean(), dark_e.mean()))
    print("blender_lit: ok")
