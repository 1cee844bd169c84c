"""The public gallery's scenes (issue 55): scenes the bake was not tuned on, built from meshes
the project did not author -- Blender's own primitives and modifiers (a displaced grid, a UV
sphere, Suzanne, arrays of cubes, cylinders) -- into a factory-empty scene (bpy).

Each builder ``build(scene)`` fills ``scene`` (made by :func:`new_scene`) and returns the objects
to bake, every one with a UV map (the primitive's own, or Smart UV Project where a modifier was
applied) and a plain Diffuse BSDF material of one colour (the normal-mapped scene adds its
Normal Map and Bump nodes). The scenes keep Blender's default Cycles settings (Light Paths:
diffuse 4, total 12; no world); each gets a camera for the camera picture, and the animated-Sun
scene a Sun keyframed over frames 1..24.

:data:`SCENES` names them (letters a..h as issue 55 lists them); :func:`lights` gives the
(azimuth, elevation) pairs -- or, for the animated Sun, the Sun's own direction on its path --
each scene is measured at.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def new_scene():
    """A factory-empty scene (no objects, no world, Blender's default render settings)."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy.context.scene


# -- helpers -------------------------------------------------------------------------------------
def _only(obj):
    """``obj`` selected alone and active, in object mode (what bpy.ops on it need)."""
    import bpy

    if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def material(obj, color, name=None):
    """A plain Diffuse BSDF material of ``color`` (RGB) on ``obj``; returns it."""
    import bpy

    mat = bpy.data.materials.new(name or f"{obj.name}Material")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    for n in list(nodes):
        nodes.remove(n)
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return mat


def smart_uv(obj, angle=66.0, margin=0.02):
    """Smart UV Project on all of ``obj`` (edit mode, then back to object mode)."""
    import bpy

    _only(obj)
    if not obj.data.uv_layers:
        obj.data.uv_layers.new(name="UVMap")
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(angle_limit=math.radians(angle), island_margin=margin)
    bpy.ops.object.mode_set(mode="OBJECT")


def apply_all(obj):
    """``obj``'s modifiers and transform applied (Object > Convert > Mesh, Apply All
    Transforms)."""
    import bpy

    _only(obj)
    if obj.modifiers:
        bpy.ops.object.convert(target="MESH")
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)


def floor(size=4.0, color=(0.6, 0.6, 0.6), name="Floor"):
    """A square plane of ``size`` metres at z = 0 (its primitive's 0..1 UVs)."""
    import bpy

    bpy.ops.mesh.primitive_plane_add(size=size, location=(0, 0, 0))
    obj = bpy.context.object
    obj.name = name
    material(obj, color)
    return obj


def camera(scene, target=(0.0, 0.0, 0.3), distance=6.0, azimuth=215.0, elevation=28.0,
           lens=40.0, size=(640, 480)):
    """The scene camera, ``distance`` m from ``target`` at ``azimuth`` / ``elevation``
    (degrees), looking at it."""
    import bpy
    from mathutils import Vector

    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    cam = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(cam)
    a, e = math.radians(azimuth), math.radians(elevation)
    t = Vector(target)
    cam.location = t + distance * Vector((math.cos(e) * math.cos(a), math.cos(e) * math.sin(a),
                                          math.sin(e)))
    cam.rotation_euler = (t - cam.location).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = size
    return cam


# -- the scenes ----------------------------------------------------------------------------------
def build_relief(scene):
    """(a) A displaced relief terrain with planar UVs: a 2 m grid of 160 x 160 quads (the
    primitive's own UVs, projected from the top), a Displace modifier (kept live) driven by
    Blender's Voronoi texture with F2 - F1 weights -- raised cells parted by deep grooves, like
    cobbles -- flat-shaded."""
    import bpy

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=160, y_subdivisions=160, size=2.0,
                                    location=(0, 0, 0))
    obj = bpy.context.object
    obj.name = "Relief"
    tex = bpy.data.textures.new("ReliefCells", type="VORONOI")
    tex.distance_metric = "DISTANCE"
    tex.weight_1, tex.weight_2, tex.weight_3, tex.weight_4 = -1.0, 1.0, 0.0, 0.0
    tex.noise_scale = 0.22
    tex.noise_intensity = 1.0
    mod = obj.modifiers.new("Displace", "DISPLACE")
    mod.texture = tex
    mod.texture_coords = "LOCAL"
    mod.direction = "Z"
    mod.mid_level = 0.0
    mod.strength = 0.12
    for p in obj.data.polygons:
        p.use_smooth = False
    material(obj, (0.62, 0.52, 0.42))
    camera(scene, target=(0, 0, 0.05), distance=3.2, elevation=35.0)
    return [obj]


def build_lowpoly(scene):
    """(b) A smooth low-poly object on a floor: a UV sphere of 12 segments x 8 rings, smooth
    shaded (its primitive UVs), on a 3 m floor."""
    import bpy

    ground = floor(3.0, (0.55, 0.55, 0.5))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=8, radius=0.5,
                                         location=(0, 0, 0.5))
    ball = bpy.context.object
    ball.name = "LowPolySphere"
    bpy.ops.object.shade_smooth()
    material(ball, (0.7, 0.25, 0.2))
    camera(scene, target=(0, 0, 0.4), distance=4.5)
    return [ball, ground]


def build_fence(scene):
    """(c) A thin-featured object: a fence of 21 posts 3 cm thick (an Array modifier of one
    thin cube, applied) and two rails, joined into one mesh with Smart UV Project, on a floor."""
    import bpy

    ground = floor(4.0, (0.5, 0.55, 0.45))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-1.5, 0.0, 0.5))
    post = bpy.context.object
    post.name = "Fence"
    post.scale = (0.03, 0.03, 1.0)
    apply_all(post)                        # the Array's offset in metres, not post widths
    arr = post.modifiers.new("Array", "ARRAY")
    arr.count = 21
    arr.use_relative_offset = False
    arr.use_constant_offset = True
    arr.constant_offset_displace = (0.15, 0.0, 0.0)
    apply_all(post)
    rails = []
    for z in (0.2, 0.85):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.025, z))
        rail = bpy.context.object
        rail.scale = (3.06, 0.02, 0.04)
        apply_all(rail)
        rails.append(rail)
    for o in bpy.context.view_layer.objects:
        o.select_set(o in rails or o == post)
    bpy.context.view_layer.objects.active = post
    bpy.ops.object.join()
    smart_uv(post)
    material(post, (0.45, 0.3, 0.2))
    camera(scene, target=(0, 0, 0.4), distance=5.0, azimuth=240.0, elevation=25.0)
    return [post, ground]


def build_scan(scene):
    """(d) A "scanned"-like dense mesh: Suzanne with two levels of Subdivision Surface applied
    (7,958 faces), smooth, Smart UV Project, sitting on a floor."""
    import bpy

    ground = floor(3.0, (0.5, 0.5, 0.55))
    bpy.ops.mesh.primitive_monkey_add(size=1.2, location=(0, 0, 0.0))
    head = bpy.context.object
    head.name = "Suzanne"
    head.rotation_euler = (math.radians(-20.0), 0.0, math.radians(-30.0))
    sub = head.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = sub.render_levels = 2
    apply_all(head)
    bpy.ops.object.shade_smooth()
    z = np.array([v.co.z for v in head.data.vertices])
    head.location.z = -float(z.min())      # resting on the floor
    smart_uv(head)
    material(head, (0.75, 0.6, 0.3))
    camera(scene, target=(0, 0, 0.4), distance=4.0, azimuth=250.0)
    return [head, ground]


#: The interior's window: the wall at x = +ROOM/2 (facing azimuth 0), this wide and tall, its
#: sill this high (metres).
ROOM, ROOM_H, WIN_W, WIN_H, WIN_SILL = 4.0, 2.5, 1.6, 1.2, 0.6


def build_interior(scene):
    """(e) An interior lit through a window: a closed 4 x 4 x 2.5 m room, one-sided faces
    facing in (so only the window lets the sun in), with a 1.6 x 1.2 m window in the wall facing
    azimuth 0; a box on its floor. Smart UV Project on both."""
    import bmesh
    import bpy
    from mathutils import Vector

    h, H = ROOM / 2, ROOM_H
    bm = bmesh.new()

    def quad(*pts):
        vs = [bm.verts.new(p) for p in pts]
        bm.faces.new(vs)

    quad((-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0))        # floor
    quad((-h, -h, H), (-h, h, H), (h, h, H), (h, -h, H))        # ceiling
    quad((-h, -h, 0), (-h, h, 0), (-h, h, H), (-h, -h, H))      # wall -x
    quad((-h, -h, 0), (-h, -h, H), (h, -h, H), (h, -h, 0))      # wall -y
    quad((-h, h, 0), (h, h, 0), (h, h, H), (-h, h, H))          # wall +y
    ys = (-h, -WIN_W / 2, WIN_W / 2, h)                          # wall +x, a hole in its middle
    zs = (0.0, WIN_SILL, WIN_SILL + WIN_H, H)
    for i in range(3):
        for j in range(3):
            if i == 1 and j == 1:
                continue
            quad((h, ys[i], zs[j]), (h, ys[i], zs[j + 1]), (h, ys[i + 1], zs[j + 1]),
                 (h, ys[i + 1], zs[j]))
    bmesh.ops.remove_doubles(bm, verts=bm.verts, dist=1e-6)
    bm.normal_update()
    centre = Vector((0.0, 0.0, H / 2))
    for f in bm.faces:   # every face facing the room's centre (one-sided walls: light from
        if f.normal.dot(centre - f.calc_center_median()) < 0:   # outside stops at them)
            f.normal_flip()
    mesh = bpy.data.meshes.new("Room")
    bm.to_mesh(mesh)
    bm.free()
    room = bpy.data.objects.new("Room", mesh)
    scene.collection.objects.link(room)
    smart_uv(room)
    material(room, (0.75, 0.72, 0.65))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.3, -0.4, 0.35))
    box = bpy.context.object
    box.name = "Box"
    box.scale = (0.8, 0.6, 0.7)
    apply_all(box)
    smart_uv(box)
    material(box, (0.3, 0.45, 0.7))
    camera(scene, target=(0.5, 0, 0.8), distance=1.8, azimuth=180.0, elevation=20.0, lens=18.0)
    scene.camera.location = (-1.8, 0.6, 1.5)
    scene.camera.rotation_euler = (Vector((1.2, -0.2, 0.4)) - scene.camera.location
                                   ).to_track_quat("-Z", "Y").to_euler()
    return [room, box]


def build_shadows(scene):
    """(f) Objects shadowing each other: three boxes and two cylinders close together on a
    floor (their primitives' UVs; scale applied)."""
    import bpy

    ground = floor(4.0, (0.55, 0.55, 0.55))
    objs = []
    specs = [("cube", (0.0, 0.0, 0.3), (0.6, 0.6, 0.6), (0.7, 0.3, 0.25)),
             ("cube", (0.65, 0.25, 0.45), (0.35, 0.35, 0.9), (0.3, 0.6, 0.3)),
             ("cube", (-0.2, -0.65, 0.15), (1.1, 0.3, 0.3), (0.35, 0.4, 0.75)),
             ("cylinder", (-0.65, 0.45, 0.5), (0.5, 0.5, 1.0), (0.8, 0.75, 0.3)),
             ("cylinder", (0.35, -0.05, 0.85), (0.25, 0.25, 0.5), (0.6, 0.35, 0.65))]
    for i, (kind, loc, scale, color) in enumerate(specs):
        if kind == "cube":
            bpy.ops.mesh.primitive_cube_add(size=1.0, location=loc)
        else:
            bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=0.5, depth=1.0, location=loc)
        o = bpy.context.object
        o.name = f"{kind.title()}{i}"
        o.scale = scale
        apply_all(o)
        material(o, color)
        objs.append(o)
    camera(scene, target=(0, 0, 0.35), distance=5.0)
    return objs + [ground]


def build_normalmap(scene):
    """(g) A normal-mapped material: a 2 m plane whose Diffuse BSDF's normal comes from a Bump
    node (height: Blender's Brick texture) over a Normal Map node fed by a Noise texture, with a
    plain box standing on it."""
    import bpy

    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0, 0, 0))
    plane = bpy.context.object
    plane.name = "NormalMapped"
    mat = material(plane, (0.65, 0.55, 0.5))
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_DIFFUSE")
    coord = nodes.new("ShaderNodeTexCoord")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 12.0
    nmap = nodes.new("ShaderNodeNormalMap")
    nmap.inputs["Strength"].default_value = 0.25
    brick = nodes.new("ShaderNodeTexBrick")
    brick.inputs["Scale"].default_value = 6.0
    brick.inputs["Mortar Size"].default_value = 0.03
    bump = nodes.new("ShaderNodeBump")
    bump.inputs["Strength"].default_value = 1.0
    bump.inputs["Distance"].default_value = 0.05
    links.new(coord.outputs["UV"], noise.inputs["Vector"])
    links.new(coord.outputs["UV"], brick.inputs["Vector"])
    links.new(noise.outputs["Color"], nmap.inputs["Color"])
    links.new(nmap.outputs["Normal"], bump.inputs["Normal"])
    links.new(brick.outputs["Fac"], bump.inputs["Height"])
    links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0.2, 0.1, 0.25))
    box = bpy.context.object
    box.name = "Box"
    material(box, (0.4, 0.5, 0.6))
    camera(scene, target=(0, 0, 0.1), distance=3.5, elevation=40.0)
    return [plane, box]


#: The animated day Sun: frames 1..24 along a great circle from east to west tilted
#: DAY_TILT degrees from the zenith (highest elevation 90 - DAY_TILT), starting and ending
#: DAY_FIRST_EL degrees above the horizon.
DAY_FRAMES, DAY_TILT, DAY_FIRST_EL = (1, 24), 12.0, 0.5


def day_direction(t):
    """Towards the day Sun at ``t`` in [0, 1] of its day (unit vector, z up)."""
    phi = math.radians(DAY_TILT)
    east = np.array([0.0, 1.0, 0.0])     # rises at azimuth 90 ...
    up = np.array([math.sin(phi), 0.0, math.cos(phi)])   # ... culminates towards azimuth 0
    th0 = math.asin(math.sin(math.radians(DAY_FIRST_EL)) / math.cos(phi))
    th = th0 + t * (math.pi - 2 * th0)
    return math.cos(th) * east + math.sin(th) * up


def build_daysun(scene):
    """(h) An animated day Sun over scene (f): a Sun lamp (Blender's default 0.526-degree
    size) whose rotation is keyframed at every frame 1..24, from 0.5 degrees above the eastern
    horizon over a 78-degree noon to the west."""
    import bpy
    from mathutils import Vector

    objs = build_shadows(scene)
    data = bpy.data.lights.new("DaySun", type="SUN")
    data.energy = 1.0
    sun = bpy.data.objects.new("DaySun", data)
    scene.collection.objects.link(sun)
    first, last = DAY_FRAMES
    scene.frame_start, scene.frame_end = first, last
    prev = None
    for f in range(first, last + 1):
        d = day_direction((f - first) / (last - first))
        q = Vector(d.tolist()).to_track_quat("Z", "Y")   # the lamp's +Z towards the sun
        e = q.to_euler("XYZ", prev) if prev is not None else q.to_euler("XYZ")
        sun.rotation_euler = e
        sun.keyframe_insert("rotation_euler", frame=f)
        prev = e
    for fc in _fcurves(sun):
        for k in fc.keyframe_points:
            k.interpolation = "LINEAR"
    scene.frame_set(first)
    return objs


def _fcurves(obj):
    """The F-curves of ``obj``'s action (Blender 5's layered actions, or the older list)."""
    act = obj.animation_data.action
    if hasattr(act, "fcurves"):
        return list(act.fcurves)
    out = []
    for layer in act.layers:
        for strip in layer.strips:
            for bag in strip.channelbags:
                out.extend(bag.fcurves)
    return out


def sun_direction(scene, name="DaySun"):
    """Towards the Sun ``name`` at the scene's current (sub)frame, as Blender evaluates it."""
    m = np.array(scene.objects[name].matrix_world, np.float64)[:3, 2]
    return m / np.linalg.norm(m)


def path_light(scene, elevation, name="DaySun"):
    """The frame (with subframe) of the morning at which the animated Sun stands at
    ``elevation`` degrees, and its direction there (bisection over the Sun's evaluated
    rotation; the current frame is restored). None when the Sun never gets that high."""
    first, last = scene.frame_start, scene.frame_end
    cur = scene.frame_current

    def at(x):
        f = int(math.floor(x))
        scene.frame_set(f, subframe=x - f)
        return sun_direction(scene, name)

    try:
        els = [(f, math.degrees(math.asin(at(f)[2]))) for f in range(first, last + 1)]
        peak = max(range(len(els)), key=lambda i: els[i][1])
        lo = next((i for i in range(peak + 1) if els[i][1] >= elevation), None)
        if lo is None:
            return None
        if lo == 0:
            x = float(first)
        else:
            a, b = float(els[lo - 1][0]), float(els[lo][0])
            for _ in range(40):
                m = 0.5 * (a + b)
                if math.degrees(math.asin(at(m)[2])) < elevation:
                    a = m
                else:
                    b = m
            x = 0.5 * (a + b)
        return x, at(x)
    finally:
        scene.frame_set(cur)


@dataclass(frozen=True)
class GalleryScene:
    key: str
    letter: str
    build: object
    what: str


SCENES = {s.key: s for s in (
    GalleryScene("relief", "a", build_relief, "displaced relief, planar UVs, flat-shaded"),
    GalleryScene("lowpoly", "b", build_lowpoly, "smooth 12x8 UV sphere on a floor"),
    GalleryScene("fence", "c", build_fence, "thin-featured: array fence on a floor"),
    GalleryScene("scan", "d", build_scan, "dense Suzanne (subdiv 2), Smart UV, on a floor"),
    GalleryScene("interior", "e", build_interior, "room lit through a window"),
    GalleryScene("shadows", "f", build_shadows, "boxes and cylinders shadowing each other"),
    GalleryScene("normalmap", "g", build_normalmap, "Normal Map + Bump (Noise, Brick) plane"),
    GalleryScene("daysun", "h", build_daysun, "scene f under a Sun animated over a day"),
)}


def resolve(names: str) -> list:
    """Scene keys from a comma list of keys or letters (``all``: every scene)."""
    if names.strip() == "all":
        return list(SCENES)
    by_letter = {s.letter: k for k, s in SCENES.items()}
    out = []
    for n in (x.strip() for x in names.split(",") if x.strip()):
        key = by_letter.get(n, n)
        if key not in SCENES:
            raise SystemExit(f"unknown gallery scene {n!r}; choose from "
                             + ", ".join(f"{s.letter}/{k}" for k, s in SCENES.items()))
        out.append(key)
    return out


#: The gallery's elevations (degrees), issue 55's.
ELEVATIONS = (1.0, 3.0, 8.0, 20.0, 45.0, 75.0)


def azimuth(key: str, elevation: float, i: int) -> float:
    """The fixed azimuth (degrees) of ``elevation``: 37 + 53 k, k its place in
    :data:`ELEVATIONS` (``i``, its place in the list asked for, for another elevation), so that a
    run over fewer elevations measures the same lights; the interior's sun stays within 20
    degrees of its window's normal (azimuth 0), -20 + 8 k, so that it comes in."""
    k = next((j for j, e in enumerate(ELEVATIONS) if abs(e - elevation) < 1e-9), i)
    if key == "interior":
        return -20.0 + 8.0 * (k % 6)
    return (37.0 + 53.0 * k) % 360.0


def lights(key: str, scene, elevations) -> list:
    """``[(label, azimuth, elevation, direction)]`` the scene is measured at: for the animated
    Sun, the Sun's own direction at the morning moment it reaches each elevation (label
    ``frame F``); else a fixed azimuth per elevation (:func:`azimuth`)."""
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

    out = []
    for i, el in enumerate(elevations):
        if key == "daysun":
            got = path_light(scene, el)
            if got is None:
                continue
            frame, d = got
            az = math.degrees(math.atan2(d[1], d[0])) % 360.0
            out.append((f"frame {frame:.2f}", az, float(el), np.asarray(d, np.float64)))
        else:
            az = azimuth(key, el, i)
            out.append(("", az, float(el), np.asarray(direction_from_az_el(az, el), np.float64)))
    return out
