"""ctest blender_ms: multiple scattering against Blender Cycles with 128 volume
bounces (issue 44), one small case of bench/ms.sh's grid: a slab of
homogeneous fog (vertical optical depth 2, albedo 0.95, HG g 0.5) over a black
ground, the sun 30 degrees up, 64x36 at 1024 samples, compared per 8x8 block
of pixels. Single scattering alone is about a tenth of Cycles' light here;
exrfog's single scattering must match Cycles' with volume bounces 0, and
single + multiple Cycles' with every bounce: median within 2 %, every block
within 5 % plus twice Cycles' noise, the error output covering the
difference (beyond the noise) on 80 % of blocks at least. Then the same slab
under a uniform sky of radiance 1 (Cycles' world; exrfog's --sky-light of a
constant map with scattering=multiple), every bounce against every order,
held alike (measured at 4096 samples: median 0.27 %, covered 100 %). And a
point lamp 10 units ahead in fog everywhere (density 0.2: the lamp's optical
depth 2; albedo 0.9, g 0.5; bench/ms_lamp_blender.py) at 4096 samples (its
blocks are noisier: 2 % at 1024), its single scattering against bounces 0 and
single + multiple against every bounce, held alike, the 99th percentile as
each block's error beyond twice its own noise (measured at 16384 samples per
4x4 block: median 0.95 % against Cycles' noise of 1.07 %). Last, the lamp in
a box of fog (density 0.2, albedo 0.95, g 0.5, 15 x 12 x 12 units about it,
the camera outside; bench/ms_lamp_box.md's first test case) at 1024 samples:
the uniform field less the lamp's images across the faces reads the multiple
part about 2 % low there (13 % high without the images), so only the single
scattering and the error output's coverage are held (95 % of 8x8 blocks;
measured 100 %, and every 4x4 block in bench/ms_lamp_box.md). Then a lamp
0.15 mean free paths below a half-space's plane (density 0.3, albedo 0.9,
g 0): the uniform field alone read the multiple part 1.93 times Cycles';
less the lamp's image across the plane it must be within 0.85 to 1.3 of
Cycles' over the frame (measured 1.14), its error output covering 95 %. And the lamp
under the soft top of layered fog (density 0.2 below z = 2, falling linearly
to 0 at z = 5; bench/ms_lamp_layered.md's first case) at 1024 samples: the
multiple part reads about 30 % high, the light leaking out through the thin
top, which the error output's leak term must cover the same way (measured
100 % of 8x8 blocks; 12 % before layers had the term).
Exits 77 (skipped) without Blender."""
import json
import os
import shutil
import subprocess
import sys
import tempfile

exrfog = os.environ["EXRFOG_BIN"]
src = os.environ["EXRFOG_SOURCE_DIR"]
blender = shutil.which("blender")
if not blender:
    print("blender_ms: Blender is not installed (skipped)")
    sys.exit(77)
bad = []
with tempfile.TemporaryDirectory(prefix="exrfog-ms-") as d:
    slab = ["30", "0.1", "0.95", "0.5", "20"]
    for spp, case, extra in (("1024", slab, []), ("1024", slab, ["-", "sky"]),
                             ("4096", ["0", "0.2", "0.9", "0.5", "0"], ["-", "lamp=10"]),
                             ("1024", ["0", "0.2", "0.95", "0.5", "0"],
                              ["-", "lamp=10", "box=-6,4,-5,9,16,7"]),
                             ("1024", ["0", "0.2", "0.95", "0.5", "0"],
                              ["-", "lamp=10", "lay=2/1,5/0"]),
                             ("1024", ["0", "0.3", "0.9", "0", "0"],
                              ["-", "lamp=10", "hs=1.5"])):
        r = subprocess.run(["/usr/bin/python3", os.path.join(src, "bench", "ms_compare.py"),
                            exrfog, blender, d, spp] + case + ["64", "36", "8"] + extra,
                           capture_output=True, text=True)
        if r.returncode:
            raise SystemExit("blender_ms: FAILED: " + r.stdout + r.stderr)
        res = json.loads(r.stdout.strip().splitlines()[-1])
        print("blender_ms: " + json.dumps(res))
        sky = "sky" in extra
        boxed = any(e.startswith(("box=", "lay=", "hs=")) for e in extra)
        half = any(e.startswith("hs=") for e in extra)
        what = ("the sky: " if sky else "the lamp in a box: " if "box=" in " ".join(extra)
                else "the lamp under a plane: " if half else "the lamp under layers: " if boxed
                else "the lamp: " if extra else "the sun: ")
        # (Cycles' world light with volume bounces 0 is not exrfog's
        # unattenuated sky model: only the sun's and the lamp's single
        # scattering compare)
        # (the lamp's single scattering reads about 0.7 % below Cycles' bounces
        # 0 over bench/ms_lamp.md's grid: 1.5 % for it)
        if not sky and not abs(res["single_check_median"]) < (0.015 if extra else 0.01):
            bad.append(what + "single scattering differs from Cycles' bounces 0 by %.2f %%"
                       % (100 * res["single_check_median"]))
        if not sky and not res["single_share_median"] < 0.5:
            bad.append(what + "single scattering is %.0f %% of the light: the case does not "
                       "test multiple" % (100 * res["single_share_median"]))
        if half:   # the image across the plane takes out what the uniform field counts
            ms = ((res["exrfog_multiple_mean"] - res["exrfog_single_mean"]) /
                  (res["cycles_mean"] - res["cycles_single_mean"]))
            if not 0.85 <= ms <= 1.3:
                bad.append(what + "the multiple part is %.2f of Cycles'" % ms)
        if boxed:   # the value is known to be off here: its error output must say so
            if not res["covered"] >= 0.95:
                bad.append(what + "the error output covers %.0f %% of blocks"
                           % (100 * res["covered"]))
            continue
        if not res["rel_median"] < 0.02:
            bad.append(what + "median error %.2f %%" % (100 * res["rel_median"]))
        # (a lamp's blocks beside it are far noisier than the median block:
        # each block's error beyond twice its own noise)
        if not (res["beyond_noise_p99"] < 0.05 if extra and not sky
                else res["rel_p99"] < 0.05 + 2 * res["noise_rel_median"]):
            bad.append(what + "99th percentile error %.2f %% (beyond the noise %.2f %%)"
                       % (100 * res["rel_p99"], 100 * res["beyond_noise_p99"]))
        if not res["covered"] >= 0.8:
            bad.append(what + "the error output covers %.0f %% of blocks"
                       % (100 * res["covered"]))
if bad:
    raise SystemExit("blender_ms: FAILED: " + "; ".join(bad))
print("blender_ms: OK")
