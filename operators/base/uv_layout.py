"""The UV layout check of a texture bake, on the mesh the render bakes (issue 59).

Texels claimed by more than one triangle of one object -- overlapping UV islands, or the copies
an Array or Mirror modifier makes, which share the base mesh's UVs -- are written by whichever
face is baked last; the bake then mixes unrelated surfaces. :func:`uv_layout` counts them
(:func:`...lt_addon.geometry.uv_layout.uv_overlap_report`) over the evaluated mesh's triangles in
the bake's UV map, for the report and its warning (:mod:`...lt_addon.caveats`).
"""

from __future__ import annotations

import numpy as np

#: The check's texel grid: the bake's side, at most this (the count is per texel centre; a
#: coarser grid keeps it a fraction of a second on large meshes).
MAX_CHECK_SIDE = 256


def _uv_map_name(obj) -> str | None:
    """The map the bake writes into (:func:`.meshes.bake_uv_name`), None without a UV map."""
    from .meshes import bake_uv_name

    return bake_uv_name(obj) if len(obj.data.uv_layers) else None


def evaluated_uv_triangles(obj, depsgraph=None) -> np.ndarray:
    """UVs of the triangles of ``obj``'s evaluated mesh (modifiers applied), shape (T, 3, 2);
    empty without a UV map."""
    import bpy

    name = _uv_map_name(obj)
    dg = depsgraph or bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    mesh = ev.to_mesh()
    try:
        layer = mesh.uv_layers.get(name) if name else None
        if layer is None:
            return np.zeros((0, 3, 2))
        mesh.calc_loop_triangles()
        loops = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("loops", loops)
        uv = np.empty(len(mesh.loops) * 2, dtype=np.float64)
        layer.data.foreach_get("uv", uv)
        return uv.reshape(-1, 2)[loops].reshape(-1, 3, 2)
    finally:
        ev.to_mesh_clear()


def uv_layout(obj, resolution: int) -> dict:
    """The report's ``uv_layout`` of ``obj`` baked at ``resolution``^2: covered and overlapping
    shares of the texels (:func:`...lt_addon.geometry.uv_layout.uv_overlap_report`)."""
    from ...lt_addon.geometry.uv_layout import uv_overlap_report

    tris = evaluated_uv_triangles(obj)
    tris = tris[np.all(np.isfinite(tris), axis=(1, 2))]
    return uv_overlap_report(tris, max(1, min(int(resolution), MAX_CHECK_SIDE)))
