"""Runs inside Blender (blender -b --factory-startup --python THIS -- OUT EXRFOG ADDON_DIR):
renders a tiny Cycles frame with the exrfog add-on enabled (fog after
render), writes the camera file, and records the camera as the test
computes it itself (Blender's angle_x, matrix_world) for the comparison
run outside Blender (tests/blender/blender_check_run.py)."""
import json
import math
import os
import sys

import addon_utils
import bpy

out_dir, exrfog_bin, addon_dir = sys.argv[sys.argv.index("--") + 1:]
sys.path.insert(0, addon_dir)
addon_utils.enable("exrfog_blender", default_set=True, handle_error=None)
assert hasattr(bpy.types.Scene, "exrfog"), "the add-on did not register"

scene = bpy.context.scene
scene.render.engine = 'CYCLES'
scene.cycles.samples = 2
scene.cycles.device = 'CPU'
scene.cycles.use_denoising = False
scene.render.resolution_x = 48
scene.render.resolution_y = 32
scene.render.resolution_percentage = 100
bpy.context.view_layer.use_pass_z = True
scene.render.image_settings.file_format = 'OPEN_EXR_MULTILAYER'
scene.render.image_settings.color_depth = '32'
scene.render.filepath = out_dir + "/render_####"
scene.frame_start = scene.frame_end = 1
scene.frame_set(1)
s = scene.exrfog
s.enabled = True
s.program = exrfog_bin
s.fog = "exp:density=0.1"
s.output = out_dir + "/fog_####.exr"
s.camera_file = out_dir + "/cams.json"
bpy.ops.render.render(animation=True)   # writes render_0001.exr, then render_write
assert bpy.ops.exrfog.write_camera() == {'FINISHED'}

# Blender's output-path rule, worked out by hand.
import exrfog_blender as eb
for path, frame, want in [("/a/fog_####.exr", 7, "/a/fog_0007.exr"), ("/a/fog_##.exr", 7, "/a/fog_07.exr"),
                          ("/a/f#_###.exr", 12, "/a/f#_012.exr"), ("/a/fog.exr", 7, "/a/fog0007.exr"),
                          ("/a/fog", 123, "/a/fog0123.exr"), ("/a/fog_#.exr", 1234, "/a/fog_1234.exr")]:
    got = eb.frame_path(path, frame)
    assert got == want, "frame_path(%r, %d) = %r, not %r" % (path, frame, got, want)
s.output = out_dir + "/sub/dir/fog_##.exr"
made = eb.fog_output_path(scene, 3)
assert made == out_dir + "/sub/dir/fog_03.exr" and os.path.isdir(out_dir + "/sub/dir"), made
s.output = out_dir + "/fog_####.exr"

cam = scene.camera
m = cam.matrix_world
with open(out_dir + "/flags.json", "w") as fh:
    json.dump({"camera_to_world": [m[i][j] for i in range(4) for j in range(4)],
               "fov": math.degrees(cam.data.angle_x),   # AUTO fit, landscape: the width's angle
               "near": cam.data.clip_start, "far": cam.data.clip_end,
               "fog_color": list(s.fog_color), "layer": bpy.context.view_layer.name}, fh)
# A scene whose fog fails, for the farm-style `blender -b ... -a` run.
s.fog = "nosuchfog:density=1"
s.output = out_dir + "/failed/fog_####.exr"
bpy.ops.wm.save_as_mainfile(filepath=out_dir + "/fail.blend", copy=True)
print("blender_check: rendered and fogged")
