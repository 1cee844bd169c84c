"""What a bake's result depends on in the scene, as a JSON-able key for the chunk cache (bpy).

:func:`scene_key` describes every object that can cast a shadow or receive light in a bake:
its evaluated geometry (modifiers applied: positions, corners, smooth flags, UVs as SHA-256 of
their bytes), its world matrix and its materials' node trees (every node's settings and input
values, the links, images by file, size and packed size). Lamps and the world are not in it:
the bakes replace both with their own lights. Blender's and this extension's versions are, as
Cycles' output may change between them.

Known blind spot, said so in docs/transport-textures.md (Resume and cancel): an image edited in
Blender and not saved or packed again keeps its key (its pixels are not hashed; a 4k image would
cost seconds per bake).
"""

from __future__ import annotations

import os

import hashlib

import bpy
import numpy as np

from ... import __version__

#: The chunk cache's folder inside a bake's output folder (hidden; removed when the bake
#: completes). :class:`...lt_addon.io.chunk_cache.ChunkCache` checks every folder from it down
#: to a key's folder is a real folder (a symlinked cache is refused, never followed).
from ...lt_addon.io.chunk_cache import CACHE_FOLDER  # (".relight_cache")


def cache_root(out_dir: str) -> str:
    """The chunk cache folder of a bake into ``out_dir``: in the output folder itself, also
    when ``out_dir`` is the bake's staging folder (the chunks outlive a killed or failed run,
    the stage does not)."""
    from ...lt_addon.io.transaction import target_of

    return os.path.join(target_of(out_dir), CACHE_FOLDER)
#: Object types whose evaluated geometry Cycles renders.
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME"}
#: Node RNA properties that are layout or UI state, not shading.
_UI_PROPS = {"rna_type", "name", "label", "location", "location_absolute", "width", "height",
             "dimensions", "select", "show_options", "show_preview", "hide", "mute",
             "show_texture", "color", "use_custom_color", "parent", "bl_idname", "bl_label",
             "bl_description", "bl_icon", "bl_static_type", "bl_width_default",
             "bl_width_min", "bl_width_max", "bl_height_default", "bl_height_min",
             "bl_height_max", "type", "internal_links", "inputs", "outputs", "warning_propagation",
             "is_active_output", "color_tag"}


def _sha(array) -> str:
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def _value(v):
    """A socket default or node property as JSON-able data (floats rounded to 7 digits)."""
    if isinstance(v, float):
        return round(v, 7)
    if isinstance(v, (bool, int, str)) or v is None:
        return v
    if isinstance(v, bpy.types.ID):
        return f"ID:{v.name}"
    try:
        return [_value(x) for x in v]
    except TypeError:
        return str(v)


def _image(img) -> dict:
    return {"name": img.name, "file": img.filepath, "size": list(img.size),
            "source": img.source,
            "packed": img.packed_file.size if img.packed_file is not None else 0,
            "colorspace": img.colorspace_settings.name}


def _node_tree(tree, seen: set) -> dict:
    """Every shading-relevant setting of ``tree`` (node groups followed once)."""
    nodes = {}
    for node in tree.nodes:
        if node.get("relight_preview"):   # our own preview nodes are swapped out for bakes
            continue
        props = {}
        for p in node.bl_rna.properties:
            if p.identifier in _UI_PROPS or p.type == "COLLECTION":
                continue
            v = getattr(node, p.identifier, None)
            if isinstance(v, bpy.types.Image):
                props[p.identifier] = _image(v)
            elif isinstance(v, bpy.types.NodeTree):
                props[p.identifier] = v.name
                if v.name not in seen:
                    seen.add(v.name)
                    props["group"] = _node_tree(v, seen)
            elif isinstance(v, bpy.types.ID):   # e.g. a Texture Coordinate's object
                props[p.identifier] = f"ID:{v.name}"
            elif p.type != "POINTER":
                props[p.identifier] = _value(v)
        props["inputs"] = [_value(s.default_value) if hasattr(s, "default_value") else None
                           for s in node.inputs]
        nodes[node.name] = props
    links = sorted([l.from_node.name, l.from_socket.identifier, l.to_node.name,
                    l.to_socket.identifier] for l in tree.links
                   if not l.from_node.get("relight_preview") and not l.to_node.get("relight_preview"))
    return {"nodes": nodes, "links": links}


def _material(mat) -> dict | None:
    if mat is None:
        return None
    out = {"name": mat.name, "diffuse_color": _value(mat.diffuse_color)}
    if mat.node_tree is not None:
        out["tree"] = _node_tree(mat.node_tree, set())
    return out


def _bake_uv(obj):
    """The UV map the bake reads (:func:`.meshes.bake_uv_name`), or None (no map, or not the
    one chosen: the bake refuses it)."""
    from ...lt_addon.errors import InputError
    from .meshes import bake_uv_name

    try:
        return bake_uv_name(obj) if obj.type == "MESH" and obj.data.uv_layers else None
    except InputError:
        return None


def _geometry(obj, depsgraph) -> dict:
    ev = obj.evaluated_get(depsgraph)
    try:
        mesh = ev.to_mesh()
    except RuntimeError:
        return {"type": obj.type}
    try:
        from .meshes import corner_vertices, uv_corners, vertex_positions

        smooth = np.zeros(len(mesh.polygons), dtype=bool)
        mesh.polygons.foreach_get("use_smooth", smooth)
        return {"type": obj.type, "positions": _sha(vertex_positions(mesh)),
                "corners": _sha(corner_vertices(mesh)), "smooth": _sha(smooth),
                "uvs": {layer.name: _sha(uv_corners(mesh, layer)) for layer in mesh.uv_layers},
                "active_uv": _bake_uv(obj)}
    finally:
        ev.to_mesh_clear()


def scene_key(scene, baked) -> dict:
    """The key of everything in ``scene`` a bake of the objects ``baked`` depends on."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    objects = {}
    for obj in sorted(scene.objects, key=lambda o: o.name):
        if obj.type not in GEOMETRY_TYPES or obj.hide_render:
            continue
        objects[obj.name] = {
            "matrix": _value([list(row) for row in obj.matrix_world]),
            "geometry": _geometry(obj, depsgraph),
            "materials": [_material(s.material) for s in obj.material_slots],
            "visible_shadow": bool(getattr(obj, "visible_shadow", True)),
        }
    return {"blender": bpy.app.version_string, "extension": __version__,
            "baked": [o.name for o in baked], "objects": objects}
