"""Live viewport preview of a transport-texture PCA model: no Python per light change (bpy).

The model relights a sun from ``w0`` as ``albedo * sum_k c_k(w0) U_k`` (+ the indirect term).
``c_k`` is tabulated over the hemisphere disk (:func:`..lt_addon.transport.texture.
coefficient_tables`), so the node group only needs texture lookups:

1. the light's disk point ``(x0, y0) = (dx, dy) / sqrt(1 + dz)`` -> table coordinate
   ``((x0 + 1) / 2, (y0 + 1) / 2)``;
2. per group of three components, one lookup in the *table atlas* (coefficients in R, G, B)
   and one in the *eigen atlas* at the texel's UV (eigen-textures in R, G, B); their dot
   product, summed -- both atlases padded tiles, one GPU sampler each;
3. times the albedo tile of the eigen atlas, gated to 0 below the horizon;
4. plus the indirect term through the steerable group of :mod:`.preview_nodes`;
5. times intensity and colour.

:func:`viewport_relight` is the same computation in NumPy (bilinear table lookup, half-float
atlases), which the tests compare with a Cycles render of the group. The sun size is baked
into the tables; changing it rewrites them (:func:`install_transport_preview`, a few ms).
"""

from __future__ import annotations

import os

import bpy
import numpy as np

from ..lt_addon.io import exrio
from ..lt_addon.transport import texture as tt
from ..lt_addon.io.atlas import atlas_layout, pack_atlas
from . import preview_nodes as pn

GROUP_PREFIX = "Relight Transport"


def _tiles3(arr):
    """(K, R, R) -> (ceil(K/3), R, R, 3), zero-padded."""
    K, R = arr.shape[0], arr.shape[1]
    n = -(-K // 3)
    out = np.zeros((n * 3, R, R), np.float32)
    out[:K] = arr
    return out.reshape(n, 3, R, R).transpose(0, 2, 3, 1)


def preview_arrays(model: tt.TexturePCA, albedo, directions, sun_angle: float, table_size: int,
                   kernel: str = "linear"):
    """(eigen tiles (n+1, R, R, 3) with the albedo last, table tiles (n, D, D, 3)), float32."""
    R = model.resolution
    U = model.U.reshape(model.k, R, R)
    eig = np.concatenate([_tiles3(U), np.asarray(albedo, np.float32)[None]], axis=0)
    tables = tt.coefficient_tables(model.V, directions, table_size, sun_angle, kernel)
    return eig, _tiles3(tables)


def viewport_relight(eig_tiles, table_tiles, direction) -> np.ndarray:
    """NumPy twin of the node group (direct light only, intensity 1): (R, R, 3)."""
    eig = np.asarray(eig_tiles, np.float64)
    tab = np.asarray(table_tiles, np.float64)
    n = tab.shape[0]
    coeffs = tt.table_lookup(tab.transpose(0, 3, 1, 2).reshape(n * 3, *tab.shape[1:3]),
                             direction).reshape(n, 3)
    e = np.einsum("tc,tyxc->yx", coeffs, eig[:n])
    return (e[..., None] * eig[n]).astype(np.float32)


def write_preview_files(base: str, eig, tables) -> dict:
    """Write the two half-float atlases; returns their paths and bytes."""
    out = {}
    for name, arr in (("eigen", eig), ("tables", tables)):
        atlas = pack_atlas(arr.astype(np.float32), "edge")
        path = f"{base}_preview_{name}.exr"
        out[name] = path
        out[f"{name}_bytes"] = exrio.write_exr(
            path, {c: atlas[..., i] for i, c in enumerate("RGB")},
            {"format": "relightable_textures.transport_preview", "tiles": len(arr),
             "resolution": arr.shape[1]}, pixel_type="half")
    return out


def _lookup(b, image, uv, tile, x, y):
    su, sv, ou, ov = tile
    mapping = b.node("ShaderNodeMapping", x, y, vector_type="POINT")
    b.links.new(uv, mapping.inputs["Vector"])
    mapping.inputs["Location"].default_value = (ou, ov, 0.0)
    mapping.inputs["Scale"].default_value = (su, sv, 1.0)
    tex = b.node("ShaderNodeTexImage", x + 200, y, image=image, interpolation="Linear",
                 extension="EXTEND")
    b.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    return tex.outputs["Color"]


def build_group(n_tiles: int, resolution: int, table_size: int, eig_image, table_image,
                uv_map: str, name: str):
    """The node group: inputs Light Direction, Intensity, Color; output Color (direct light)."""
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group[pn._TAG] = True
    iface = group.interface
    s = iface.new_socket("Light Direction", in_out="INPUT", socket_type="NodeSocketVector")
    s.default_value = (0.0, 0.0, 1.0)
    s = iface.new_socket("Intensity", in_out="INPUT", socket_type="NodeSocketFloat")
    s.default_value, s.min_value = 1.0, 0.0
    s = iface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    s.default_value = (1.0, 1.0, 1.0, 1.0)
    iface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    b = pn._Builder(group)
    gin = b.node("NodeGroupInput", -1800, 0)
    gout = b.node("NodeGroupOutput", 1600, 0)
    d = b.vmath("NORMALIZE", gin.outputs["Light Direction"], x=-1600, y=0)
    sep = b.node("ShaderNodeSeparateXYZ", -1400, 0)
    b.links.new(d, sep.inputs[0])
    dx, dy, dz = sep.outputs["X"], sep.outputs["Y"], sep.outputs["Z"]
    root = b.math("SQRT", b.math("MAXIMUM", b.math("ADD", dz, 1.0, x=-1200, y=-100), 1e-6,
                                 x=-1100, y=-100), x=-1000, y=-100)
    tx = b.math("MULTIPLY_ADD", b.math("DIVIDE", dx, root, x=-900, y=100), 0.5, 0.5, x=-800, y=100)
    ty = b.math("MULTIPLY_ADD", b.math("DIVIDE", dy, root, x=-900, y=0), 0.5, 0.5, x=-800, y=0)
    table_uv = b.node("ShaderNodeCombineXYZ", -700, 50)
    b.links.new(tx, table_uv.inputs[0])
    b.links.new(ty, table_uv.inputs[1])
    uv = b.node("ShaderNodeUVMap", -700, -400, uv_map=uv_map).outputs["UV"]
    lay_e = atlas_layout(n_tiles + 1, resolution)
    lay_t = atlas_layout(n_tiles, table_size)
    acc = None
    for t in range(n_tiles):
        y = 600 - 220 * t
        c = _lookup(b, table_image, table_uv.outputs[0], lay_t["tiles"][t], -500, y)
        e = _lookup(b, eig_image, uv, lay_e["tiles"][t], -500, y - 100)
        dot = b.vmath("DOT_PRODUCT", c, e, x=-50, y=y)
        acc = dot if acc is None else b.math("ADD", acc, dot, x=150, y=y)
    albedo = _lookup(b, eig_image, uv, lay_e["tiles"][n_tiles], -500, -600)
    lit = b.math("GREATER_THAN", dz, 0.0, x=150, y=-200)
    scale = b.math("MULTIPLY", b.math("MULTIPLY", acc, lit, x=350, y=-100),
                   gin.outputs["Intensity"], x=550, y=-100)
    color = b.vmath("SCALE", albedo, x=750, y=-300, scale=scale)
    color = b.vmath("MULTIPLY", color, gin.outputs["Color"], x=950, y=-300)
    b.links.new(color, gout.inputs["Color"])
    return group


def install_transport_preview(scene, obj, report: dict, bake, store, sun_angle: float | None = None,
                              sun=None) -> dict:
    """Write the atlases, build the group(s) and wire them into ``obj``'s materials (replacing
    an earlier preview of ``obj``). The indirect term, when baked, goes through the steerable
    group of :mod:`.preview_nodes`."""
    s = report["settings"]
    angle = float(s["sun_angle"] if sun_angle is None else sun_angle)
    model = bake.model
    if not getattr(model, "live_preview", False):
        raise ValueError("the live preview shows PCA models (model 'pca'); this bake has "
                         f"{report['model']['kind']!r}")
    eig, tables = preview_arrays(model, bake.albedo, store.directions, angle, s["table_size"],
                                 s.get("kernel", "linear"))
    base = os.path.splitext(report["report"])[0].removesuffix("_texture_report")
    files = write_preview_files(base, eig, tables)
    eig_img = pn.load_atlas_image(files["eigen"], f"{obj.name} transport eigen atlas")
    tab_img = pn.load_atlas_image(files["tables"], f"{obj.name} transport tables")
    uv_map = next((uv.name for uv in obj.data.uv_layers if uv.active_render),
                  obj.data.uv_layers[0].name)
    gname = f"{GROUP_PREFIX} ({obj.name})"
    old = bpy.data.node_groups.get(gname)
    group = build_group(len(tables), model.resolution, s["table_size"], eig_img, tab_img,
                        uv_map, gname + " new")
    if old is not None:
        bpy.data.node_groups.remove(old)
    group.name = gname
    indirect_group = None
    if bake.indirect is not None:
        iname = f"{GROUP_PREFIX} indirect ({obj.name})"
        ipath = report["files"]["indirect"]
        atlas_path, _ = pn.write_atlas(bake.indirect, ipath)
        iimg = pn.load_atlas_image(atlas_path, f"{obj.name} indirect atlas")
        old = bpy.data.node_groups.get(iname)
        indirect_group = pn.build_group(bake.indirect, iimg, uv_map, name=iname + " new")
        if old is not None:
            bpy.data.node_groups.remove(old)
        indirect_group.name = iname
    pn.ensure_sliders(scene)
    if sun is None:
        sun = scene.get("relight_sun")

    def color(b):
        direction, intensity, col, _ = pn._controls(b, scene, sun, -200, 800)
        g = b.node("ShaderNodeGroup", 700, 800, node_tree=group, label="Relight Transport")
        for k, v in (("Light Direction", direction), ("Intensity", intensity), ("Color", col)):
            b.links.new(v, g.inputs[k])
        out = g.outputs["Color"]
        if indirect_group is not None:
            gi = b.node("ShaderNodeGroup", 700, 600, node_tree=indirect_group,
                        label="Indirect (steerable)")
            for k, v in (("Light Direction", direction), ("Intensity", intensity),
                         ("Color", col)):
                b.links.new(v, gi.inputs[k])
            out = b.vmath("ADD", out, gi.outputs["Color"], x=900, y=700)
        return out

    pn._wire_preview(obj, color, "transport_texture")
    return {**files, "group": gname, "group_nodes": len(group.nodes), "sun_angle": angle,
            "tiles": len(tables)}


def rewrite_tables(obj, report: dict, bake, store, sun_angle: float) -> None:
    """Re-tabulate the coefficients for ``sun_angle`` and reload the table image in place."""
    s = report["settings"]
    tables = _tiles3(tt.coefficient_tables(bake.model.V, store.directions, s["table_size"],
                                           sun_angle, s.get("kernel", "linear")))
    base = os.path.splitext(report["report"])[0].removesuffix("_texture_report")
    atlas = pack_atlas(tables, "edge")
    path = f"{base}_preview_tables.exr"
    exrio.write_exr(path, {c: atlas[..., i] for i, c in enumerate("RGB")},
                    {"format": "relightable_textures.transport_preview", "tiles": len(tables),
                     "resolution": tables.shape[1], "sun_angle": sun_angle}, pixel_type="half")
    pn.load_atlas_image(path, f"{obj.name} transport tables")
