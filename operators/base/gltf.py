"""The object as glTF binary for a game engine's lightmap: Blender's own glTF exporter on a
temporary copy whose UV maps are (the texture map, the bake's map), so the bake's map is
``TEXCOORD_1`` (what Godot imports as UV2 and samples lightmaps with).

Materials are not exported: the glTF exporter walks a material's node tree exhaustively, and
a relit object's tree (the preview's node groups) took it over 10 minutes on the bumps demo
without finishing; the engine's default material shows the lightmap, and the user's own
materials go on in the engine.

The copy carries the original's name (the original is renamed for the duration and given
its name back), so the glTF node -- and the engine's node -- is named as in Blender; nothing
in the user's file changes: the copy, its mesh and the rename are undone in ``finally``.
"""

from __future__ import annotations

import numpy as np

LIGHTMAP_UV = "Lightmap"


def _uvs(layer) -> np.ndarray:
    uv = np.empty(len(layer.data) * 2, np.float32)
    layer.data.foreach_get("uv", uv)
    return uv


def write_glb(scene, obj, path: str, uv_map: str | None = None) -> dict:
    """Write ``obj`` (modifiers applied as for the render, world transform as the node's) to
    ``path`` with TEXCOORD_0 = its first non-bake UV map (or the bake map when it has one
    map) and TEXCOORD_1 = the bake's UV map (``uv_map``, the one its report names, else the
    rule of :func:`.meshes.baked_uv_name`). Returns what was written: {"node", "texcoord_0",
    "texcoord_1"}."""
    import bpy

    mesh = obj.data
    from .meshes import baked_uv_name

    bake_uv = baked_uv_name(obj, {"uv_map": uv_map})
    first = next((uv.name for uv in mesh.uv_layers if uv.name != bake_uv), bake_uv)
    name = obj.name
    coll = bpy.data.collections.new("relight-gltf-export")
    scene.collection.children.link(coll)
    copy_mesh = mesh.copy()
    tex, light = _uvs(mesh.uv_layers[first]), _uvs(mesh.uv_layers[bake_uv])
    while copy_mesh.uv_layers:
        copy_mesh.uv_layers.remove(copy_mesh.uv_layers[0])
    for uv_name, data in ((first, tex), (LIGHTMAP_UV, light)):
        layer = copy_mesh.uv_layers.new(name=uv_name if uv_name != LIGHTMAP_UV else
                                        uv_name + "_0")
        layer.data.foreach_set("uv", data)
    copy_mesh.uv_layers[0].active_render = True
    copy = obj.copy()
    copy.data = copy_mesh
    copy.parent = None
    copy.matrix_world = obj.matrix_world.copy()
    coll.objects.link(copy)
    obj.name = name + ".relight-original"
    copy.name = name
    view_layer = scene.view_layers[0]
    selected = [o for o in view_layer.objects if o.select_get(view_layer=view_layer)]
    active = view_layer.objects.active
    try:
        for o in selected:
            o.select_set(False, view_layer=view_layer)
        copy.select_set(True, view_layer=view_layer)
        view_layer.objects.active = copy
        with bpy.context.temp_override(scene=scene, view_layer=view_layer,
                                       active_object=copy, object=copy,
                                       selected_objects=[copy]):
            bpy.ops.export_scene.gltf(filepath=path, export_format="GLB",
                                      use_selection=True, export_apply=True,
                                      export_texcoords=True, export_normals=True,
                                      export_materials="NONE", export_animations=False)
    finally:
        copy.select_set(False, view_layer=view_layer)
        bpy.data.objects.remove(copy)
        bpy.data.meshes.remove(copy_mesh)
        bpy.data.collections.remove(coll)
        obj.name = name
        for o in selected:
            o.select_set(True, view_layer=view_layer)
        view_layer.objects.active = active
    return {"node": name, "texcoord_0": first, "texcoord_1": bake_uv}
