"""Runs inside Blender (blender -b --factory-startup --python THIS -- OUT EXRFOG ADDON_DIR):
renders a tiny Cycles frame with the exrfog add-on enabled (fog after
render), writes the camera file, and records the camera as the test
computes it itself (Blender's angle_x, matrix_world) for the comparison
run outside Blender (tests/blender_check_run.py)."""
import json
import math
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

cam = scene.camera
m = cam.matrix_world
with open(out_dir + "/flags.json", "w") as fh:
    json.dump({"camera_to_world": [m[i][j] for i in range(4) for j in range(4)],
               "fov": math.degrees(cam.data.angle_x),   # AUTO fit, landscape: the width's angle
               "near": cam.data.clip_start, "far": cam.data.clip_end,
               "fog_color": list(s.fog_color), "layer": bpy.context.view_layer.name}, fh)
print("blender_check: rendered and fogged")
