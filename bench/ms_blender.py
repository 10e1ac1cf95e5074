"""Runs inside Blender (blender -b --factory-startup --python THIS -- OUT SPP BOUNCES ELEV
DENSITY ALBEDO G TOP WIDTH HEIGHT [LAYERS|- [sky]]): the multiple-scattering reference scene of bench/ms.sh and
tests/blender/blender_ms_run.py.

A slab of homogeneous fog (Volume Scatter of density DENSITY * ALBEDO, HG anisotropy G, plus
Volume Absorption of the rest) from the ground z = 0 to z = TOP (its box reaches 1 below), 4 km wide (so that it is
the same along the ground for what the camera sees), a black ground that only absorbs (no
emission, no BSDF: exrfog's black ground=0), a black world, a sun of strength 1 at ELEV
degrees above the horizon, the camera 2 units up looking 8 degrees down (camz=Z: Z up, and
20 degrees down when above the fog's top); sbox=X0,Y0,X1,Y1 cuts the slab to that footprint (a
box lit through its top and sides). BOUNCES volume
bounces (0: single scattering; 128: every order the issue asks for; -1: no fog, for the depth), max bounces as many,
transparent bounces left at their default. Writes OUT (RGBA + Z, 32-bit) and OUT.json (the
camera and the direction towards the sun)."""
import json
import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ms_scene  # noqa: E402

args = sys.argv[sys.argv.index("--") + 1:]
out, spp, bounces = args[0], int(args[1]), int(args[2])
plain = bounces < 0   # no fog: the depth alone (Cycles' Z inside fog is unreliable)
bounces = max(bounces, 0)
elev, dens, albedo, g, top = (float(v) for v in args[3:8])
width, height = int(args[8]), int(args[9])
# LAYERS (optional): "TOP:DENSITY:ALBEDO:G,..." replaces the slab by nested boxes from z = -1
# to each TOP, their densities adding where they overlap (exrfog: one half-space each)
layers = ([tuple(float(v) for v in l.split(":")) for l in args[10].split(",")]
          if len(args) > 10 and args[10] != "-" else [(top, dens, albedo, g)])
# "sky" (after LAYERS or "-"): a uniform sky of radiance 1 (the world), no sun
sky = "sky" in args[11:]
# "camz=Z": the camera Z units up (default 2; above TOP it looks down into the fog from above)
camz = float(next((a[5:] for a in args[11:] if a.startswith("camz=")), "2"))
# "sbox=X0,Y0,X1,Y1": the fog's box over that footprint alone (exrfog: box:min=X0,Y0,-1:max=X1,Y1,TOP)
sbox = next(([float(v) for v in a[5:].split(",")] for a in args[11:] if a.startswith("sbox=")), None)
sc = ms_scene.setup(spp, bounces, width, height, 11, 1.0 if sky else 0.0)
# the ground: black, absorbing every ray (a material with no output)
bpy.ops.mesh.primitive_plane_add(size=4000, location=(0, 0, 0))
bpy.context.object.data.materials.append(ms_scene.black())
# the fog's boxes reach below the ground (a face on the ground's plane would hide it)
for li, (ltop, ldens, lalb, lg) in enumerate(layers):
    if sbox:
        bpy.ops.mesh.primitive_cube_add(size=1, location=((sbox[0] + sbox[2]) / 2,
                                                          (sbox[1] + sbox[3]) / 2, (ltop - 1) / 2))
    else:
        bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, (ltop - 1) / 2))
    cube = bpy.context.object
    cube.scale = ((sbox[2] - sbox[0], sbox[3] - sbox[1], ltop + 1) if sbox
                  else (4000 - li, 4000 - li, ltop + 1))
    if plain:
        cube.hide_render = True
    m = ms_scene.fog("fog%d" % li, ldens, lalb, lg)
    cube.data.materials.append(m)
sun = bpy.data.lights.new("sun", 'SUN'); sun.energy = 0.0 if sky else 1.0; sun.angle = 0.0
so = bpy.data.objects.new("sun", sun); sc.collection.objects.link(so)
so.rotation_euler = (math.radians(90 - elev), 0, math.radians(150))
cam = ms_scene.camera(sc, (0, 0, camz), (82 if camz <= top else 70, 0, 0))
sc.render.filepath = out
bpy.ops.render.render(write_still=True)
mw = cam.matrix_world
t = so.matrix_world.col[2]
json.dump({"c2w": [mw[i][j] for i in range(4) for j in range(4)], "fov": math.degrees(cam.data.angle_x),
           "near": cam.data.clip_start, "far": cam.data.clip_end, "towards": [t[0], t[1], t[2]]},
          open(out + ".json", "w"))
print("ms_blender: rendered")
