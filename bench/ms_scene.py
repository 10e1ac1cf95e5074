"""What bench/ms_blender.py and bench/ms_lamp_blender.py share (inside Blender): Cycles set up
for a volume reference and the fog's material."""
import bpy


def setup(spp, bounces, width, height, seed, sky=0.0):
    """Clears meshes and lights; Cycles on the CPU, SPP samples without denoising, adaptive
    sampling or clamping, BOUNCES volume bounces (max bounces as many, at least 1; no diffuse,
    glossy or transmission bounces), WIDTHxHEIGHT 32-bit EXR with Z; a world of radiance SKY
    (0: black)."""
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
    sc.cycles.seed = seed
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = width, height, 100
    sc.render.image_settings.file_format = 'OPEN_EXR'
    sc.render.image_settings.color_depth = '32'
    sc.render.image_settings.use_zbuffer = True
    bpy.context.view_layer.use_pass_z = True
    sc.render.film_transparent = False
    w = bpy.data.worlds.new("world"); w.use_nodes = True
    w.node_tree.nodes["Background"].inputs[0].default_value = (1, 1, 1, 1)
    w.node_tree.nodes["Background"].inputs[1].default_value = sky
    sc.world = w
    return sc


def black():
    """A material that only absorbs (an emission of strength 0, no BSDF)."""
    m = bpy.data.materials.new("black"); m.use_nodes = True
    m.node_tree.nodes.clear()
    e = m.node_tree.nodes.new('ShaderNodeEmission'); e.inputs[1].default_value = 0.0
    o = m.node_tree.nodes.new('ShaderNodeOutputMaterial')
    m.node_tree.links.new(e.outputs[0], o.inputs[0])
    return m


def fog(name, dens, albedo, g):
    """Homogeneous fog: Volume Scatter of density DENS * ALBEDO, HG anisotropy G, plus Volume
    Absorption of the rest."""
    m = bpy.data.materials.new(name); m.use_nodes = True
    nt = m.node_tree; nt.nodes.clear()
    s, a = _scatter_absorb(nt, g)
    s.inputs['Density'].default_value = dens * albedo
    a.inputs['Density'].default_value = dens * (1 - albedo)
    m.cycles.homogeneous_volume = True
    m.cycles.volume_sampling = 'MULTIPLE_IMPORTANCE'
    return m


def layered_fog(name, dens, albedo, g, knots, step_rate):
    """Layered fog over world z: density DENS times a factor piecewise linear between KNOTS
    ((height, factor) pairs, heights increasing) and constant beyond the ends (exrfog's layered
    model), as a sum of clamped Map Range ramps; split as fog() splits it, marched at STEP_RATE
    times Cycles' automatic step."""
    m = bpy.data.materials.new(name); m.use_nodes = True
    nt = m.node_tree; nt.nodes.clear()
    geo = nt.nodes.new('ShaderNodeNewGeometry')
    sep = nt.nodes.new('ShaderNodeSeparateXYZ')
    nt.links.new(geo.outputs['Position'], sep.inputs[0])
    acc = None
    for (h0, f0), (h1, f1) in zip(knots, knots[1:]):
        mr = nt.nodes.new('ShaderNodeMapRange'); mr.clamp = True
        mr.inputs['From Min'].default_value = h0; mr.inputs['From Max'].default_value = h1
        mr.inputs['To Min'].default_value = 0.0; mr.inputs['To Max'].default_value = f1 - f0
        nt.links.new(sep.outputs['Z'], mr.inputs['Value'])
        if acc is None:
            add = nt.nodes.new('ShaderNodeMath'); add.operation = 'ADD'
            add.inputs[1].default_value = knots[0][1]
            nt.links.new(mr.outputs['Result'], add.inputs[0])
        else:
            add = nt.nodes.new('ShaderNodeMath'); add.operation = 'ADD'
            nt.links.new(acc.outputs[0], add.inputs[0]); nt.links.new(mr.outputs['Result'], add.inputs[1])
        acc = add
    return _factor_fog(m, acc.outputs[0], dens, albedo, g, step_rate)


def _factor_fog(m, factor, dens, albedo, g, step_rate):
    """Material M's fog from the node socket FACTOR (the density over DENS): scattering DENS *
    ALBEDO and absorption the rest times it, HG G, marched at STEP_RATE times Cycles' automatic
    step; returns M."""
    nt = m.node_tree
    ds = nt.nodes.new('ShaderNodeMath'); ds.operation = 'MULTIPLY'
    ds.inputs[1].default_value = dens * albedo
    nt.links.new(factor, ds.inputs[0])
    da = nt.nodes.new('ShaderNodeMath'); da.operation = 'MULTIPLY'
    da.inputs[1].default_value = dens * (1 - albedo)
    nt.links.new(factor, da.inputs[0])
    s, a = _scatter_absorb(nt, g)
    nt.links.new(ds.outputs[0], s.inputs['Density'])
    nt.links.new(da.outputs[0], a.inputs['Density'])
    m.cycles.homogeneous_volume = False
    m.cycles.volume_sampling = 'MULTIPLE_IMPORTANCE'
    m.cycles.volume_step_rate = step_rate
    return m


def _scatter_absorb(nt, g):
    """Volume Scatter (white, HG anisotropy G) plus black Volume Absorption into the material
    output of node tree NT; returns the two nodes, their densities for the caller."""
    s = nt.nodes.new('ShaderNodeVolumeScatter')
    s.inputs['Anisotropy'].default_value = g
    s.inputs['Color'].default_value = (1, 1, 1, 1)
    a = nt.nodes.new('ShaderNodeVolumeAbsorption')
    a.inputs['Color'].default_value = (0, 0, 0, 1)
    add = nt.nodes.new('ShaderNodeAddShader')
    o = nt.nodes.new('ShaderNodeOutputMaterial')
    nt.links.new(s.outputs[0], add.inputs[0]); nt.links.new(a.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], o.inputs['Volume'])
    return s, a


def camera(sc, location, rotation_deg):
    """The scene's camera at LOCATION, turned by ROTATION_DEG (Euler XYZ, degrees), a 60 degree
    horizontal field of view, clipping 0.05 to 10000."""
    import math
    cam = sc.camera
    cam.location = location
    cam.rotation_euler = tuple(math.radians(a) for a in rotation_deg)
    cam.data.sensor_fit = 'HORIZONTAL'
    cam.data.angle = math.radians(60)
    cam.data.clip_start, cam.data.clip_end = 0.05, 10000.0
    bpy.context.view_layer.update()
    return cam


def height_fog(name, dens, albedo, g, falloff, step_rate):
    """Exponential height fog over world z: density DENS * exp(-FALLOFF z) (Geometry's world
    position), split as fog() splits it, marched at STEP_RATE times Cycles' automatic step."""
    m = bpy.data.materials.new(name); m.use_nodes = True
    nt = m.node_tree; nt.nodes.clear()
    geo = nt.nodes.new('ShaderNodeNewGeometry')
    sep = nt.nodes.new('ShaderNodeSeparateXYZ')
    nt.links.new(geo.outputs['Position'], sep.inputs[0])
    mul = nt.nodes.new('ShaderNodeMath'); mul.operation = 'MULTIPLY'
    mul.inputs[1].default_value = -falloff
    nt.links.new(sep.outputs['Z'], mul.inputs[0])
    ex = nt.nodes.new('ShaderNodeMath'); ex.operation = 'EXPONENT'
    nt.links.new(mul.outputs[0], ex.inputs[0])
    return _factor_fog(m, ex.outputs[0], dens, albedo, g, step_rate)
