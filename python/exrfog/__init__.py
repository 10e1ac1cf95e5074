"""exrfog: physically correct fog for rendered OpenEXR images, from Python.

A thin ctypes binding of libexrfog (include/exrfog.h); it needs nothing
beyond the Python standard library, and numpy for fog_pixels().

    import exrfog
    exrfog.fog("beauty.exr", "fogged.exr", fog=["exp:density=0.02"], fog_color=(0.6, 0.65, 0.7))
    facts = exrfog.explain("beauty.exr")          # dict: camera per view, channels, ...
    out = exrfog.fog_pixels(rgb, alpha, depth, camera, ["exp:density=0.02"])

Options are the command line's long options with '_' for '-'
(fog_color=, depth_mode=, threads=, view=[...], preview=...); True turns a
flag on, None or False leaves it out, a list of strings repeats the option
and a list of numbers is written R,G,B style. Failures raise exrfog.Error
with the command line's message; the run's warnings (a Nuke 1/z depth, a
V-Ray Z-up camera, a view left unfogged) are issued through Python's
warnings module as exrfog.Warning. Every call may run from any number of
threads at once, and Ctrl-C during a call raises KeyboardInterrupt within a
second, leaving no output and no temporary file. The library is found through
$EXRFOG_LIBRARY, then beside the installed module, then the system's
loader (libexrfog.so.0).
"""

import ctypes
import ctypes.util
import json
import os
import threading
import warnings

__all__ = ["Error", "Warning", "fog", "explain", "fog_pixels", "version", "library_version"]

version = "0.1.0"


class Error(Exception):
    """A failed exrfog call; str(e) is the command line's message
    ("FILE: what is wrong (how to fix it)"), e.status its exit status."""

    def __init__(self, message, status=1):
        super().__init__(message)
        self.status = status


class Warning(UserWarning):  # noqa: A001 (the name scripts filter on)
    """A warning of an exrfog run, as the command line prints it after
    "exrfog: FILE: warning: "."""


def _load():
    names = []
    env = os.environ.get("EXRFOG_LIBRARY")
    if env:
        names.append(env)
    try:
        from . import _paths  # written by cmake --install
        names.append(os.path.join(os.path.dirname(__file__), _paths.LIBRARY))
    except ImportError:
        pass
    names.append("libexrfog.so.0")
    found = ctypes.util.find_library("exrfog")
    if found:
        names.append(found)
    errors = []
    for n in names:
        try:
            return ctypes.CDLL(n)
        except OSError as e:
            errors.append(str(e))
    raise ImportError("exrfog: cannot load libexrfog (set EXRFOG_LIBRARY to its path): "
                      + "; ".join(errors))


_lib = _load()
_ctx_p = ctypes.c_void_p
_lib.exrfog_version.restype = ctypes.c_char_p
_lib.exrfog_context_create.restype = _ctx_p
_lib.exrfog_context_destroy.argtypes = [_ctx_p]
_lib.exrfog_error.restype = ctypes.c_char_p
_lib.exrfog_error.argtypes = [_ctx_p]
_lib.exrfog_set_print.argtypes = [_ctx_p, ctypes.c_int]
_argv_t = ctypes.POINTER(ctypes.c_char_p)
_lib.exrfog_run.argtypes = [_ctx_p, ctypes.c_int, _argv_t]
_lib.exrfog_explain.argtypes = [_ctx_p, ctypes.c_int, _argv_t, ctypes.POINTER(ctypes.c_void_p)]
_lib.exrfog_free.argtypes = [ctypes.c_void_p]
_PROGRESS = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double)
_lib.exrfog_set_progress.argtypes = [_ctx_p, _PROGRESS, ctypes.c_void_p]
_WARNING = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_char_p)
_lib.exrfog_set_warning.argtypes = [_ctx_p, _WARNING, ctypes.c_void_p]
_lib.exrfog_cancel.argtypes = [_ctx_p]
_lib.exrfog_cancel.restype = None
_lib.exrfog_scene_create.argtypes = [_ctx_p, _argv_t, ctypes.c_int, ctypes.c_char_p,
                                     ctypes.POINTER(ctypes.c_double), ctypes.POINTER(_ctx_p)]
_lib.exrfog_scene_destroy.argtypes = [_ctx_p]
_lib.exrfog_camera_from_matrix.argtypes = [_ctx_p, ctypes.POINTER(ctypes.c_double), ctypes.c_char_p,
                                           ctypes.c_double, ctypes.POINTER(ctypes.c_int),
                                           ctypes.POINTER(_ctx_p)]
_lib.exrfog_camera_from_file.argtypes = [_ctx_p, ctypes.c_char_p, ctypes.POINTER(_ctx_p)]
_lib.exrfog_camera_destroy.argtypes = [_ctx_p]
_lib.exrfog_fog_pixels.argtypes = [_ctx_p, _ctx_p, _ctx_p, ctypes.c_void_p]
_lib.exrfog_scene_light_count.argtypes = [_ctx_p]
_lib.exrfog_scene_light_name.argtypes = [_ctx_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
_lib.exrfog_scene_light_name.restype = ctypes.c_char_p
_lib.exrfog_scene_has_sky_light.argtypes = [_ctx_p]


def library_version():
    """The version of the libexrfog actually loaded."""
    return _lib.exrfog_version().decode()


class _Context:
    def __init__(self):
        self.p = _lib.exrfog_context_create()
        if not self.p:
            raise MemoryError("exrfog: out of memory")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        _lib.exrfog_context_destroy(self.p)

    def check(self, status):
        if status != 0:
            raise Error(_lib.exrfog_error(self.p).decode("utf-8", "replace"), status)


def _text(s):
    """s as a C string: refused, as open() refuses a name, where a NUL
    would cut it short (C would see a shorter word)."""
    b = s.encode() if isinstance(s, str) else bytes(s)
    if b"\0" in b:
        raise ValueError("embedded null byte")
    return b


def _argv(args):
    enc = [a.encode() if isinstance(a, str) else os.fsencode(a) for a in args]
    for a in enc:
        if b"\0" in a:
            # as open() does: C would see a shorter name, another file
            raise ValueError("embedded null byte")
    arr = (ctypes.c_char_p * (len(enc) + 1))(*enc, None)
    return len(enc), arr


def _operand(path):
    """A file name as the command line's INPUT: one starting with '-'
    ("-in.exr", "--help") is a file, not an option, so it goes in as
    ./NAME (the same file; the command line reads it as the user typed
    it otherwise, and the output's exrfog/history records it so)."""
    p = os.fspath(path)
    if isinstance(p, bytes):
        return b"./" + p if p.startswith(b"-") else p
    return "./" + p if p.startswith("-") else p


def _options(options):
    """The command line's spelling of keyword options."""
    args = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            args.append(flag)
        elif isinstance(value, (list, tuple)):
            if value and all(isinstance(v, str) for v in value):
                for v in value:
                    args += [flag, v]
            else:
                args += [flag, ",".join(repr(float(v)) for v in value)]
        else:
            args += [flag, str(value)]
    return args


def _fog_args(fog, scene):
    args = []
    for spec in ([fog] if isinstance(fog, str) else (fog or [])):
        args += ["--fog", spec]
    if scene is not None:
        args += ["--scene", os.fspath(scene)]
    return args


def _call(ctx, fn, *args):
    """Runs fn(*args) (a job of ctx) on a thread of its own while this one
    waits, so that Ctrl-C reaches Python at once: the job is then cancelled
    (it removes its temporary files and writes nothing) and
    KeyboardInterrupt raised. The job's warnings are issued here, on the
    caller's thread. Returns fn's result."""
    said = []

    def on_warning(user, file, text):
        said.append((file or b"").decode("utf-8", "replace") + ": " +
                    (text or b"").decode("utf-8", "replace"))

    cb = _WARNING(on_warning)
    _lib.exrfog_set_warning(ctx.p, cb, None)
    result = []
    done = threading.Event()

    def work():
        try:
            result.append(fn(*args))
        finally:
            done.set()

    # an Event, not Thread.join: a join interrupted by Ctrl-C can mark the
    # thread finished while it still runs (CPython before 3.13)
    threading.Thread(target=work, daemon=True).start()
    try:
        while not done.wait(0.05):
            pass
    except BaseException:
        _lib.exrfog_cancel(ctx.p)
        while not done.wait(0.05):
            pass
        raise
    finally:
        for w in said:
            warnings.warn(w, Warning, stacklevel=3)
    return result[0]


def fog(input, output, fog=None, scene=None, progress=None, **options):
    """Fogs INPUT into OUTPUT as `exrfog INPUT -o OUTPUT ...` does: fog is a
    SPEC or a list of them, scene a scene file, options the command line's
    (sequences, views, colour, formats included). progress(fraction) hears
    the fraction done after every chunk and frame (1.0 at the end) and may
    return True to cancel (Error with status 3, nothing written)."""
    args = ["exrfog", _operand(input), "-o", os.fspath(output)] + _fog_args(fog, scene)
    args += _options(options)
    n, argv = _argv(args)
    with _Context() as ctx:
        cb = None
        if progress is not None:
            cb = _PROGRESS(lambda user, f: 1 if progress(f) else 0)
            _lib.exrfog_set_progress(ctx.p, cb, None)
        ctx.check(_call(ctx, _lib.exrfog_run, ctx.p, n, argv))


def explain(path, fog=None, scene=None, **options):
    """What exrfog reads in PATH and would do (`exrfog --explain --json`),
    as a dict: the camera of each view, the channels, the depth, the scene
    and the working colour space. Nothing is written."""
    args = ["exrfog", _operand(path)] + _fog_args(fog, scene) + _options(options)
    n, argv = _argv(args)
    with _Context() as ctx:
        out = ctypes.c_void_p()
        ctx.check(_call(ctx, _lib.exrfog_explain, ctx.p, n, argv, ctypes.byref(out)))
        try:
            return json.loads(ctypes.string_at(out).decode("utf-8", "replace"))
        finally:
            _lib.exrfog_free(out)


class _Image(ctypes.Structure):
    _fields_ = [("size", ctypes.c_size_t), ("x0", ctypes.c_int), ("y0", ctypes.c_int),
                ("width", ctypes.c_int), ("height", ctypes.c_int), ("stride", ctypes.c_ssize_t),
                ("rgb", ctypes.c_void_p * 3), ("alpha", ctypes.c_void_p),
                ("depth", ctypes.c_void_p), ("depth_mode", ctypes.c_char_p),
                ("T", ctypes.c_void_p * 3), ("error", ctypes.c_void_p * 3),
                ("P", ctypes.c_void_p * 3), ("ambient", ctypes.c_void_p * 3),
                ("light", ctypes.POINTER(ctypes.c_void_p)), ("sky", ctypes.c_void_p * 3),
                ("lit", ctypes.POINTER(ctypes.c_void_p))]


def fog_pixels(rgb, alpha, depth, camera, scene, color=None, depth_mode=None, origin=(0, 0),
               layers=False):
    """Fogs pixels in memory (numpy arrays), no file involved.

    rgb: H x W x 3, alpha: H x W or None, depth: H x W (planar camera depth
    unless depth_mode says otherwise). camera: a path to an EXR whose header
    holds the camera, or a dict with "camera_to_world" (16 numbers),
    "fov" (horizontal degrees), optional "convention" ("exr", "blender",
    "nuke", "maya", "houdini", "usd") and "display_window" (xmin, ymin,
    xmax, ymax; default the array's size at origin). scene: a SPEC or a
    list of them, or a dict {"fog": [...], "scene": path}. origin: the
    absolute (x, y) of pixel [0, 0]. Returns a dict of float32 arrays:
    rgb, alpha, T (transmittance), error (its bound), P (world position).
    layers=True (a scene with lights): also "ambient" (H x W x 3), "lights"
    {NAME: H x W x 3} per light, "sky" (H x W x 3, with a sky light) and
    "lit" {NAME: H x W} per shadowed light, as --aov light,lit writes them;
    ambient, the lights and sky sum to the fog's colour."""
    import numpy as np
    rgb = np.array(rgb, dtype=np.float32, copy=True, order="C")
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise Error("fog_pixels: rgb must be H x W x 3", 2)
    h, w = rgb.shape[:2]
    planes = [np.ascontiguousarray(rgb[:, :, k]) for k in range(3)]
    a = None if alpha is None else np.array(alpha, dtype=np.float32, copy=True, order="C")
    d = np.ascontiguousarray(depth, dtype=np.float32)
    if d.shape != (h, w) or (a is not None and a.shape != (h, w)):
        raise Error("fog_pixels: depth (and alpha) must be H x W like rgb", 2)
    T = [np.zeros((h, w), np.float32) for _ in range(3)]
    E = [np.zeros((h, w), np.float32) for _ in range(3)]
    P = [np.zeros((h, w), np.float32) for _ in range(3)]
    if isinstance(scene, str):
        specs, scene_file, colour = [scene], None, color
    elif isinstance(scene, dict):
        specs, scene_file, colour = scene.get("fog", []), scene.get("scene"), scene.get("color", color)
    else:
        specs, scene_file, colour = list(scene), None, color
    if colour is not None and len(colour) != 3:
        raise Error("fog_pixels: color must be 3 numbers (R, G, B), not %d" % len(colour), 2)
    with _Context() as ctx:
        sc, cam = _ctx_p(), _ctx_p()
        n, argv = _argv(specs)
        col = (ctypes.c_double * 3)(*colour) if colour is not None else None
        if scene_file is not None and b"\0" in os.fsencode(scene_file):
            raise ValueError("embedded null byte")
        ctx.check(_lib.exrfog_scene_create(ctx.p, argv, n,
                                           os.fsencode(scene_file) if scene_file else None,
                                           col, ctypes.byref(sc)))
        try:
            if isinstance(camera, (str, bytes, os.PathLike)):
                if b"\0" in os.fsencode(camera):
                    raise ValueError("embedded null byte")
                ctx.check(_lib.exrfog_camera_from_file(ctx.p, os.fsencode(camera), ctypes.byref(cam)))
            else:
                m = (ctypes.c_double * 16)(*camera["camera_to_world"])
                win = camera.get("display_window", (origin[0], origin[1], origin[0] + w - 1,
                                                    origin[1] + h - 1))
                if len(win) != 4:
                    raise Error("fog_pixels: display_window must be 4 numbers (xmin, ymin, "
                                "xmax, ymax), not %d" % len(win), 2)
                if len(camera["camera_to_world"]) != 16:
                    raise Error("fog_pixels: camera_to_world must be 16 numbers", 2)
                ctx.check(_lib.exrfog_camera_from_matrix(
                    ctx.p, m, _text(camera.get("convention", "exr")), float(camera["fov"]),
                    (ctypes.c_int * 4)(*win), ctypes.byref(cam)))
            img = _Image()
            img.size = ctypes.sizeof(_Image)
            img.x0, img.y0, img.width, img.height, img.stride = origin[0], origin[1], w, h, w
            for k in range(3):
                img.rgb[k] = planes[k].ctypes.data
                img.T[k] = T[k].ctypes.data
                img.error[k] = E[k].ctypes.data
                img.P[k] = P[k].ctypes.data
            img.alpha = a.ctypes.data if a is not None else None
            img.depth = d.ctypes.data
            img.depth_mode = _text(depth_mode) if depth_mode else None
            extra = {}
            if layers:
                nl = _lib.exrfog_scene_light_count(sc)
                names, shadowed = [], []
                for j in range(nl):
                    sh = ctypes.c_int(0)
                    names.append(_lib.exrfog_scene_light_name(sc, j, ctypes.byref(sh)).decode())
                    shadowed.append(sh.value != 0)
                amb = [np.zeros((h, w), np.float32) for _ in range(3)]
                lp = [[np.zeros((h, w), np.float32) for _ in range(3)] for _ in range(nl)]
                lit = [np.ones((h, w), np.float32) if shadowed[j] else None for j in range(nl)]
                sky = [np.zeros((h, w), np.float32) for _ in range(3)]
                larr = (ctypes.c_void_p * max(1, 3 * nl))(
                    *[lp[j][k].ctypes.data for j in range(nl) for k in range(3)])
                tarr = (ctypes.c_void_p * max(1, nl))(
                    *[lit[j].ctypes.data if shadowed[j] else None for j in range(nl)])
                for k in range(3):
                    img.ambient[k] = amb[k].ctypes.data
                    img.sky[k] = sky[k].ctypes.data
                img.light = ctypes.cast(larr, ctypes.POINTER(ctypes.c_void_p))
                img.lit = ctypes.cast(tarr, ctypes.POINTER(ctypes.c_void_p))
            # on a thread of its own, as a run: Ctrl-C cancels it at once
            ctx.check(_call(ctx, _lib.exrfog_fog_pixels, ctx.p, sc, cam, ctypes.byref(img)))
            if layers:
                extra = {"ambient": np.stack(amb, axis=2),
                         "lights": {names[j]: np.stack(lp[j], axis=2) for j in range(nl)},
                         "lit": {names[j]: lit[j] for j in range(nl) if shadowed[j]}}
                if _lib.exrfog_scene_has_sky_light(sc):
                    extra["sky"] = np.stack(sky, axis=2)
        finally:
            _lib.exrfog_camera_destroy(cam)
            _lib.exrfog_scene_destroy(sc)
    return dict({"rgb": np.stack(planes, axis=2), "alpha": a, "T": np.stack(T, axis=2),
                 "error": np.stack(E, axis=2), "P": np.stack(P, axis=2)}, **extra)
