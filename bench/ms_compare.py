"""Compares exrfog's multiple scattering with Cycles' (bench/ms.sh, the suite's blender_ms):

  ms_compare.py EXRFOG BLENDER DIR SPP ELEV DENSITY ALBEDO G TOP W H [BLOCK [LAYERS|- [sky]
                [camz=Z] [lamp=DIST [wall=D]]]]

Renders bench/ms_blender.py's slab twice (volume bounces 0 and 128), runs exrfog on the
render without fog (black under the sun, so the output is the fog's light alone) with the same sun,
scattering=single and scattering=multiple:ground=0, and prints one line of JSON: per BLOCKxBLOCK
block of pixels (noise averaged down), Cycles' radiance with every bounce against exrfog's
single + multiple, the share single scattering alone gives, Cycles' own noise (the standard
error of the block mean from its pixels), exrfog's error output, and the times.

lamp=DIST: bench/ms_lamp_blender.py's point lamp DIST units ahead in fog everywhere (ELEV and TOP
unused; exrfog: exp fog and the lamp with scattering=multiple); wall=D adds its black wall over
the frame's left half (the glow must stop at it); behind puts the lamp behind the camera;
falloff=K makes the fog exponential height fog, DENSITY exp(-K z) over the camera's height
(exrfog: height:density=DENSITY:falloff=K with --up-axis z)."""
import json
import os
import subprocess
import sys
import time

import numpy as np
import OpenImageIO as oiio

exrfog, blender, d = sys.argv[1], sys.argv[2], sys.argv[3]
spp, elev, dens, albedo, g, top = sys.argv[4], *(float(v) for v in sys.argv[5:10])
W, H = int(sys.argv[10]), int(sys.argv[11])
block = int(sys.argv[12]) if len(sys.argv) > 12 else 4
# LAYERS (optional, as bench/ms_blender.py's): nested slabs of their own albedo and g
layers = sys.argv[13] if len(sys.argv) > 13 and sys.argv[13] != "-" else None
# "sky": a uniform sky of radiance 1 in place of the sun (exrfog: --sky-light of a constant map)
sky = "sky" in sys.argv[14:]
# "camz=Z": the camera's height (bench/ms_blender.py)
camz = next((a for a in sys.argv[14:] if a.startswith("camz=")), None)
lamp = next((float(a[5:]) for a in sys.argv[14:] if a.startswith("lamp=")), None)
wall = next((a for a in sys.argv[14:] if a.startswith("wall=")), None)
behind = "behind" in sys.argv[14:]
falloff = next((a for a in sys.argv[14:] if a.startswith("falloff=")), None)
# spot=CONE: the lamp is a spot of that cone (degrees, blend 0.2) aimed straight down (-z)
spot = next((a for a in sys.argv[14:] if a.startswith("spot=")), None)
across = spot is not None and "across" in sys.argv[14:]   # the spot aimed along -x instead
# box=X0,Y0,Z0,X1,Y1,Z1 (with lamp=): the fog fills that box alone (exrfog: box:min=:max=)
box = next((a for a in sys.argv[14:] if a.startswith("box=")), None)
# sbox=X0,Y0,X1,Y1 (with the sun): the slab cut to that footprint (exrfog: box:min=X0,Y0,-1:max=X1,Y1,TOP)
sbox = next((a for a in sys.argv[14:] if a.startswith("sbox=")), None)
# hs=Z (with lamp=): the fog fills everything below z = Z (exrfog: halfspace:plane=0,0,1,-Z)
hs = next((a for a in sys.argv[14:] if a.startswith("hs=")), None)
# lay=H0/F0,H1/F1,... (with lamp=): layered fog, DENSITY times factors linear between the knots
# (exrfog: layered:heights=H0,H1,...:densities=DENSITY F0,...)
lay = next((a for a in sys.argv[14:] if a.startswith("lay=")), None)
here = os.path.dirname(os.path.abspath(__file__))
os.makedirs(d, exist_ok=True)
tag = ("e%g_d%g_a%g_g%g" % (elev, dens, albedo, g) + ("_layers" if layers else "") +
       ("_sky" if sky else "") + ("_" + camz.replace("=", "") if camz else "") +
       ("_sbox" + sbox[5:].replace(",", "_") if sbox else ""))
if lamp is not None:
    tag = ("lamp%g_d%g_a%g_g%g" % (lamp, dens, albedo, g) + ("_" + wall.replace("=", "") if wall else "")
           + ("_behind" if behind else "") + ("_" + falloff.replace("=", "") if falloff else "")
           + ("_" + spot.replace("=", "") if spot else "") + ("_across" if across else "")
           + ("_box" + box[4:].replace(",", "_") if box else "") + ("_hs" + hs[3:] if hs else "")
           + ("_lay" + lay[4:].replace(",", "_").replace("/", "x") if lay else ""))


def render(bounces):
    out = "%s/%s_%s.exr" % (d, tag, "b%d" % bounces if bounces >= 0 else "plain")
    t0 = time.time()
    if lamp is not None:
        script = [here + "/ms_lamp_blender.py", "--", out, spp, str(bounces), str(dens), str(albedo),
                  str(g), str(lamp), str(W), str(H)] + ([wall] if wall else []) + (["behind"] if behind else []) + ([falloff] if falloff else []) + ([spot] if spot else []) + (["across"] if across else []) + ([box] if box else []) + ([hs] if hs else []) + ([lay] if lay else [])
    else:
        script = ([here + "/ms_blender.py", "--", out, spp, str(bounces), str(elev),
                   str(dens), str(albedo), str(g), str(top), str(W), str(H)]
                  + [layers or "-"] + (["sky"] if sky else []) + ([camz] if camz else [])
                  + ([sbox] if sbox else []))
    if os.environ.get("MS_REUSE") and os.path.exists(out) and os.path.exists(out + ".json"):
        return out, 0.0   # MS_REUSE=1: an earlier run's render of the same case
    r = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python"]
                       + script, capture_output=True, text=True)
    if "blender: rendered" not in r.stdout:
        raise SystemExit("ms_compare: Blender failed:\n" + r.stdout[-2000:] + r.stderr[-2000:])
    return out, time.time() - t0


def pixels(path):
    b = oiio.ImageBuf(path)
    return b.get_pixels(oiio.FLOAT), b.spec()


c0, t_c0 = render(0)
cm, t_cm = render(128)
cp, _ = render(-1)
cam = json.load(open(cm + ".json"))
# exrfog's input: the render without fog (black where the sun lights it; the
# sky itself where the world does), with its depth
px, spec = pixels(cp)
inp = px.copy()
inp[..., 3] = 1
ib = oiio.ImageBuf(spec)
ib.set_pixels(oiio.ROI(), inp)
ib.write("%s/%s_in.exr" % (d, tag))
fogs = []
for l in ([] if lamp is not None else layers.split(",") if layers else ["%r:%r:%r:%r" % (top, dens, albedo, g)]):
    lt, ld, la, lg = (float(v) for v in l.split(":"))
    if sbox:
        x0, y0, x1, y1 = (float(v) for v in sbox[5:].split(","))
        fogs += ["--fog", "box:min=%r,%r,-1:max=%r,%r,%r:density=%r:albedo=%r:phase=hg:g=%r" % (
            x0, y0, x1, y1, lt, ld, la, lg)]
    else:
        fogs += ["--fog", "halfspace:plane=0,0,1,%r:density=%r:albedo=%r:phase=hg:g=%r" % (-lt, ld, la, lg)]
common = ["--up-axis", "z", "--camera-convention", "blender", "--camera-to-world",
          ",".join(repr(v) for v in cam["c2w"]), "--fov", repr(cam["fov"]), "--near",
          repr(cam["near"]), "--far", repr(cam["far"]), "--fog-color", "0,0,0"] + fogs + [
          "--aov", "error"]
if lamp is not None:
    fogs = ["--fog", "exp:density=%r:albedo=%r:phase=hg:g=%r" % (dens, albedo, g)]
    if falloff:
        fogs = ["--fog", "height:density=%r:%s:albedo=%r:phase=hg:g=%r" % (dens, falloff, albedo, g)]
    if box:
        bx = [float(v) for v in box[4:].split(",")]
        fogs = ["--fog", "box:min=%r,%r,%r:max=%r,%r,%r:density=%r:albedo=%r:phase=hg:g=%r" % (
            tuple(bx) + (dens, albedo, g))]
    if hs:
        fogs = ["--fog", "halfspace:plane=0,0,1,%r:density=%r:albedo=%r:phase=hg:g=%r" % (
            -float(hs[3:]), dens, albedo, g)]
    if lay:
        kn = [tuple(float(x) for x in k.split("/")) for k in lay[4:].split(",")]
        fogs = ["--fog", "layered:heights=%s:densities=%s:albedo=%r:phase=hg:g=%r" % (
            ",".join(repr(h) for h, _ in kn), ",".join(repr(dens * f) for _, f in kn), albedo, g)]
    common[common.index("--fog-color") + 2:common.index("--fog-color") + 2] = fogs
    sun = "point:position=%r,%r,%r:intensity=%r" % (tuple(cam["lamp"]) + (cam["intensity"],))
    if spot:   # cosine=1: Cycles 3.x's spots fall as cos alpha inside the cone too
        sun = "spot:position=%r,%r,%r:aim=%s:cone=%s:blend=0.2:cosine=1:intensity=%r" % (
            tuple(cam["lamp"]) + ("-1,0,0" if across else "0,0,-1", spot[5:], cam["intensity"]))
else:
    sun = "sun:towards=%r,%r,%r:intensity=1" % tuple(cam["towards"])
if sky:
    env = np.ones((32, 64, 3), np.float32)
    eb = oiio.ImageBuf(oiio.ImageSpec(64, 32, 3, oiio.FLOAT))
    eb.set_pixels(oiio.ROI(), env)
    eb.write("%s/env1.exr" % d)
times = {}
for mode, extra in (("single", ""), ("multiple", ":scattering=multiple" + ("" if lamp is not None else ":ground=0"))):
    t0 = time.time()
    light = (["--sky-light", "%s/env1.exr%s" % (d, extra or ":intensity=1")] if sky
             else ["--light", sun + extra])
    r = subprocess.run([exrfog, "%s/%s_in.exr" % (d, tag), "-o", "%s/%s_ef_%s.exr" % (d, tag, mode)]
                       + light + common, capture_output=True, text=True)
    times[mode] = time.time() - t0
    if r.returncode:
        raise SystemExit("ms_compare: exrfog failed: " + r.stderr)
cyc0 = pixels(c0)[0][..., :3]
cycm = pixels(cm)[0][..., :3]
efs, s1 = pixels("%s/%s_ef_single.exr" % (d, tag))
efm, s2 = pixels("%s/%s_ef_multiple.exr" % (d, tag))
names = list(s2.channelnames)
err = efm[..., names.index("fog_error.R"):names.index("fog_error.R") + 3]
efs, efm = efs[..., :3], efm[..., :3]
h, w = (H // block) * block, (W // block) * block


def blocks(a):
    a = a[:h, :w].mean(axis=2)
    return a.reshape(h // block, block, w // block, block).mean(axis=(1, 3))


def block_se(a):
    # a pixel's noise from its difference to the mean of its four neighbours
    # (var = 1.25 sigma^2 for independent noise; the field's curvature adds a
    # little: an over-estimate), then the block mean's standard error
    a = a.mean(axis=2)
    r = a[1:-1, 1:-1] - 0.25 * (a[:-2, 1:-1] + a[2:, 1:-1] + a[1:-1, :-2] + a[1:-1, 2:])
    sig = np.zeros_like(a)
    sig[1:-1, 1:-1] = r * r / 1.25
    sig[0, :], sig[-1, :], sig[:, 0], sig[:, -1] = sig[1, :], sig[-2, :], sig[:, 1], sig[:, -2]
    v = sig[:h, :w].reshape(h // block, block, w // block, block).mean(axis=(1, 3))
    return np.sqrt(v) / block


C, C0, E1, EM, ER = blocks(cycm), blocks(cyc0), blocks(efs), blocks(efm), blocks(err)
noise = block_se(cycm)
ok = C > 1e-4
rel = (EM - C)[ok] / C[ok]
res = {
    "case": tag, "layers": layers, "sky": sky, "lamp": lamp, "wall": float(wall[5:]) if wall else None,
    "behind": behind, "falloff": float(falloff[8:]) if falloff else 0.0,
    "spot": float(spot[5:]) if spot else None, "across": across, "box": box[4:] if box else None, "sbox": sbox[5:] if sbox else None, "hs": float(hs[3:]) if hs else None, "lay": lay[4:] if lay else None,
    "lamp_tau": dens * lamp if lamp is not None else None, "camz": float(camz[5:]) if camz else 2.0,
    "elev": elev, "density": dens, "albedo": albedo, "g": g, "top": top,
    "vertical_tau": dens * top, "spp": int(spp), "size": [W, H], "block": block,
    "blocks": int(ok.sum()),
    "cycles_mean": float(C[ok].mean()), "cycles_single_mean": float(C0[ok].mean()),
    "exrfog_single_mean": float(E1[ok].mean()), "exrfog_multiple_mean": float(EM[ok].mean()),
    "single_share_median": float(np.median(E1[ok] / C[ok])),
    "single_check_median": float(np.median((E1[ok] - C0[ok]) / C0[ok])),
    "rel_median": float(np.median(np.abs(rel))), "rel_p99": float(np.percentile(np.abs(rel), 99)),
    "rel_signed_median": float(np.median(rel)),
    # each block's error beyond twice its own noise (the reference's share)
    "beyond_noise_p99": float(np.percentile(np.maximum(0, np.abs(rel) - 2 * noise[ok] / C[ok]), 99)),
    "noise_rel_median": float(np.median(noise[ok] / C[ok])),
    "covered": float(np.mean(np.abs(EM - C)[ok] <= ER[ok] + 2 * noise[ok])),
    "err_rel_median": float(np.median(ER[ok] / C[ok])),
    "t_cycles_single": t_c0, "t_cycles_multiple": t_cm,
    "t_exrfog_single": times["single"], "t_exrfog_multiple": times["multiple"],
}
print(json.dumps(res))
