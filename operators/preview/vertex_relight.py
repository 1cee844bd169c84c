"""Eigentransport relighting of baked per-vertex transport (bpy side).

The sidecar format and the shading are bpy-free (:mod:`..lt_addon.transport.sidecar`); this
module reads what Blender holds (the world's environment, the evaluated mesh, the point lamp)
and writes the result: one colour attribute per object, the only thing that goes to the GPU.
Coefficients are not stored as mesh attributes: a GPU material reads at most ~15 vertex
attributes (DESIGN.md sec. 4) and d is typically 20-150. With the scene's ``show_clusters``
toggle the preview colours each vertex by its CPCA cluster.
"""

from __future__ import annotations

import os
import time

import bpy
import numpy as np

from ...lt_addon.transport.sidecar import TransportData
from ..base.meshes import image_pixels, set_color_attribute, vertex_normals, vertex_positions

KIND = "eigentransport"
SHADING_ATTRIBUTE = "relight_shading"
#: Scene property holding the last vertex-preview warning (e.g. a lamp inside the hull).
WARNING_KEY = "relight_vertex_warning"


def world_environment(scene):
    """The scene world's light as an equirect (H, W, 3) radiance image, bottom row first: its
    Environment Texture (or else its constant Background colour) times the Background strength;
    None if neither can be read (e.g. a procedural sky)."""
    pixels, strength = world_light(scene)
    return None if pixels is None else pixels * strength


_PIXELS: dict = {}


def world_light(scene):
    """(pixels (H, W, 3) float64 bottom row first, or None; Background strength): the world's
    Environment Texture image -- read from Blender once per image and kept (an unsaved,
    painted image is read again every time) -- or its constant Background colour."""
    world = scene.world
    if world is None or world.node_tree is None:
        return None, 1.0
    tex = next((n for n in world.node_tree.nodes
                if n.bl_idname == "ShaderNodeTexEnvironment" and n.image is not None), None)
    bg = next((n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground"), None)
    strength = float(bg.inputs["Strength"].default_value) if bg is not None else 1.0
    if tex is None:
        if bg is None or bg.inputs["Color"].is_linked:
            return None, strength
        color = np.array(bg.inputs["Color"].default_value[:3], dtype=np.float64)
        return np.broadcast_to(color, (8, 16, 3)).copy(), strength  # a constant sky
    img = tex.image
    w, h = img.size
    if not w or not h:
        return None, strength
    key = (img.name_full, w, h, img.filepath_raw, img.source)
    hit = _PIXELS.get("image")
    if hit is None or hit[0] != key or img.is_dirty:
        hit = _PIXELS["image"] = (key, image_pixels(img)[..., :3].astype(np.float64))
    return hit[1], strength


def world_rotation(scene) -> tuple[float, str]:
    """(degrees, note): the Z rotation of the Mapping node that feeds the world's Environment
    Texture, in that node's own convention for the Point type (0 without one), and a note
    saying what the preview cannot follow ("" when it follows everything).

    Vector and Normal mappings rotate like Point; a Texture mapping applies the inverse, so its
    rotation counts negated. X/Y rotation, location and scale are not followed (the note says
    so): the eigentransport preview rotates its lighting about +z only (paper sec. 5)."""
    world = scene.world
    if world is None or world.node_tree is None:
        return 0.0, ""
    tex = next((n for n in world.node_tree.nodes
                if n.bl_idname == "ShaderNodeTexEnvironment" and n.image is not None), None)
    if tex is None or not tex.inputs["Vector"].is_linked:
        return 0.0, ""
    node = tex.inputs["Vector"].links[0].from_node
    if node.bl_idname != "ShaderNodeMapping":
        return 0.0, (f"the world's {node.name} node feeding the environment is not followed; "
                     "the preview uses the image unrotated")
    rot = node.inputs["Rotation"]
    if rot.is_linked:
        return 0.0, "the world Mapping rotation is driven by a link; the preview ignores it"
    x, y, z = (float(np.degrees(a)) for a in rot.default_value)
    notes = []
    if abs(x) > 1e-6 or abs(y) > 1e-6:
        notes.append("X/Y rotation")
    if node.vector_type == "POINT" and np.any(np.abs(node.inputs["Location"].default_value)
                                              > 1e-9):
        notes.append("location")
    if node.vector_type in ("POINT", "TEXTURE") and np.any(
            np.abs(np.asarray(node.inputs["Scale"].default_value) - 1.0) > 1e-9):
        notes.append("scale")
    note = ("the world Mapping's " + ", ".join(notes) + " are not followed by the preview "
            "(Z rotation only)") if notes else ""
    return (-z if node.vector_type == "TEXTURE" else z), note


def shade_rotation(mapping_deg: float) -> float:
    """The rotation :meth:`TransportData.shade` takes (environment content turned
    counter-clockwise seen from above: ``L(R^T w)``) for a Mapping node (Point type) Z rotation
    of ``mapping_deg``: its negative. A Point mapping rotates the *lookup* direction, so the
    picture turns the other way -- measured in a Cycles vertex bake: a Mapping Z rotation of
    +90 deg moved a bright spot of the environment from azimuth 112.5 to 22.5 deg."""
    return -float(mapping_deg)


def mesh_positions_normals(obj) -> tuple[np.ndarray, np.ndarray]:
    """World-space positions (V, 3) and unit normals (V, 3) of the base vertices where the bake
    saw them: on the evaluated mesh (modifiers applied), as the transport was baked.

    Topology-preserving modifiers (Displace, Shrinkwrap ...) keep vertex ``i`` at index ``i``;
    Subdivision Surface puts the base vertices first, at their subdivided positions. A modifier
    that leaves fewer vertices than the base mesh (Decimate, Weld ...) cannot be mapped back;
    the base mesh is used then."""
    V = len(obj.data.vertices)
    mesh, evaluated = obj.data, None
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = obj.evaluated_get(depsgraph)
        ev_mesh = evaluated.to_mesh()
        if len(ev_mesh.vertices) >= V:
            mesh = ev_mesh
    except (RuntimeError, AttributeError):
        evaluated = None
    try:
        co, n = vertex_positions(mesh)[:V], vertex_normals(mesh)[:V]
    finally:
        if evaluated is not None:
            evaluated.to_mesh_clear()
    m = np.array(obj.matrix_world, dtype=np.float64)
    pos = co @ m[:3, :3].T + m[:3, 3]
    nrm = n @ np.linalg.inv(m[:3, :3])  # inverse transpose for normals
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    return pos, nrm


# ---------------------------------------------------------------------------------------------
# the viewport preview: one colour attribute written from NumPy


def write_shading(obj, values: np.ndarray) -> None:
    """Write (V, 3) linear RGB into the FLOAT_COLOR point attribute ``relight_shading``."""
    mesh = obj.data
    attr = mesh.color_attributes.get(SHADING_ATTRIBUTE)
    if attr is None or attr.domain != "POINT" or attr.data_type != "FLOAT_COLOR":
        if attr is not None:
            mesh.color_attributes.remove(attr)
        attr = mesh.color_attributes.new(SHADING_ATTRIBUTE, "FLOAT_COLOR", "POINT")
    set_color_attribute(attr, values)
    mesh.update()


_CACHE: dict = {}


def transport_data(obj) -> TransportData:
    """The object's sidecar, loaded once and cached until the file changes."""
    from ..base.blend_files import bake_file

    path = bake_file(obj, KIND, "eigentransport")
    key = (obj.name, path, os.path.getmtime(path))
    if key not in _CACHE:
        _CACHE.clear()
        _CACHE[key] = TransportData(path)
    return _CACHE[key]


def shade(data, env, rotation, strength: float = 1.0, light=None) -> tuple:
    """One bake's vertex radiance (V, 3) under the environment ``env`` (turned by the lattice
    ``rotation``, :func:`shade_rotation`) times ``strength`` plus the point ``light`` (position,
    power, colour) or None, and the warnings the shading raised, as text. What the preview and
    ``relight relight-vertices`` both show."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        values = data.shade(env, rotation, strength, light)
    return values, [str(w.message) for w in caught]


def update_preview(scene) -> dict:
    """Recompute the shading of every object with a transport bake; returns ms timings per
    object and ``"warnings"`` (also kept in ``scene[WARNING_KEY]`` for the panel).

    With ``scene.relight.show_clusters`` the vertices get their CPCA cluster colours instead."""
    props = getattr(scene, "relight", None)
    baked = []
    for obj in scene.objects:
        if obj.type != "MESH" or "relightable_bakes" not in obj:
            continue
        try:
            baked.append((obj, transport_data(obj)))
        except (ValueError, FileNotFoundError):
            continue
    if not baked:                   # nothing to shade: the world's pixels are not read
        if scene.get(WARNING_KEY):
            scene[WARNING_KEY] = ""
        return {"warnings": []}
    env = world_environment(scene)
    world_z, note = world_rotation(scene)
    # the slider adds to the world's own Mapping rotation, in the same (Mapping) convention
    rotation = shade_rotation(world_z + (props.env_rotation if props else 0.0))
    timings = {}
    messages = []
    for obj, data in baked:
        t0 = time.perf_counter()
        if props is not None and props.show_clusters:
            write_shading(obj, data.cluster_colors())
            timings[obj.name] = {"clusters_ms": 1e3 * (time.perf_counter() - t0)}
            continue
        light = None
        if props is not None and props.point_light is not None:
            lamp = props.point_light
            light = (np.array(lamp.matrix_world.translation), float(lamp.data.energy),
                     tuple(lamp.data.color))
        values, said = shade(data, env, rotation, props.env_strength if props else 1.0, light)
        messages += [f"{obj.name}: {w}" for w in said]
        t1 = time.perf_counter()
        write_shading(obj, values)
        timings[obj.name] = {"shade_ms": 1e3 * (t1 - t0),
                             "write_ms": 1e3 * (time.perf_counter() - t1)}
    if note and env is not None and timings:
        messages.insert(0, note)
    # the panel shows it (a property callback or handler has no operator to report to)
    text = "; ".join(messages)
    if scene.get(WARNING_KEY, "") != text:
        scene[WARNING_KEY] = text
    timings["warnings"] = messages
    return timings
