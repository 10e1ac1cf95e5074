"""The Python module (python/exrfog) against the command line and against
values worked out by hand. Run by ctest with PYTHONPATH at python/ and
EXRFOG_LIBRARY at the built libexrfog; exits 77 (skipped) without numpy
only for the in-memory part."""
import math
import os
import subprocess
import sys
import tempfile

import exrfog

BIN = os.environ["EXRFOG_BIN"]
SAMPLE = os.path.join(os.environ["EXRFOG_SOURCE_DIR"], "samples", "sample.exr")
failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAILED:", what, file=sys.stderr)


def cli(args):
    return subprocess.run([BIN] + args, capture_output=True, text=True)


with tempfile.TemporaryDirectory() as d:
    # fog(): the same file as the command line, byte for byte
    a, b = os.path.join(d, "cli.exr"), os.path.join(d, "py.exr")
    r = cli([SAMPLE, "-o", a, "--fog", "exp:density=0.02", "--fog-color", "0.6,0.65,0.7",
             "--aov", "T"])
    check(r.returncode == 0, "the CLI run")
    exrfog.fog(SAMPLE, b, fog=["exp:density=0.02"], fog_color="0.6,0.65,0.7", aov="T")
    check(open(a, "rb").read() == open(b, "rb").read(), "fog() writes the CLI's bytes")
    # a list of numbers is written as the CLI's R,G,B
    c = os.path.join(d, "py2.exr")
    exrfog.fog(SAMPLE, c, fog="exp:density=0.02", fog_color=(0.6, 0.65, 0.7), aov="T")
    r = cli([SAMPLE, "-o", a, "--fog", "exp:density=0.02", "--fog-color", "0.6,0.65,0.7",
             "--aov", "T"])
    check(open(a, "rb").read() == open(c, "rb").read(), "numbers as R,G,B: the CLI's bytes")

    # errors: the CLI's message and status
    missing = os.path.join(d, "missing.exr")
    r = cli([missing, "-o", a, "--fog", "exp:density=0.02"])
    try:
        exrfog.fog(missing, a, fog="exp:density=0.02")
        check(False, "a missing input raises")
    except exrfog.Error as e:
        check(str(e) == r.stderr.strip()[len("exrfog: "):], "the CLI's message: %r vs %r" % (str(e), r.stderr))
        check(e.status == 1 == r.returncode, "status 1")
    try:
        exrfog.fog(SAMPLE, a, fog="bogus")
        check(False, "a bad SPEC raises")
    except exrfog.Error as e:
        check(e.status == 2 and "bogus" in str(e), "usage error, status 2")

    # progress and cancellation
    seen = []
    exrfog.fog(SAMPLE, b, fog="exp:density=0.02", progress=lambda f: seen.append(f) and False)
    check(len(seen) >= 1 and all(0 <= f <= 1 for f in seen), "progress fractions")
    out = os.path.join(d, "cancelled.exr")
    try:
        exrfog.fog(SAMPLE, out, fog="exp:density=0.02", progress=lambda f: True)
        check(False, "a cancelled run raises")
    except exrfog.Error as e:
        check(e.status == 3 and not os.path.exists(out), "cancelled: status 3, nothing written")

    # progress: monotonic, per chunk, exactly 1.0 once at the end
    seen = []
    exrfog.fog(SAMPLE, b, fog="exp:density=0.02", progress=lambda f: seen.append(f) and False)
    check(len(seen) >= 3, "progress per chunk (%d calls)" % len(seen))
    check(all(x < y for x, y in zip(seen, seen[1:])), "progress never goes back")
    check(seen[-1] == 1.0 and all(f < 1.0 for f in seen[:-1]), "progress ends at exactly 1.0")

    # threads: eight calls at once, each the bytes of the same call alone
    import threading
    jobs = [("exp:density=0.05", "T"), ("noise:density=0.2:scale=2:octaves=2", "T,error"),
            ("height:density=0.1:falloff=0.2:base=0", "P"), ("exp2:density=0.02", "T")]
    alone = []
    for k, (spec, aov) in enumerate(jobs):
        o = os.path.join(d, "alone%d.exr" % k)
        exrfog.fog(SAMPLE, o, fog=spec, aov=aov)
        alone.append(open(o, "rb").read())
    errors = []

    def one(i):
        spec, aov = jobs[i % 4]
        o = os.path.join(d, "thread%d.exr" % i)
        try:
            exrfog.fog(SAMPLE, o, fog=spec, aov=aov)
            if open(o, "rb").read() != alone[i % 4]:
                errors.append("thread %d differs" % i)
            facts = exrfog.explain(SAMPLE, fog=spec)
            if facts["fog"] != [spec]:
                errors.append("thread %d explain" % i)
        except Exception as e:  # noqa: BLE001 (collected, then checked)
            errors.append("thread %d: %r" % (i, e))
    ts = [threading.Thread(target=one, args=(i,)) for i in range(8)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    check(not errors, "eight threads at once give the bytes of each alone: %s" % errors)

    # hostile names: "--help" and "-in.exr" are files; NUL is refused as open() refuses it
    for name in ("--help", "-in.exr"):
        src = os.path.join(d, name)
        open(src, "wb").write(open(SAMPLE, "rb").read())
        cwd = os.getcwd()
        os.chdir(d)
        try:
            exrfog.fog(name, "out_" + name.lstrip("-"), fog="exp:density=0.02")
            check(os.path.exists("out_" + name.lstrip("-")), "INPUT %r is a file" % name)
        except exrfog.Error as e:
            check(False, "INPUT %r: %s" % (name, e))
        finally:
            os.chdir(cwd)
    for bad in (SAMPLE + "\0x", ):
        try:
            exrfog.fog(bad, b, fog="exp:density=0.02")
            check(False, "a NUL in a path raises")
        except ValueError as e:
            check("null" in str(e), "ValueError as open() raises")
    try:
        exrfog.fog(SAMPLE, b + "\0.exr", fog="exp:density=0.02")
        check(False, "a NUL in the output raises")
    except ValueError:
        pass

    # warnings reach Python's warnings module as exrfog.Warning, with the
    # text the command line prints (a non-rigid camera pose from the flags)
    import warnings
    shear = "2,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1"
    r = cli([SAMPLE, "-o", a, "--fog", "exp:density=0.02", "--world-to-camera", shear,
             "--fov", "50"])
    cli_warn = [l for l in r.stderr.splitlines() if ": warning: " in l]
    check(len(cli_warn) == 1, "the CLI warns once: %r" % r.stderr)
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        exrfog.fog(SAMPLE, b, fog="exp:density=0.02", world_to_camera=shear, fov=50)
    got = [w for w in got if issubclass(w.category, exrfog.Warning)]
    check(len(got) == 1, "one exrfog.Warning: %r" % [str(w.message) for w in got])
    if got and cli_warn:
        check("exrfog: " + str(got[0].message).replace(": ", ": warning: ", 1) == cli_warn[0],
              "the warning's text is the CLI's: %r vs %r" % (str(got[0].message), cli_warn[0]))

    # explain(): the same facts as --explain --json
    facts = exrfog.explain(SAMPLE, fog="exp:density=0.02")
    pos = facts["views"][0]["camera"]["position"]
    check(abs(pos[1] - 1.7) < 1e-6 and abs(pos[0]) < 1e-6, "the sample's camera at (0, 1.7, 0)")
    check(facts["views"][0]["depth"]["channel"] == "Z", "depth channel Z")
    check(facts["fog"] == ["exp:density=0.02"], "the fog")

try:
    import numpy as np
except ImportError:
    np = None
if np is not None:
    # fog_pixels(): 4 x 2 pixels of a 90-degree camera at the origin, depth 2:
    # T = exp(-0.1 * 2 * |ray|), P = 2 * ray, ray = (2u - 1, (1 - 2v) / 2, 1)
    h, w = 2, 4
    rgb = np.full((h, w, 3), 0.5, np.float32)
    depth = np.full((h, w), 2.0, np.float32)
    cam = {"camera_to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "fov": 90.0}
    res = exrfog.fog_pixels(rgb, None, depth, cam, ["exp:density=0.1"], color=(1, 1, 1))
    # a NUL in the convention or the depth mode was cut off silently by C
    # (issue 47): refused as open() refuses such a name
    for kw in ({"depth_mode": "planar\0junk"}, {}):
        c2 = dict(cam, convention="exr\0junk") if not kw else cam
        try:
            exrfog.fog_pixels(rgb, None, depth, c2, ["exp:density=0.1"], **kw)
            check(False, "a NUL in %s is refused" % (kw or "convention"))
        except ValueError as e:
            check("null" in str(e), "a NUL in %s is refused (%s)" % (kw or "convention", e))
    for y in range(h):
        for x in range(w):
            dx = 2 * (x + 0.5) / w - 1
            dy = (1 - 2 * (y + 0.5) / h) * h / w
            t = math.exp(-0.1 * 2 * math.sqrt(dx * dx + dy * dy + 1))
            check(abs(res["T"][y, x, 0] - t) < 1e-6, "fog_pixels T by hand")
            check(abs(res["rgb"][y, x, 1] - (0.5 * t + (1 - t))) < 1e-6, "fog_pixels colour by hand")
            check(np.allclose(res["P"][y, x], [2 * dx, 2 * dy, 2], atol=1e-6), "fog_pixels P by hand")
    check(float(rgb[0, 0, 0]) == 0.5, "the caller's array is not changed")
    try:
        exrfog.fog_pixels(rgb, None, depth[:1], cam, ["exp:density=0.1"])
        check(False, "mismatched shapes raise")
    except exrfog.Error:
        pass
    # a camera from a file's header
    res = exrfog.fog_pixels(np.full((1, 1, 3), 0.5), None, np.full((1, 1), 5.0), SAMPLE,
                            "exp:density=0.1", origin=(320, 180))
    check(0 < res["T"][0, 0, 0] < 1, "a camera from the sample's header")
    # layers=True: a white point lamp of 2 W/sr at (0.3, 0.2, 1) in exp fog of
    # density 0.1, the same 4 x 2 pixels over black: the lamp's layer by hand
    # (Simpson's rule, 4000 steps, of int e^-(0.1 t) 0.1 / (4 pi) 2 e^-(0.1 r)
    # / r^2 dt along each ray), and ambient + the lamp = the fog's colour
    import json
    import tempfile
    with tempfile.TemporaryDirectory() as td:
        sf = os.path.join(td, "lamp.json")
        with open(sf, "w") as f:
            json.dump({"lights": ["point:position=0.3,0.2,1:intensity=2:name=bulb"]}, f)
        res = exrfog.fog_pixels(np.zeros((h, w, 3), np.float32), None, depth, cam,
                                {"fog": ["exp:density=0.1"], "scene": sf}, color=(1, 1, 1),
                                layers=True)
    check(list(res["lights"]) == ["bulb"] and res["lit"] == {} and "sky" not in res,
          "fog_pixels layers: one light named bulb, no shadow, no sky (%s)" % list(res))
    worst = 0.0
    for y in range(h):
        for x in range(w):
            dx = 2 * (x + 0.5) / w - 1
            dy = (1 - 2 * (y + 0.5) / h) * h / w
            n = math.sqrt(dx * dx + dy * dy + 1)
            u = (dx / n, dy / n, 1 / n)
            D, steps = 2 * n, 4000
            acc = 0.0
            for i in range(steps + 1):
                t = D * i / steps
                r = math.dist((t * u[0], t * u[1], t * u[2]), (0.3, 0.2, 1.0))
                f = math.exp(-0.1 * t) * 0.1 / (4 * math.pi) * 2 * math.exp(-0.1 * r) / (r * r)
                acc += f * (1 if i in (0, steps) else 4 if i % 2 else 2)
            want = acc * D / steps / 3
            got = float(res["lights"]["bulb"][y, x, 1])
            worst = max(worst, abs(got - want) / want)
            tot = float(res["ambient"][y, x, 1]) + got
            check(abs(float(res["rgb"][y, x, 1]) - tot) <= 1e-6 * tot,
                  "fog_pixels layers sum to the fog's colour")
    check(worst < 1e-5, "fog_pixels lamp layer by hand (worst %.2e)" % worst)

# Ctrl-C during a slow call raises KeyboardInterrupt within a second and
# leaves no output and no temporary file (a child interpreter, SIGINT after
# half a second into an exact noise frame).
child = r"""
import os, sys, time, exrfog
out = sys.argv[2]
print("ready", flush=True)
t0 = time.monotonic()
try:
    exrfog.fog(sys.argv[1], out, threads=2,
               fog="noise:density=0.05:scale=10:octaves=4:falloff=0.01:base=0:method=exact")
    print("finished")
except KeyboardInterrupt:
    print("interrupted %.3f" % (time.monotonic() - t0))
"""
def interrupt(code, *args):
    """Runs code in a child interpreter, sends SIGINT half a second after
    it says it is ready, and returns (its output, seconds from the signal
    to its end)."""
    import signal
    import time
    p = subprocess.Popen([sys.executable, "-c", code] + list(args), stdout=subprocess.PIPE,
                         text=True, env=os.environ)
    p.stdout.readline()   # the interpreter and the module are loaded
    time.sleep(0.5)       # the call has started
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    so, _ = p.communicate(timeout=120)
    return so, time.monotonic() - t0


with tempfile.TemporaryDirectory() as d:
    out = os.path.join(d, "slow.exr")
    so, took = interrupt(child, SAMPLE, out)
    check(so.startswith("interrupted"), "Ctrl-C raises KeyboardInterrupt: %r" % so)
    check(took < 1.0, "within a second (%.3f s)" % took)
    check(not os.path.exists(out), "no output")
    check(not [f for f in os.listdir(d) if "exrfog-" in f], "no temporary file")

# Ctrl-C during a slow fog_pixels (issue 47: it was heard only when the
# call returned): KeyboardInterrupt within a second, the call cancelled
# between bands of rows (1536 x 1536 pixels of noise fog, a few seconds).
child_px = r"""
import sys, time, numpy as np, exrfog
rgb = np.zeros((1536, 1536, 3), np.float32)
depth = np.full((1536, 1536), 400.0, np.float32)
cam = {"camera_to_world": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "fov": 60.0}
print("ready", flush=True)
t0 = time.monotonic()
try:
    exrfog.fog_pixels(rgb, None, depth, cam,
                      ["noise:density=0.05:scale=2:octaves=8:falloff=0.01:base=0"])
    print("finished %.3f" % (time.monotonic() - t0))
except KeyboardInterrupt:
    print("interrupted %.3f" % (time.monotonic() - t0))
"""
try:
    import numpy  # noqa: F401
    have_np = True
except ImportError:
    have_np = False
if have_np:
    so, took = interrupt(child_px)
    check(so.startswith("interrupted"), "Ctrl-C in fog_pixels raises KeyboardInterrupt: %r" % so)
    check(took < 1.0, "fog_pixels: within a second (%.3f s)" % took)

print("test_python: %d failure(s)" % len(failures))
sys.exit(1 if failures else 0)
