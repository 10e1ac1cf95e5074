"""Runs inside Blender (blender -b --factory-startup --python THIS -- OUT SPP BOUNCES DENSITY
ALBEDO G DIST WIDTH HEIGHT [wall=D]): the point lamp's multiple-scattering reference scene of
bench/ms.sh and tests/blender/blender_ms_run.py.

Homogeneous fog everywhere that matters (a cube 4 km wide about the camera: Volume Scatter of
density DENSITY * ALBEDO with HG anisotropy G plus Volume Absorption of the rest), a black
world, the camera at the origin looking along +y with a 60 degree field of view, and a point
lamp of 100 W (radius 0: I = 100 / (4 pi) W/sr) DIST units ahead, 0.15 DIST to the right and
0.1 DIST up (its own optical depth to the camera is about DENSITY * DIST). With wall=D, a
black wall (it only absorbs) D units ahead covers the frame's left half, between the camera
and the lamp when D < DIST: the glow must stop at it (no halo). BOUNCES volume bounces (0:
single scattering; 128: every order), max bounces as many, transparent bounces at their
default; BOUNCES -1: no fog (the depth alone). Writes OUT (RGBA + Z, 32-bit) and OUT.json
(camera, lamp position and intensity)."""
import json
import math
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1:]
out, spp, bounces = args[0], int(args[1]), int(args[2])
plain = bounces < 0
bounces = max(bounces, 0)
dens, albedo, g, dist = (float(v) for v in args[3:7])
width, height = int(args[7]), int(args[8])
wall = float(next((a[5:] for a in args[9:] if a.startswith("wall=")), "0"))
sc = bpy.context.scene
for o in list(bpy.data.objects):
    if o.type in ('MESH', 'LIGHT'):
        bpy.data.objects.remove(o, do_unlink=True)
sc.render.engine = 'CYCLES'
sc.cycles.device = 'CPU'
sc.cycles.samples = spp
sc.cycles.use_denoising = False
sc.cycles.use_adaptive_sampling = False
sc.cycles.max_bounces = max(bounces, 1)
sc.cycles.volume_bounces = bounces
sc.cycles.diffuse_bounces = 0
sc.cycles.glossy_bounces = 0
sc.cycles.transmission_bounces = 0
sc.cycles.sample_clamp_direct = 0
sc.cycles.sample_clamp_indirect = 0
sc.cycles.seed = 7
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = width, height, 100
sc.render.image_settings.file_format = 'OPEN_EXR'
sc.render.image_settings.color_depth = '32'
sc.render.image_settings.use_zbuffer = True
bpy.context.view_layer.use_pass_z = True
sc.render.film_transparent = False
w = bpy.data.worlds.new("black"); w.use_nodes = True
w.node_tree.nodes["Background"].inputs[1].default_value = 0.0
sc.world = w
if wall > 0:
    # a black wall covering the left half of the frame: x from -4000 to 0 at y = wall
    bpy.ops.mesh.primitive_plane_add(size=1, location=(-2000, wall, 0), rotation=(math.radians(90), 0, 0))
    wo = bpy.context.object
    wo.scale = (4000, 4000, 1)
    wm = bpy.data.materials.new("wall"); wm.use_nodes = True
    wm.node_tree.nodes.clear()
    e = wm.node_tree.nodes.new('ShaderNodeEmission'); e.inputs[1].default_value = 0.0
    o = wm.node_tree.nodes.new('ShaderNodeOutputMaterial')
    wm.node_tree.links.new(e.outputs[0], o.inputs[0])
    wo.data.materials.append(wm)
bpy.ops.mesh.primitive_cube_add(size=4000, location=(0, 0, 0))
cube = bpy.context.object
if plain:
    cube.hide_render = True
m = bpy.data.materials.new("fog"); m.use_nodes = True
nt = m.node_tree; nt.nodes.clear()
s = nt.nodes.new('ShaderNodeVolumeScatter')
s.inputs['Density'].default_value = dens * albedo
s.inputs['Anisotropy'].default_value = g
s.inputs['Color'].default_value = (1, 1, 1, 1)
a = nt.nodes.new('ShaderNodeVolumeAbsorption')
a.inputs['Density'].default_value = dens * (1 - albedo)
a.inputs['Color'].default_value = (0, 0, 0, 1)
add = nt.nodes.new('ShaderNodeAddShader')
o = nt.nodes.new('ShaderNodeOutputMaterial')
nt.links.new(s.outputs[0], add.inputs[0]); nt.links.new(a.outputs[0], add.inputs[1])
nt.links.new(add.outputs[0], o.inputs['Volume'])
m.cycles.homogeneous_volume = True
m.cycles.volume_sampling = 'MULTIPLE_IMPORTANCE'
cube.data.materials.append(m)
pos = (0.15 * dist, dist, 0.1 * dist)
pl = bpy.data.lights.new("lamp", 'POINT'); pl.energy = 100.0; pl.shadow_soft_size = 0.0
po = bpy.data.objects.new("lamp", pl); sc.collection.objects.link(po)
po.location = pos
cam = sc.camera
cam.location = (0, 0, 0)
cam.rotation_euler = (math.radians(90), 0, 0)
cam.data.sensor_fit = 'HORIZONTAL'
cam.data.angle = math.radians(60)
cam.data.clip_start, cam.data.clip_end = 0.05, 10000.0
bpy.context.view_layer.update()
sc.render.filepath = out
bpy.ops.render.render(write_still=True)
mw = cam.matrix_world
json.dump({"c2w": [mw[i][j] for i in range(4) for j in range(4)], "fov": math.degrees(cam.data.angle_x),
           "near": cam.data.clip_start, "far": cam.data.clip_end, "lamp": list(pos),
           "intensity": 100.0 / (4 * math.pi)}, open(out + ".json", "w"))
print("ms_lamp_blender: rendered")
