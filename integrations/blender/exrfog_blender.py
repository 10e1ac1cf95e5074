"""exrfog for Blender: physically correct fog on renders, with Blender's camera.

Blender writes no camera into its EXRs. This add-on hands the scene camera
to exrfog in Blender's own convention (matrix_world as Blender prints it,
the lens and sensor fit as a horizontal field of view, the clip range):

* after each render written as a multilayer EXR with the Depth pass, the
  frame is fogged into the output path set in the panel (Output
  Properties > exrfog), when "Fog after render" is on. The path follows
  Blender's rule (the last run of '#' is the frame, zero-padded to its
  width; no '#': 4 digits added) and its directories are created. A
  failing fog shows its error in the UI; in background mode
  (blender -b ... -a, a farm) it stops the render with exit status 1;
* "Fog EXR" fogs a chosen EXR with the current frame's camera;
* "Write camera file" writes a camera file (exrfog --camera-file) for the
  frame range, so any later exrfog run finds the cameras;
* "Render shadow map" renders the active sun's or spot's shadow map in one
  step: the depth of the scene seen from the light (orthographic along a
  sun's light, from a camera "Sun map distance" back along it from the sun
  object over "Sun map width" units; perspective from a spot over its
  cone), written as MAP.exr with its camera in MAP.exr.json (exrfog's
  camera-file form, shadow-camera=), and the --light SPEC that uses both
  (shown in the panel and added to "Extra options" when asked).

The fog (exrfog SPECs), its colour and extra options are stored in the
.blend. exrfog is run as a program (the "exrfog program" setting, default
exrfog on PATH).
"""

bl_info = {
    "name": "exrfog",
    "author": "exrfog",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Output > exrfog",
    "description": "Physically correct fog on renders with exrfog, using the scene camera",
    "category": "Render",
}

import json
import math
import os
import shlex
import subprocess

import bpy
from bpy.app.handlers import persistent


def horizontal_fov(scene, cam):
    """The horizontal field of view (degrees) of a perspective camera as
    Blender frames it: the sensor fit decides which side the sensor width
    (or height) spans, on the render's pixel-aspect-corrected size."""
    r = scene.render
    w = r.resolution_x * r.pixel_aspect_x
    h = r.resolution_y * r.pixel_aspect_y
    d = cam.data
    if d.type != 'PERSP':
        raise ValueError("exrfog needs a perspective camera (this one is %s)" % d.type)
    fit = d.sensor_fit
    if fit == 'AUTO':
        fit = 'HORIZONTAL' if w >= h else 'VERTICAL'
        size = d.sensor_width
    else:
        size = d.sensor_width if fit == 'HORIZONTAL' else d.sensor_height
    half = math.atan(size / (2.0 * d.lens))
    if fit == 'HORIZONTAL':
        return math.degrees(2.0 * half)
    return math.degrees(2.0 * math.atan(math.tan(half) * w / h))


def camera_entry(scene, cam):
    """One frame's camera in exrfog's camera-file form (Blender convention)."""
    m = cam.matrix_world
    return {
        "camera_to_world": [m[i][j] for i in range(4) for j in range(4)],
        "fov": horizontal_fov(scene, cam),
        "near": cam.data.clip_start,
        "far": cam.data.clip_end,
    }


def camera_args(scene, cam):
    """exrfog's flags for the camera at the current frame."""
    e = camera_entry(scene, cam)
    if abs(cam.data.shift_x) > 0 or abs(cam.data.shift_y) > 0:
        print("exrfog: warning: the camera's lens shift is ignored (exrfog's pinhole is centred)")
    return ["--camera-convention", "blender",
            "--camera-to-world", ",".join(repr(v) for v in e["camera_to_world"]),
            "--fov", repr(e["fov"]), "--near", repr(e["near"]), "--far", repr(e["far"])]


def light_spec(light, map_path=None):
    """exrfog's --light SPEC for a Blender sun or spot (world axes as
    Blender's, the add-on's runs use --up-axis z): a sun's strength is
    irradiance (W/m^2), a spot's power P watts is I = P / (4 pi) W/sr as for
    a point lamp (Cycles), its cone its spot_size. With map_path, the light's
    shadow map and its camera file."""
    d = light.data
    col = ",".join(repr(c) for c in d.color)
    m = light.matrix_world
    if d.type == 'SUN':
        t = m.col[2]
        spec = "sun:towards=%r,%r,%r:color=%s:intensity=%r" % (t[0], t[1], t[2], col, d.energy)
        if d.angle > 0:
            spec += ":angle=%r" % math.degrees(d.angle)
    elif d.type == 'SPOT':
        p, a = m.col[3], -m.col[2]
        spec = ("spot:position=%r,%r,%r:aim=%r,%r,%r:cone=%r:blend=%r:color=%s:intensity=%r"
                % (p[0], p[1], p[2], a[0], a[1], a[2], math.degrees(d.spot_size), d.spot_blend,
                   col, d.energy / (4 * math.pi)))
        if bpy.app.version < (4, 0, 0):
            # Cycles 3.x's spots also fall as cos alpha inside the cone
            # (tests/blender/blender_lit_run.py measures it)
            spec += ":cosine=1"
    else:
        raise ValueError("a shadow map is for a sun or a spot (this light is %s)" % d.type)
    if map_path:
        spec += ":shadow=%s:shadow-camera=%s.json" % (map_path, map_path)
    return spec


def render_shadow_map(scene, light, path, size, width, distance):
    """Renders light's shadow map into path (an EXR with Z) and its camera
    into path.json; returns the --light SPEC. The scene's camera, render
    settings and engine are restored afterwards."""
    d = light.data
    if d.type not in ('SUN', 'SPOT'):
        raise ValueError("a shadow map is for a sun or a spot (this light is %s)" % d.type)
    cam_data = bpy.data.cameras.new("exrfog_shadow_map")
    cam = bpy.data.objects.new("exrfog_shadow_map", cam_data)
    scene.collection.objects.link(cam)
    m = light.matrix_world
    cam.matrix_world = m.copy()
    if d.type == 'SUN':
        # back along the light from the sun object, looking down the light
        t = m.col[2]
        cam.location = (m.col[3][0] + distance * t[0], m.col[3][1] + distance * t[1],
                        m.col[3][2] + distance * t[2])
        cam_data.type = 'ORTHO'
        cam_data.ortho_scale = width
        cam_data.clip_end = max(2 * distance, 1000.0)
    else:
        cam_data.type = 'PERSP'
        cam_data.sensor_fit = 'HORIZONTAL'
        cam_data.angle = min(d.spot_size, math.radians(170))
        cam_data.clip_end = 1e5
    cam_data.clip_start = 1e-3
    r = scene.render
    img = r.image_settings
    keep = (scene.camera, r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage,
            r.pixel_aspect_x, r.pixel_aspect_y, r.filepath, r.use_border, img.file_format,
            img.color_depth, img.use_zbuffer, scene.cycles.samples, r.film_transparent)
    layer = bpy.context.view_layer
    keep_z = layer.use_pass_z
    try:
        scene.camera = cam
        r.engine = 'CYCLES'
        scene.cycles.samples = 1
        r.resolution_x = r.resolution_y = size
        r.resolution_percentage = 100
        r.pixel_aspect_x = r.pixel_aspect_y = 1
        r.use_border = False
        r.film_transparent = False
        img.file_format = 'OPEN_EXR'
        img.color_depth = '32'
        img.use_zbuffer = True
        layer.use_pass_z = True
        r.filepath = path
        bpy.context.view_layer.update()
        bpy.ops.render.render(write_still=True)
        cm = cam.matrix_world
        entry = {"camera_to_world": [cm[i][j] for i in range(4) for j in range(4)]}
        if d.type == 'SUN':
            entry["ortho_width"] = cam_data.ortho_scale
        else:
            entry["fov"] = math.degrees(cam_data.angle_x)
        with open(path + ".json", "w") as fh:
            json.dump({"convention": "blender", "frames": {str(scene.frame_current): entry}},
                      fh, indent=1)
    finally:
        (scene.camera, r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage,
         r.pixel_aspect_x, r.pixel_aspect_y, r.filepath, r.use_border, img.file_format,
         img.color_depth, img.use_zbuffer, scene.cycles.samples, r.film_transparent) = keep
        layer.use_pass_z = keep_z
        bpy.data.objects.remove(cam, do_unlink=True)
        bpy.data.cameras.remove(cam_data)
    if not os.path.exists(path):
        raise RuntimeError("Blender did not write the shadow map " + path)
    return light_spec(light, path)


def exrfog_command(scene, input_path, output_path):
    """The exrfog command line for a multilayer EXR of this scene."""
    s = scene.exrfog
    layer = bpy.context.view_layer.name if bpy.context.view_layer else scene.view_layers[0].name
    args = [s.program, input_path, "-o", output_path,
            "--layer", layer + ".Combined", "--depth-channel", layer + ".Depth.Z",
            "--up-axis", "z", "--units-per-meter", repr(1.0 / scene.unit_settings.scale_length)]
    args += camera_args(scene, scene.camera)
    for spec in s.fog.split():
        args += ["--fog", spec]
    args += ["--fog-color", ",".join(repr(c) for c in s.fog_color)]
    args += shlex.split(s.extra)
    return args


def run_exrfog(args):
    """Runs exrfog; raises RuntimeError with its message on failure."""
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(r.stderr.strip() or "exrfog exited %d" % r.returncode)
    return r


def frame_path(path, frame):
    """Blender's output-path rule: the last run of '#' becomes the frame,
    zero-padded to the run's width (fog_##.exr -> fog_07.exr); a path with
    no '#' gets the frame in 4 digits before its .exr (fog.exr ->
    fog0007.exr, fog -> fog0007.exr)."""
    head, sep, name = path.rpartition("/")
    end = name.rfind("#")
    if end >= 0:
        start = end
        while start > 0 and name[start - 1] == "#":
            start -= 1
        width = end - start + 1
        digits = ("-%0*d" % (width - 1, -frame)) if frame < 0 else "%0*d" % (width, frame)
        name = name[:start] + digits + name[end + 1:]
    else:
        stem = name[:-4] if name.lower().endswith(".exr") else name
        name = stem + ("-%03d" % -frame if frame < 0 else "%04d" % frame) + ".exr"
    return head + sep + name


def fog_output_path(scene, frame):
    """The fogged frame's path (Blender's '#' rule), its directory created."""
    path = frame_path(bpy.path.abspath(scene.exrfog.output), frame)
    d = os.path.dirname(path)
    if d:
        os.makedirs(d, exist_ok=True)
    return path


# The last failure of the after-render fog, shown in the panel.
LAST_ERROR = ""


def show_error(message):
    """The error in the UI, from the main thread (a timer): a popup, and
    the panel keeps it until the next success."""
    def popup():
        def draw(menu, context):
            for line in message.splitlines()[:6]:
                menu.layout.label(text=line[:200])
        wm = bpy.context.window_manager
        if wm is not None and wm.windows:
            wm.popup_menu(draw, title="exrfog failed", icon='ERROR')
        return None
    bpy.app.timers.register(popup, first_interval=0.1)


class ExrfogSettings(bpy.types.PropertyGroup):
    enabled: bpy.props.BoolProperty(
        name="Fog after render", default=False,
        description="Fog every rendered multilayer EXR (with the Depth pass) into the output path")
    program: bpy.props.StringProperty(name="exrfog program", default="exrfog",
                                      description="The exrfog executable")
    fog: bpy.props.StringProperty(
        name="Fog", default="exp:density=0.02",
        description="exrfog fog SPECs, separated by spaces (see exrfog(1))")
    fog_color: bpy.props.FloatVectorProperty(name="Fog colour", subtype='COLOR', size=3,
                                             default=(0.7, 0.75, 0.8), min=0.0)
    output: bpy.props.StringProperty(name="Output", default="//fog_####.exr", subtype='FILE_PATH',
                                     description="Where fogged frames go: the last run of # is "
                                                 "the frame, zero-padded to its width; without "
                                                 "#, 4 digits are added. Directories are created")
    extra: bpy.props.StringProperty(name="Extra options", default="",
                                    description="More exrfog options, as on a command line")
    camera_file: bpy.props.StringProperty(name="Camera file", default="//cameras.json",
                                          subtype='FILE_PATH')
    shadow_map: bpy.props.StringProperty(
        name="Shadow map", default="//shadow_{light}.exr", subtype='FILE_PATH',
        description="Where \"Render shadow map\" writes the active light's map ({light}: its "
                    "name); its camera goes beside it, in the same name plus .json")
    shadow_size: bpy.props.IntProperty(name="Map size", default=1024, min=16, max=11585,
                                       description="The shadow map's width and height in texels")
    sun_width: bpy.props.FloatProperty(
        name="Sun map width", default=100.0, min=1e-3,
        description="How much of the scene a sun's map covers across, in scene units, around "
                    "the sun object's location")
    sun_distance: bpy.props.FloatProperty(
        name="Sun map distance", default=500.0, min=0.0,
        description="How far back along the sunlight from the sun object a sun's map camera "
                    "sits: everything that casts a shadow must lie in front of it")
    add_light: bpy.props.BoolProperty(
        name="Add the light to Extra options", default=True,
        description="Append the --light SPEC with the new map to Extra options")
    last_light: bpy.props.StringProperty(name="Last shadow map's light", default="")


class EXRFOG_OT_write_camera(bpy.types.Operator):
    """Write the scene camera of every frame to an exrfog camera file"""
    bl_idname = "exrfog.write_camera"
    bl_label = "Write camera file"

    def execute(self, context):
        scene = context.scene
        keep = scene.frame_current
        frames = {}
        try:
            for f in range(scene.frame_start, scene.frame_end + 1, scene.frame_step):
                scene.frame_set(f)
                frames[str(f)] = camera_entry(scene, scene.camera)
        finally:
            scene.frame_set(keep)
        path = bpy.path.abspath(scene.exrfog.camera_file)
        with open(path, "w") as fh:
            json.dump({"convention": "blender", "frames": frames}, fh, indent=1)
        self.report({'INFO'}, "exrfog: %d cameras written to %s" % (len(frames), path))
        return {'FINISHED'}


class EXRFOG_OT_shadow_map(bpy.types.Operator):
    """Render the active sun's or spot's shadow map (depth from the light, with its camera
    file) for exrfog's shadow= and shadow-camera="""
    bl_idname = "exrfog.shadow_map"
    bl_label = "Render shadow map"

    def execute(self, context):
        scene = context.scene
        s = scene.exrfog
        light = context.active_object
        if light is None or light.type != 'LIGHT':
            self.report({'ERROR'}, "exrfog: select a sun or a spot light first")
            return {'CANCELLED'}
        path = bpy.path.abspath(s.shadow_map.replace("{light}", bpy.path.clean_name(light.name)))
        folder = os.path.dirname(path)
        try:
            if folder:
                os.makedirs(folder, exist_ok=True)
            spec = render_shadow_map(scene, light, path, s.shadow_size, s.sun_width,
                                     s.sun_distance)
        except (RuntimeError, ValueError, OSError) as e:
            self.report({'ERROR'}, "exrfog: " + str(e))
            return {'CANCELLED'}
        s.last_light = spec
        if s.add_light:
            s.extra = (s.extra + " " if s.extra.strip() else "") + shlex.join(["--light", spec])
        self.report({'INFO'}, "exrfog: shadow map written to %s; --light %s" % (path, spec))
        return {'FINISHED'}


class EXRFOG_OT_fog_file(bpy.types.Operator):
    """Fog a multilayer EXR of this scene with the current frame's camera"""
    bl_idname = "exrfog.fog_file"
    bl_label = "Fog EXR"
    filepath: bpy.props.StringProperty(subtype='FILE_PATH')

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        scene = context.scene
        out = fog_output_path(scene, scene.frame_current)
        try:
            run_exrfog(exrfog_command(scene, self.filepath, out))
        except (RuntimeError, ValueError, OSError) as e:
            self.report({'ERROR'}, str(e))
            return {'CANCELLED'}
        self.report({'INFO'}, "exrfog: wrote " + out)
        return {'FINISHED'}


class EXRFOG_PT_panel(bpy.types.Panel):
    bl_label = "exrfog"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "output"

    def draw(self, context):
        s = context.scene.exrfog
        col = self.layout.column()
        if LAST_ERROR:
            box = col.box()
            for line in LAST_ERROR.splitlines()[:4]:
                box.label(text=line[:200], icon='ERROR')
        # each group of settings, then the operator that uses them
        for props, op in ((("enabled", "fog", "fog_color", "output", "extra", "program"),
                           EXRFOG_OT_fog_file),
                          (("camera_file",), EXRFOG_OT_write_camera),
                          (("shadow_map", "shadow_size", "sun_width", "sun_distance", "add_light"),
                           EXRFOG_OT_shadow_map)):
            for name in props:
                col.prop(s, name)
            col.operator(op.bl_idname)
        if s.last_light:
            col.label(text="--light " + s.last_light[:180])


@persistent
def fog_written_frame(scene, *args):
    """render_write: fog the frame Blender just wrote, when asked to."""
    s = scene.exrfog
    if not s.enabled:
        return
    if scene.render.image_settings.file_format != 'OPEN_EXR_MULTILAYER':
        print("exrfog: skipped: the render output is not a multilayer EXR")
        return
    global LAST_ERROR
    path = bpy.path.abspath(scene.render.frame_path(frame=scene.frame_current))
    try:
        out = fog_output_path(scene, scene.frame_current)
        run_exrfog(exrfog_command(scene, path, out))
        LAST_ERROR = ""
        print("exrfog: fogged %s -> %s" % (path, out))
    except (RuntimeError, ValueError, OSError) as e:
        LAST_ERROR = "frame %d: %s" % (scene.frame_current, e)
        print("exrfog: error: %s" % LAST_ERROR, flush=True)
        if bpy.app.background:
            # A farm's `blender -b ... -a` must fail: Blender ignores a
            # handler's exceptions, so the render job ends here, exit 1.
            import sys
            sys.stderr.write("exrfog: the fog failed; stopping the render with exit status 1\n")
            sys.stderr.flush()
            os._exit(1)
        show_error(LAST_ERROR)


classes = (ExrfogSettings, EXRFOG_OT_write_camera, EXRFOG_OT_shadow_map, EXRFOG_OT_fog_file,
           EXRFOG_PT_panel)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.exrfog = bpy.props.PointerProperty(type=ExrfogSettings)
    bpy.app.handlers.render_write.append(fog_written_frame)


def unregister():
    if fog_written_frame in bpy.app.handlers.render_write:
        bpy.app.handlers.render_write.remove(fog_written_frame)
    del bpy.types.Scene.exrfog
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
