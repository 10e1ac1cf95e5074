"""Runs inside Blender (blender -b --factory-startup --python THIS -- OUT SPP BOUNCES DENSITY
ALBEDO G DIST WIDTH HEIGHT [wall=D] [behind]): the point lamp's multiple-scattering reference scene of
bench/ms.sh and tests/blender/blender_ms_run.py.

Homogeneous fog everywhere that matters (a cube 4 km wide about the camera: Volume Scatter of
density DENSITY * ALBEDO with HG anisotropy G plus Volume Absorption of the rest), a black
world, the camera at the origin looking along +y with a 60 degree field of view, and a point
lamp of 100 W (radius 0: I = 100 / (4 pi) W/sr) DIST units ahead, 0.15 DIST to the right and
0.1 DIST up (its own optical depth to the camera is about DENSITY * DIST); with behind, DIST
units behind the camera instead (the frame shows only the fog it lights). With wall=D, a
black wall (it only absorbs) D units ahead covers the frame's left half, between the camera
and the lamp when D < DIST: the glow must stop at it (no halo). BOUNCES volume bounces (0:
single scattering; 128: every order), max bounces as many, transparent bounces at their
default; BOUNCES -1: no fog (the depth alone). With falloff=K, exponential height fog
instead: density DENSITY exp(-K z) over world z (up; the camera at z = 0), in a box 600 units
wide from z = -4 / K to 15 / K (e^-15 of the density at the top; below the bottom the fog is
already e^4 times denser, which takes what light reaches it), marched by Cycles in steps of
about a fiftieth of the scale height 1 / K. With spot=CONE the lamp is a spot of that cone
(degrees, blend 0.2) aimed straight down (with across, along -x: across the view), of the
same 100 W. With box=X0,Y0,Z0,X1,Y1,Z1 the homogeneous fog fills that box alone; with hs=Z, everything below z = Z.
With lay=H0/F0,H1/F1,...: layered fog, DENSITY times a factor linear between the knots (heights
increasing) and constant beyond: homogeneous below H0 (a box 4 km wide) and marched between H0
and the last knot (steps of a hundredth of the closest knots' gap), homogeneous above it
unless its factor is 0. Writes OUT (RGBA + Z, 32-bit) and OUT.json
(camera, lamp position and intensity)."""
import json
import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ms_scene  # noqa: E402

args = sys.argv[sys.argv.index("--") + 1:]
out, spp, bounces = args[0], int(args[1]), int(args[2])
plain = bounces < 0
bounces = max(bounces, 0)
dens, albedo, g, dist = (float(v) for v in args[3:7])
width, height = int(args[7]), int(args[8])
wall = float(next((a[5:] for a in args[9:] if a.startswith("wall=")), "0"))
behind = "behind" in args[9:]
falloff = float(next((a[8:] for a in args[9:] if a.startswith("falloff=")), "0"))
spot = float(next((a[5:] for a in args[9:] if a.startswith("spot=")), "0"))
# box=X0,Y0,Z0,X1,Y1,Z1: the homogeneous fog fills that box only (not 4 km)
box = next(([float(v) for v in a[4:].split(",")] for a in args[9:] if a.startswith("box=")), None)
# hs=Z: the homogeneous fog fills everything below z = Z (a half-space: a box 4 km wide)
hs = next((float(a[3:]) for a in args[9:] if a.startswith("hs=")), None)
if hs is not None:
    box = [-2000, -2000, -2000, 2000, 2000, hs]
# lay=H0/F0,H1/F1,...: layered fog (the knots' heights and density factors)
lay = next(([tuple(float(x) for x in k.split("/")) for k in a[4:].split(",")]
            for a in args[9:] if a.startswith("lay=")), None)
sc = ms_scene.setup(spp, bounces, width, height, 7)
if wall > 0:
    # a black wall covering the left half of the frame: x from -4000 to 0 at y = wall
    bpy.ops.mesh.primitive_plane_add(size=1, location=(-2000, wall, 0), rotation=(math.radians(90), 0, 0))
    wo = bpy.context.object
    wo.scale = (4000, 4000, 1)
    wo.data.materials.append(ms_scene.black())
if falloff > 0:
    zlo, zhi = -4 / falloff, 15 / falloff
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.5 * (zlo + zhi)))
    cube = bpy.context.object
    cube.scale = (600, 600, zhi - zlo)
    # Cycles' automatic step for a procedural volume is a tenth of the bounds' mean size
    step = 0.1 * (600 + 600 + zhi - zlo) / 3
    m = ms_scene.height_fog("fog", dens, albedo, g, falloff, (0.02 / falloff) / step)
    sc.cycles.volume_max_steps = 100000
elif lay:
    def slab(z0, z1):
        bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.5 * (z0 + z1)))
        c = bpy.context.object
        c.scale = (4000, 4000, z1 - z0)
        return c
    h0, hn = lay[0][0], lay[-1][0]
    if lay[0][1] > 0:
        slab(-2000, h0).data.materials.append(ms_scene.fog("fog_below", dens * lay[0][1], albedo, g))
    if lay[-1][1] > 0:
        slab(hn, 2000).data.materials.append(ms_scene.fog("fog_above", dens * lay[-1][1], albedo, g))
    cube = slab(h0, hn)
    gap = min(b[0] - a[0] for a, b in zip(lay, lay[1:]))
    step = 0.1 * (4000 + 4000 + hn - h0) / 3
    m = ms_scene.layered_fog("fog", dens, albedo, g, lay, (gap / 100) / step)
    sc.cycles.volume_max_steps = 100000
elif box:
    bpy.ops.mesh.primitive_cube_add(size=1, location=tuple(0.5 * (box[i] + box[i + 3]) for i in range(3)))
    cube = bpy.context.object
    cube.scale = tuple(box[i + 3] - box[i] for i in range(3))
    m = ms_scene.fog("fog", dens, albedo, g)
else:
    bpy.ops.mesh.primitive_cube_add(size=4000, location=(0, 0, 0))
    cube = bpy.context.object
    m = ms_scene.fog("fog", dens, albedo, g)
if plain:
    cube.hide_render = True
cube.data.materials.append(m)
pos = (0.15 * dist, -dist if behind else dist, 0.1 * dist)
pl = bpy.data.lights.new("lamp", 'SPOT' if spot > 0 else 'POINT'); pl.energy = 100.0; pl.shadow_soft_size = 0.0
if spot > 0:   # a spot of that cone, blend 0.2, aimed down (-z: a light's default)
    pl.spot_size = math.radians(spot); pl.spot_blend = 0.2
po = bpy.data.objects.new("lamp", pl); sc.collection.objects.link(po)
po.location = pos
if spot > 0 and "across" in args[9:]:   # aimed along -x, across the view: -z turned 90 degrees about y
    po.rotation_euler = (0, math.radians(90), 0)
cam = ms_scene.camera(sc, (0, 0, 0), (90, 0, 0))
sc.render.filepath = out
bpy.ops.render.render(write_still=True)
mw = cam.matrix_world
json.dump({"c2w": [mw[i][j] for i in range(4) for j in range(4)], "fov": math.degrees(cam.data.angle_x),
           "near": cam.data.clip_start, "far": cam.data.clip_end, "lamp": list(pos),
           "intensity": 100.0 / (4 * math.pi)}, open(out + ".json", "w"))
print("ms_lamp_blender: rendered")
