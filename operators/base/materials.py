"""The scene's materials as the bakes see them (bpy): the BSDF on a material's own output, the
colour an edit changes, its Metallic and Roughness, and every material the rendered meshes use.
Read by the material bakes, their rays, their preview and the panel."""

from __future__ import annotations

import numpy as np


def material_bsdf(mat):
    """The BSDF node on the material's own active output (not a relight preview's), or None."""
    tree = mat.node_tree if mat is not None else None
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"
            and not n.get("relight_preview")] if tree else []
    out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
    return (out.inputs["Surface"].links[0].from_node
            if out is not None and out.inputs["Surface"].is_linked else None)


def material_colour_socket(mat):
    """The unlinked Base Color / Color socket of the BSDF on the material's own active output
    (the colour an edit changes), or None."""
    node = material_bsdf(mat)
    socket = {"ShaderNodeBsdfPrincipled": "Base Color", "ShaderNodeBsdfDiffuse": "Color"}.get(
        getattr(node, "bl_idname", ""))
    return node.inputs[socket] if socket and not node.inputs[socket].is_linked else None


def finish_sockets(mat) -> dict:
    """The unlinked Metallic and Roughness sockets of the material's Principled BSDF
    (``{"metallic": socket, "roughness": socket}``, fewer where linked or not Principled)."""
    node = material_bsdf(mat)
    if node is None or node.bl_idname != "ShaderNodeBsdfPrincipled":
        return {}
    return {k.lower(): node.inputs[k] for k in ("Metallic", "Roughness")
            if not node.inputs[k].is_linked}


def material_finish(mat) -> tuple:
    """``(metallic, roughness)`` of the material's Principled BSDF (unlinked inputs; a linked
    one counts as 0 / 0.5), ``(0, 0.5)`` for anything else: the finish glossy anchors edit."""
    knobs = finish_sockets(mat)
    return tuple(float(knobs[k].default_value) if k in knobs else default
                 for k, default in (("metallic", 0.0), ("roughness", 0.5)))


def material_colour(mat) -> tuple[np.ndarray, str | None]:
    """The diffuse colour a material bakes with (RGB float64) and, when it is not an unlinked
    Base Color / Color of its own output's BSDF, why the viewport colour stands in."""
    if mat is None:
        return np.full(3, 0.8), "no material: grey 0.8"
    socket = material_colour_socket(mat)
    if socket is not None:
        return np.array(socket.default_value[:3], dtype=np.float64), None
    return (np.array(mat.diffuse_color[:3], dtype=np.float64),
            f"{mat.name!r}'s colour is not an unlinked Principled Base Color or Diffuse Color "
            "(a texture, another node): its viewport colour stands in")


def scene_materials(scene) -> list:
    """Every material (or None for an empty slot list) on the scene's rendered meshes."""
    seen, out = set(), []
    for o in scene.objects:
        if o.type != "MESH" or o.hide_render:
            continue
        mats = [s.material for s in o.material_slots] or [None]
        for m in mats:
            key = m.name if m is not None else None
            if key not in seen:
                seen.add(key)
                out.append(m)
    return out
