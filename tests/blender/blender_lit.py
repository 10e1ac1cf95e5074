"""Runs inside Blender (blender -b --factory-startup --python THIS -- OUT plain|fog|sunmap SPP
SUN [shadow]): a tiny Cycles scene for lit fog (tests/blender/blender_lit_run.py compares):
emission-only surfaces (a ground plane and a ball that casts no shadow, or
with "shadow" does: shafts),
a black world, a box of homogeneous fog (Volume Scatter, HG g = 0.5, plus
Volume Absorption: sigma_t 0.08, albedo 0.75) from z = -1 to 6 around the
camera, a sun of strength SUN, volume bounces 0 (single scattering).
"plain" renders without the fog (with Z), "fog" with it, "sunmap" the
scene's depth from an orthographic camera looking along the sunlight (the
shadow map; OUT.json then holds that camera and its ortho scale). Writes
OUT and OUT.json (the camera and the direction towards the sun)."""
import json
import math
import os
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1:]
out, fog, spp, sun_strength = args[0], args[1] == "fog", int(args[2]), float(args[3])
sunmap, shadows = args[1] == "sunmap", "shadow" in args[4:]
# "lamp": a point lamp of power SUN watts (radius 0) in place of the sun;
# "calib": no fog, black surfaces and a white diffuse plane 2 units behind
# the lamp, facing the camera, to read the lamp's radiant intensity off
lamp, calib = "lamp" in args[4:], "calib" in args[4:]
LAMP = (1.5, 4.0, 2.0)
# "spot": a spot of power SUN watts (radius 0, cone 70 deg, no blend) over
# the ball, aimed straight down; mode "spotmap" renders the depth from it
# with a perspective camera of 90 deg
spot, spotmap = "spot" in args[4:], args[1] == "spotmap"
SPOT = (-1.0, 2.0, 5.5)
sc = bpy.context.scene
for o in list(bpy.data.objects):
    if o.type in ('MESH', 'LIGHT'):
        bpy.data.objects.remove(o, do_unlink=True)
sc.render.engine = 'CYCLES'
sc.cycles.device = 'CPU'
sc.cycles.samples = spp
sc.cycles.use_denoising = False
sc.cycles.use_adaptive_sampling = False
sc.cycles.max_bounces = 16
sc.cycles.volume_bounces = 0
sc.cycles.diffuse_bounces = 0
sc.cycles.glossy_bounces = 0
sc.cycles.transmission_bounces = 0
sc.cycles.transparent_max_bounces = 16
sc.cycles.sample_clamp_direct = 0
sc.cycles.sample_clamp_indirect = 0
sc.cycles.seed = 7
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 36, 100
sc.render.image_settings.file_format = 'OPEN_EXR'
sc.render.image_settings.color_depth = '32'
sc.render.image_settings.use_zbuffer = True
bpy.context.view_layer.use_pass_z = True
sc.render.film_transparent = False
w = bpy.data.worlds.new("black"); w.use_nodes = True
w.node_tree.nodes["Background"].inputs[1].default_value = 0.0
sc.world = w
def emissive(name, rgb):
    m = bpy.data.materials.new(name); m.use_nodes = True
    nt = m.node_tree; nt.nodes.clear()
    e = nt.nodes.new('ShaderNodeEmission'); e.inputs[0].default_value = (*rgb, 1); e.inputs[1].default_value = 0.0 if calib else 1.0
    o = nt.nodes.new('ShaderNodeOutputMaterial'); nt.links.new(e.outputs[0], o.inputs[0])
    m.cycles.sample_as_light = False   # the surfaces do not light the fog (exrfog's lights only)
    return m
bpy.ops.mesh.primitive_plane_add(size=40, location=(0, 0, 0))
bpy.context.object.data.materials.append(emissive("ground", (0.3, 0.25, 0.2)))
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.5, location=(-1, 2, 1.5), segments=48, ring_count=24)
bpy.context.object.data.materials.append(emissive("ball", (0.1, 0.4, 0.8)))
bpy.context.object.visible_shadow = shadows   # shafts, or none
if shadows:
    # a wall with a gap between the camera's fog and the (backlit) sun
    for x0, x1 in ((-20, -1.5), (1.5, 20)):
        bpy.ops.mesh.primitive_cube_add(size=1, location=((x0 + x1) / 2, 9, 3))
        wall = bpy.context.object
        wall.scale = (x1 - x0, 0.5, 6)
        wall.data.materials.append(emissive("wall", (0.2, 0.2, 0.22)))
if fog:
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 2.5))
    cube = bpy.context.object
    cube.scale = (60, 60, 7)
    m = bpy.data.materials.new("fog"); m.use_nodes = True
    nt = m.node_tree; nt.nodes.clear()
    s = nt.nodes.new('ShaderNodeVolumeScatter'); s.inputs['Density'].default_value = 0.06; s.inputs['Anisotropy'].default_value = 0.5; s.inputs['Color'].default_value = (1, 1, 1, 1)
    a = nt.nodes.new('ShaderNodeVolumeAbsorption'); a.inputs['Density'].default_value = 0.02; a.inputs['Color'].default_value = (0, 0, 0, 1)
    add = nt.nodes.new('ShaderNodeAddShader')
    o = nt.nodes.new('ShaderNodeOutputMaterial')
    nt.links.new(s.outputs[0], add.inputs[0]); nt.links.new(a.outputs[0], add.inputs[1]); nt.links.new(add.outputs[0], o.inputs['Volume'])
    m.cycles.homogeneous_volume = True
    m.cycles.volume_sampling = 'MULTIPLE_IMPORTANCE'
    cube.data.materials.append(m)
    cube.visible_shadow = True
if calib:
    bpy.ops.mesh.primitive_plane_add(size=4, location=(LAMP[0], LAMP[1] + 2, LAMP[2]),
                                     rotation=(math.radians(90), 0, 0))
    m = bpy.data.materials.new("white"); m.use_nodes = True
    nt = m.node_tree; nt.nodes.clear()
    dfs = nt.nodes.new('ShaderNodeBsdfDiffuse'); dfs.inputs[0].default_value = (1, 1, 1, 1)
    o = nt.nodes.new('ShaderNodeOutputMaterial'); nt.links.new(dfs.outputs[0], o.inputs[0])
    bpy.context.object.data.materials.append(m)
if lamp or calib:
    pl = bpy.data.lights.new("lamp", 'POINT'); pl.energy = sun_strength; pl.shadow_soft_size = 0.0
    plo = bpy.data.objects.new("lamp", pl); sc.collection.objects.link(plo)
    plo.location = LAMP
if spot:
    sp = bpy.data.lights.new("spot", 'SPOT'); sp.energy = sun_strength; sp.shadow_soft_size = 0.0
    sp.spot_size = math.radians(70); sp.spot_blend = 0.0
    spo = bpy.data.objects.new("spot", sp); sc.collection.objects.link(spo)
    spo.location = SPOT
sun = bpy.data.lights.new("sun", 'SUN'); sun.energy = 0.0 if (lamp or calib or spot) else sun_strength
# "soft": the sun's disc 3 degrees wide (penumbrae), else a point
sun.angle = math.radians(3.0) if "soft" in args[4:] else 0.0
so = bpy.data.objects.new("sun", sun); sc.collection.objects.link(so)
so.rotation_euler = (math.radians(72 if shadows else 60), 0, math.radians(170 if shadows else 150))
bpy.context.view_layer.update()
cam = sc.camera
cam.location = (0, -14, 2.5); cam.rotation_euler = (math.radians(85), 0, 0)
if sunmap:
    # the light's view: an orthographic camera looking along the sunlight
    # from 30 units towards the sun, over the ball and the ground near it
    t = so.matrix_world.col[2]
    cam.location = (40 * t[0], 4 + 40 * t[1], 2 + 40 * t[2])
    cam.rotation_euler = so.rotation_euler
    cam.data.type = 'ORTHO'
    cam.data.ortho_scale = 48.0
    cam.data.clip_start, cam.data.clip_end = 0.01, 500.0
    sc.render.resolution_x = sc.render.resolution_y = 512
if spotmap:
    cam.location = SPOT
    cam.rotation_euler = (0, 0, 0)   # down -Z, as the spot
    cam.data.type = 'PERSP'
    cam.data.sensor_fit = 'HORIZONTAL'
    cam.data.angle = math.radians(90)
    cam.data.clip_start, cam.data.clip_end = 0.01, 500.0
    sc.render.resolution_x = sc.render.resolution_y = 512
bpy.context.view_layer.update()
if args[1] == "opmap":
    # the add-on's "Render shadow map" on the sun (moved to where the test's
    # own sun map is centred, with its width, distance and size) or the spot
    sys.path.insert(0, os.path.join(os.environ["EXRFOG_SOURCE_DIR"], "integrations", "blender"))
    import addon_utils
    addon_utils.enable("exrfog_blender", default_set=True, handle_error=None)
    light = spo if spot else so
    so.location = (0, 4, 2)
    bpy.context.view_layer.objects.active = light
    s = sc.exrfog
    s.shadow_map, s.shadow_size, s.sun_width, s.sun_distance = out, 512, 48.0, 40.0
    res = bpy.ops.exrfog.shadow_map()
    print("blender_lit: operator %s" % sorted(res))
    print("blender_lit: light " + s.last_light)
    print("blender_lit: extra " + s.extra)
    print("blender_lit: rendered")
    sys.exit(0)
sc.render.filepath = out
bpy.ops.render.render(write_still=True)
m = cam.matrix_world
t = so.matrix_world.col[2]
json.dump({"c2w": [m[i][j] for i in range(4) for j in range(4)], "fov": math.degrees(cam.data.angle_x),
           "ortho_scale": cam.data.ortho_scale if sunmap else 0,
           "near": cam.data.clip_start, "far": cam.data.clip_end, "towards": [t[0], t[1], t[2]]}, open(out + ".json", "w"))
print("blender_lit: rendered")
