"""ctest blender_addon: renders a tiny Cycles frame in headless Blender with
the exrfog add-on (tests/blender/blender_check.py), then checks the add-on's
fogged frame against exrfog run on the raw render with the same camera
given by flags, and against a run through the camera file it wrote.
Exits 77 (skipped) when Blender is not installed."""
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
    print("blender_addon: Blender is not installed (skipped)")
    sys.exit(77)


def run(args):
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode:
        print(r.stdout[-3000:], r.stderr[-3000:], file=sys.stderr)
        raise SystemExit("blender_addon: FAILED: " + " ".join(args[:3]))
    return r


def same_pixels(a, b):
    r = subprocess.run(["oiiotool", "--diff", a, b], capture_output=True, text=True)
    return r.returncode == 0 and "PASS" in r.stdout


with tempfile.TemporaryDirectory() as d:
    env = dict(os.environ, BLENDER_USER_CONFIG=d + "/cfg", BLENDER_USER_SCRIPTS=d + "/scripts")
    r = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                        os.path.join(src, "tests", "blender", "blender_check.py"), "--", d, exrfog,
                        os.path.join(src, "integrations", "blender")],
                       capture_output=True, text=True, env=env)
    if r.returncode or "blender_check: rendered and fogged" not in r.stdout:
        print(r.stdout[-4000:], r.stderr[-4000:], file=sys.stderr)
        raise SystemExit("blender_addon: FAILED: Blender run")
    render, fogged = d + "/render_0001.exr", d + "/fog_0001.exr"
    for f in (render, fogged, d + "/cams.json"):
        if not os.path.exists(f):
            raise SystemExit("blender_addon: FAILED: %s was not written" % f)
    flags = json.load(open(d + "/flags.json"))
    common = ["--layer", flags["layer"] + ".Combined", "--depth-channel",
              flags["layer"] + ".Depth.Z", "--up-axis", "z", "--units-per-meter", "1.0",
              "--fog", "exp:density=0.1",
              "--fog-color", ",".join(repr(c) for c in flags["fog_color"])]
    by_flags = d + "/flags.exr"
    run([exrfog, render, "-o", by_flags, "--camera-convention", "blender", "--camera-to-world",
         ",".join(repr(v) for v in flags["camera_to_world"]), "--fov", repr(flags["fov"]),
         "--near", repr(flags["near"]), "--far", repr(flags["far"])] + common)
    if not same_pixels(fogged, by_flags):
        raise SystemExit("blender_addon: FAILED: the add-on's frame differs from the flags run")
    by_file = d + "/cf_0001.exr"
    run([exrfog, d + "/render_#.exr", "--frames", "1", "-o", d + "/cf_#.exr", "--camera-file",
         d + "/cams.json"] + common)
    if not same_pixels(fogged, by_file):
        raise SystemExit("blender_addon: FAILED: the camera file run differs")
    # the fog really did something
    r = subprocess.run(["oiiotool", "--diff", render, fogged], capture_output=True, text=True)
    if "PASS" in r.stdout:
        raise SystemExit("blender_addon: FAILED: the fogged frame equals the render")
    # AOVs of a Blender multilayer render are passes of its view layer:
    # Blender itself (a CompositorNodeImage, headless) must list them.
    layer = flags["layer"]
    aov = d + "/aov.exr"
    run([exrfog, render, "-o", aov, "--aov", "fog,T,error,P,distance", "--camera-convention",
         "blender", "--camera-to-world", ",".join(repr(v) for v in flags["camera_to_world"]),
         "--fov", repr(flags["fov"]), "--near", repr(flags["near"]), "--far", repr(flags["far"])]
        + common)
    r = run(["oiiotool", "--info", "-v", aov])
    want = [layer + "." + c for c in ("Fog.R", "Fog.A", "FogT.B", "FogError.G", "FogP.X",
                                      "FogDistance.Z")]
    for c in want:
        if c not in r.stdout:
            raise SystemExit("blender_addon: FAILED: no channel %s in %s" % (c, r.stdout[-2000:]))
    if "fog_T." in r.stdout or "fog.R" in r.stdout:
        raise SystemExit("blender_addon: FAILED: Nuke-style AOV names on a Blender input")
    lister = d + "/list_passes.py"
    with open(lister, "w") as fh:
        fh.write("import bpy, sys\n"
                 "img = bpy.data.images.load(sys.argv[sys.argv.index('--') + 1])\n"
                 "bpy.context.scene.use_nodes = True\n"
                 "node = bpy.context.scene.node_tree.nodes.new('CompositorNodeImage')\n"
                 "node.image = img\n"
                 "print('PASSES:', img.type, node.layer, '|'.join(o.name for o in node.outputs))\n")
    r = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                        lister, "--", aov], capture_output=True, text=True, env=env)
    line = [l for l in r.stdout.splitlines() if l.startswith("PASSES:")]
    if r.returncode or not line:
        print(r.stdout[-3000:], r.stderr[-3000:], file=sys.stderr)
        raise SystemExit("blender_addon: FAILED: Blender could not list the passes")
    kind, _, outs = line[0].split(" ", 3)[1:]
    outs = outs.split("|")
    for p in ("Combined", "Depth", "Fog", "FogT", "FogError", "FogP", "FogDistance"):
        if p not in outs:
            raise SystemExit("blender_addon: FAILED: Blender lists %s, not %s" % (outs, p))
    if kind != "MULTILAYER":
        raise SystemExit("blender_addon: FAILED: Blender reads the output as %s" % kind)
    # A failing fog fails the render job: `blender -b scene -a` exits non-zero.
    enable = ("import sys; sys.path.insert(0, %r); import addon_utils; "
              "addon_utils.enable('exrfog_blender', default_set=True, handle_error=None)"
              % os.path.join(src, "integrations", "blender"))
    r = subprocess.run([blender, "-b", d + "/fail.blend", "--python-expr", enable, "-a"],
                       capture_output=True, text=True, env=env)
    if r.returncode == 0 or "exrfog: error: frame 1" not in r.stdout + r.stderr:
        print(r.stdout[-3000:], r.stderr[-3000:], file=sys.stderr)
        raise SystemExit("blender_addon: FAILED: a failing fog let blender -b -a exit %d"
                         % r.returncode)
    if "unknown fog model" not in r.stdout + r.stderr and "nosuchfog" not in r.stdout + r.stderr:
        raise SystemExit("blender_addon: FAILED: exrfog's reason is not in the render log")
print("blender_addon: the add-on's fog equals exrfog's with the camera by flags and by file; "
      "Blender lists the AOVs as passes")
