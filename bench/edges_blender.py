"""Runs inside Blender: blender -b --factory-startup --python THIS -- OUT VARIANT W H SAMPLES DENSITY

Renders the scenes of bench/edges.sh (issue 45) with Cycles twice: the
flat render a user hands exrfog (Combined and the Depth pass, no fog), and
the same frame with the fog inside the scene, the ground truth. Every
surface only emits (no lights), and the fog is an emission-absorption
volume (absorption DENSITY, emission DENSITY times the fog colour), so
each camera sample's colour is exactly c T + F (1 - T) along its own ray
and the truth pixel is the filtered mean of those: what exrfog's fog,
exp:density=DENSITY with --fog-color F, gives each sample, mixed as the
renderer mixes them. The default pixel filter (Blackman-Harris, 1.5 px).

Variants (the scene at 0..300 m, z up, camera 1.7 m up looking along +y):
  thin     poles, a fence and a wire 3-8 m away against boxes 20-240 m
           away, a sphere, the ground and the sky
  cards    partly transparent cards (leaf-like: alpha from a procedural
           texture) 4-10 m away against the same background
  motion   a pole crossing the frame fast, with motion blur
  dof      the thin scene with a shallow depth of field (f/1.4 at 5 m)
  calib    another layout (different distances, colours, a lattice),
           for calibrating the error output; not a test scene

Writes OUT/nofog.exr, OUT/fog.exr and OUT/flags.json (the camera as
exrfog's flags want it)."""
import json
import math
import random
import sys

import bpy

out, variant, W, H, samples, density = sys.argv[sys.argv.index("--") + 1:]
W, H, samples, density = int(W), int(H), int(samples), float(density)
FOG = (0.7, 0.75, 0.8)
rng = random.Random({"thin": 1, "cards": 2, "motion": 3, "dof": 1, "calib": 9}[variant])

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = 'CYCLES'
scene.cycles.device = 'CPU'
scene.cycles.samples = samples
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.cycles.max_bounces = 0
scene.cycles.transparent_max_bounces = 64
scene.cycles.volume_bounces = 0
scene.cycles.seed = 7
scene.render.resolution_x, scene.render.resolution_y = W, H
scene.render.resolution_percentage = 100
scene.render.film_transparent = False
scene.render.image_settings.file_format = 'OPEN_EXR_MULTILAYER'
scene.render.image_settings.color_depth = '32'
scene.render.image_settings.exr_codec = 'ZIP'
scene.view_settings.view_transform = 'Standard'
world = bpy.data.worlds.new("w")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs[1].default_value = 0.0
scene.world = world
bpy.context.view_layer.use_pass_z = True


def bare_material(name):
    """A new node material with no nodes but its output: (material, tree, output)."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    return m, nt, nt.nodes.new("ShaderNodeOutputMaterial")


def emissive(name, colour, alpha_tex=None):
    """A material that only emits colour (and, for cards, is transparent
    where a procedural texture says so)."""
    m, nt, o = bare_material(name)
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs[0].default_value = colour + (1.0,)
    e.inputs[1].default_value = 1.0
    # a little texture, so neighbours' colours differ as real surfaces' do
    tex = nt.nodes.new("ShaderNodeTexNoise")
    tex.inputs["Scale"].default_value = 6.0
    mix = nt.nodes.new("ShaderNodeMixRGB")
    mix.blend_type = 'MULTIPLY'
    mix.inputs[0].default_value = 0.3
    mix.inputs[1].default_value = colour + (1.0,)
    nt.links.new(tex.outputs["Color"], mix.inputs[2])
    nt.links.new(mix.outputs[0], e.inputs[0])
    if alpha_tex is None:
        nt.links.new(e.outputs[0], o.inputs["Surface"])
    else:
        t = nt.nodes.new("ShaderNodeBsdfTransparent")
        mx = nt.nodes.new("ShaderNodeMixShader")
        v = nt.nodes.new("ShaderNodeTexVoronoi")
        v.inputs["Scale"].default_value = alpha_tex
        ramp = nt.nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.elements[0].position = 0.45
        ramp.color_ramp.elements[1].position = 0.55
        nt.links.new(v.outputs["Distance"], ramp.inputs[0])
        nt.links.new(ramp.outputs[0], mx.inputs[0])
        nt.links.new(e.outputs[0], mx.inputs[1])
        nt.links.new(t.outputs[0], mx.inputs[2])
        nt.links.new(mx.outputs[0], o.inputs["Surface"])
        m.blend_method = 'HASHED'
    return m


def add(obj, mat):
    obj.data.materials.append(mat)
    return obj


def box(loc, size, colour):
    bpy.ops.mesh.primitive_cube_add(location=loc)
    o = bpy.context.object
    o.scale = (size[0] / 2, size[1] / 2, size[2] / 2)
    return add(o, emissive("b", colour))


def pole(x, y, r, h, colour):
    bpy.ops.mesh.primitive_cylinder_add(radius=r, depth=h, location=(x, y, h / 2), vertices=24)
    return add(bpy.context.object, emissive("p", colour))


# the ground and the far objects
bpy.ops.mesh.primitive_plane_add(size=4000, location=(0, 0, 0))
add(bpy.context.object, emissive("ground", (0.18, 0.16, 0.12)))
for k in range(9):
    d = 20 * (12 ** (k / 8.0)) * (0.8 if variant == "calib" else 1.0)
    x = rng.uniform(-0.5, 0.5) * d
    s = rng.uniform(0.15, 0.35) * d
    box((x, d, s / 2), (s, s * 0.5, s), (rng.uniform(0.1, 0.9), rng.uniform(0.1, 0.9),
                                          rng.uniform(0.1, 0.9)))
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.5, location=(3.5, 12, 1.5))
add(bpy.context.object, emissive("sphere", (0.9, 0.5, 0.2)))

if variant in ("thin", "dof", "calib", "motion"):
    for k in range(7):
        pole(rng.uniform(-4, 4), rng.uniform(3, 8), rng.uniform(0.02, 0.08), 5,
             (rng.uniform(0.3, 1.0), rng.uniform(0.3, 1.0), rng.uniform(0.3, 1.0)))
    fence_y = 6.5 if variant != "calib" else 9.0
    for k in range(24):
        box((-3 + 0.25 * k, fence_y, 0.6), (0.04, 0.04, 1.2), (0.95, 0.95, 0.9))
    box((0, fence_y, 1.15), (6, 0.04, 0.05), (0.95, 0.95, 0.9))
    bpy.ops.mesh.primitive_cylinder_add(radius=0.012, depth=30, location=(0, 5, 3.0),
                                        rotation=(0, math.pi / 2, 0))
    add(bpy.context.object, emissive("wire", (0.05, 0.05, 0.05)))
    if variant == "calib":
        for i in range(6):
            for j in range(4):
                box((-2 + 0.8 * i, 4.5, 0.5 + 0.6 * j), (0.05, 0.05, 0.05), (0.2, 0.9, 0.4))
if variant == "cards":
    for k in range(14):
        bpy.ops.mesh.primitive_plane_add(size=rng.uniform(0.6, 1.4),
                                         location=(rng.uniform(-3, 3), rng.uniform(4, 10),
                                                   rng.uniform(0.5, 3.0)),
                                         rotation=(math.pi / 2 + rng.uniform(-0.4, 0.4), 0,
                                                   rng.uniform(-0.5, 0.5)))
        add(bpy.context.object, emissive("card", (rng.uniform(0.1, 0.4), rng.uniform(0.4, 0.9),
                                                  rng.uniform(0.1, 0.3)), alpha_tex=4.0))
if variant == "motion":
    o = pole(-3, 4, 0.06, 5, (1.0, 0.9, 0.2))
    scene.frame_start = scene.frame_end = 1
    o.location.x = -3
    o.keyframe_insert("location", frame=0)
    o.location.x = 3
    o.keyframe_insert("location", frame=2)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 1.0
scene.frame_set(1)

bpy.ops.object.camera_add(location=(0, 0, 1.7), rotation=(math.radians(90), 0, 0))
cam = bpy.context.object
scene.camera = cam
cam.data.lens = 35
cam.data.clip_start = 0.1
cam.data.clip_end = 5000
if variant == "dof":
    cam.data.dof.use_dof = True
    cam.data.dof.focus_distance = 5.0
    cam.data.dof.aperture_fstop = 1.4

scene.render.filepath = out + "/nofog.exr"
bpy.ops.render.render(write_still=True)

# the fog inside the scene: a cube of 4 km around everything
bpy.ops.mesh.primitive_cube_add(size=4000, location=(0, 0, 0))
fogbox = bpy.context.object
m, nt, o = bare_material("fog")
ab = nt.nodes.new("ShaderNodeVolumeAbsorption")
ab.inputs["Color"].default_value = (0, 0, 0, 1)   # Cycles absorbs density (1 - colour)
ab.inputs["Density"].default_value = density
em = nt.nodes.new("ShaderNodeEmission")
em.inputs[0].default_value = FOG + (1.0,)
em.inputs[1].default_value = density
add_s = nt.nodes.new("ShaderNodeAddShader")
nt.links.new(ab.outputs[0], add_s.inputs[0])
nt.links.new(em.outputs[0], add_s.inputs[1])
nt.links.new(add_s.outputs[0], o.inputs["Volume"])
fogbox.data.materials.append(m)
m.cycles.homogeneous_volume = True
scene.render.filepath = out + "/fog.exr"
bpy.ops.render.render(write_still=True)

mw = cam.matrix_world
json.dump({"camera_to_world": [mw[i][j] for i in range(4) for j in range(4)],
           "fov": math.degrees(cam.data.angle_x), "near": cam.data.clip_start,
           "far": cam.data.clip_end, "layer": bpy.context.view_layer.name, "fog_color": FOG,
           "density": density, "variant": variant, "samples": samples},
          open(out + "/flags.json", "w"))
print("edges_blender: rendered")
