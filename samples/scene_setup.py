"""Scene-wide settings shared by the sample builders: Cycles, world, camera, materials (bpy).

Every Cycles default that changes a bake result (adaptive sampling, denoiser, indirect
clamping, animated seed) is set explicitly so a bake is reproducible (DESIGN.md section 4).
"""

from __future__ import annotations

import math

import bpy

from ..operators.base.compat import ensure_node_tree
from ..operators.base.meshes import set_image_pixels

#: Samples per pixel written into each sample scene, by size.
SAMPLES = {"test": 16, "demo": 64}


def configure_cycles(scene, size: str) -> None:
    """Cycles on the CPU with deterministic, unclamped, un-denoised sampling."""
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.samples = SAMPLES[size]
    cyc.preview_samples = SAMPLES[size]
    cyc.seed = 0
    cyc.use_animated_seed = False
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.use_preview_denoising = False
    cyc.sample_clamp_direct = 0.0
    cyc.sample_clamp_indirect = 0.0
    cyc.max_bounces = 4
    cyc.diffuse_bounces = 4
    scene.render.bake.margin = 4
    scene.render.resolution_x = 256 if size == "test" else 1024
    scene.render.resolution_y = 256 if size == "test" else 1024
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"


def uniform_world(scene, name: str, strength: float = 1.0, color=(1.0, 1.0, 1.0)):
    """A world with a constant background; sampling off so bakes stay linear in the light."""
    world = bpy.data.worlds.new(name)
    nodes = ensure_node_tree(world).nodes
    background = nodes.get("Background") or nodes.new("ShaderNodeBackground")
    background.inputs["Color"].default_value = (*color, 1.0)
    background.inputs["Strength"].default_value = strength
    world.cycles.sampling_method = "NONE"
    scene.world = world
    return world


def sky_world(scene, name: str, sun_az_el=(200.0, 35.0)):
    """A sun-and-sky HDR environment (packed into the .blend as OpenEXR) behind a Point Mapping
    node, for the object scenes: the vertex preview follows the node's Z rotation, and its
    Environment Rotation slider visibly turns the sun and its shadows (a constant sky does not
    change when rotated). Sampling off, as for :func:`uniform_world`: our bakes replace the
    world with their own lights, so this world lights only the previews and renders."""

    from ..lt_addon.sphere.hemisphere import direction_from_az_el
    from ..lt_addon.transport.error import sun_sky_environment

    # a soft sun (10 deg Gaussian radius): 384 transport directions resolve its shadows
    env = sun_sky_environment(64, direction_from_az_el(*sun_az_el), row_order="bottom_first",
                              sun_radiance=120.0, sun_radius_deg=10.0)
    h, w = env.shape[:2]
    img = bpy.data.images.new(f"{name}Sky", w, h, float_buffer=True)
    set_image_pixels(img, env)
    img.file_format = "OPEN_EXR"           # packed as float, not as an 8-bit PNG
    img.pack()
    world = bpy.data.worlds.new(name)
    tree = ensure_node_tree(world)
    nodes, links = tree.nodes, tree.links
    background = nodes.get("Background") or nodes.new("ShaderNodeBackground")
    background.inputs["Strength"].default_value = 1.0
    tex = nodes.new("ShaderNodeTexEnvironment")
    tex.image = img
    tex.location = (-300, 300)
    mapping = nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.location = (-500, 300)
    coords = nodes.new("ShaderNodeTexCoord")
    coords.location = (-700, 300)
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], background.inputs["Color"])
    world.cycles.sampling_method = "NONE"
    scene.world = world
    return world


def diffuse_material(name: str, color) -> bpy.types.Material:
    """A pure Lambertian material (Diffuse BSDF, roughness 0) of the given linear RGB albedo."""
    mat = bpy.data.materials.new(name)
    nodes = ensure_node_tree(mat).nodes
    for node in list(nodes):
        nodes.remove(node)
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf.location, out.location = (-200, 0), (100, 0)
    mat.node_tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    mat.diffuse_color = (*color, 1.0)
    return mat


def make_principled(mat) -> None:
    """Swap a :func:`diffuse_material`'s Diffuse BSDF for a Principled BSDF of its colour
    (metallic 0, roughness 0.5): the material whose Metallic and Roughness a material bake
    with glossy anchors edits."""
    tree = mat.node_tree
    (old,) = [n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfDiffuse"]
    new = tree.nodes.new("ShaderNodeBsdfPrincipled")
    new.inputs["Base Color"].default_value = old.inputs["Color"].default_value
    new.location = old.location
    (out,) = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    tree.links.new(new.outputs["BSDF"], out.inputs["Surface"])
    tree.nodes.remove(old)


def ortho_top_camera(scene, collection, centre, size: float, height: float = 5.0):
    """An orthographic camera looking straight down -z at ``centre`` covering ``size`` metres."""
    cam_data = bpy.data.cameras.new("TopCamera")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = size
    cam = bpy.data.objects.new("TopCamera", cam_data)
    cam.location = (centre[0], centre[1], height)
    collection.objects.link(cam)
    scene.camera = cam
    return cam


def perspective_camera(scene, collection, location, target, lens: float = 50.0):
    """A perspective camera at ``location`` aimed at ``target`` (both in metres)."""
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = lens
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = location
    dx, dy, dz = (target[i] - location[i] for i in range(3))
    # Blender cameras look down their local -z; rotate so -z points at the target.
    cam.rotation_euler = (math.atan2(math.hypot(dx, dy), -dz), 0.0, math.atan2(dy, dx) - math.pi / 2)
    collection.objects.link(cam)
    scene.camera = cam
    return cam


def sun_lamp(collection, elevation_deg: float = 45.0, azimuth_deg: float = 30.0,
             strength: float = 3.0, angle_deg: float = 0.0, hide: bool = True):
    """A Sun lamp pointing from (azimuth, elevation); hidden from render by default.

    The sample scenes are lit by their world; the Sun is there to be followed by the live preview
    and to render "Sun lamp" ground truths, so it starts hidden to keep bakes world-only.
    """
    data = bpy.data.lights.new("Sun", type="SUN")
    data.energy = strength
    data.angle = math.radians(angle_deg)
    sun = bpy.data.objects.new("Sun", data)
    # A sun shines along its local -z; tilt so light arrives from (azimuth, elevation).
    sun.rotation_euler = (math.radians(90.0 - elevation_deg), 0.0, math.radians(azimuth_deg + 90.0))
    sun.hide_render = hide
    sun.hide_viewport = False
    collection.objects.link(sun)
    return sun
