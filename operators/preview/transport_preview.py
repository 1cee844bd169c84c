"""Live viewport preview of a transport-texture bake: no Python per light change (bpy).

Two sun groups, chosen by the bake's ``viewport`` setting (:func:`install_transport_preview`):

* **from T itself** (:func:`build_sparse_group`): an 8-bit atlas of T, three directions per
  RGB tile, and sparse kernel tables over the hemisphere disk
  (:mod:`..lt_addon.transport.sparse_tables`): per pixel the four table texels around the
  light's disk point, six directions each. Keeps cast shadows on large receivers; its NumPy
  twin is :func:`viewport_relight_sparse`;
* **from the PCA** (:func:`build_group`), described below; the World light always uses the PCA.

The model relights a sun from ``w0`` as ``albedo * sum_k c_k(w0) U_k`` (+ the indirect term).
``c_k`` is tabulated over the hemisphere disk (:func:`..lt_addon.transport.texture.
coefficient_tables`), so the node group only needs texture lookups:

1. the light's disk point ``(x0, y0) = (dx, dy) / sqrt(1 + dz)`` -> table coordinate
   ``((x0 + 1) / 2, (y0 + 1) / 2)``;
2. per group of three components, one lookup in the *table atlas* (coefficients in R, G, B)
   and one in the *eigen atlas* at the texel's UV (eigen-textures in R, G, B); their dot
   product, summed -- both atlases padded tiles, one GPU sampler each;
3. times the albedo tile of the eigen atlas, gated to 0 below the horizon;
4. plus the indirect term: the gathered term's group (:func:`build_gathered_group`: its own
   coefficient tables over the sun's disk and k RGB component images; twin
   ``gathered_texture.viewport_relight``), or the steerable group of :mod:`.preview_nodes`;
5. times intensity and colour.

:func:`viewport_relight` is the same computation in NumPy (bilinear table lookup, half-float
atlases), which the tests compare with a Cycles render of the group. The sun size is baked
into the tables; changing it rewrites them (:func:`install_transport_preview`, a few ms).

**The world's environment** (the scene's *Texture Light* set to World): an environment is
``sum_s L(w_s) dw_s T[s]``, so each component gets one RGB coefficient ``C[:, k] = sum_s L_s
dw_s V[s, k]`` and each indirect image one ``G[:, j]``: ``sum_s L_s dw_s V_ind[s, j]`` for the
gathered term's components, ``sum_s L_s dw_s gain(w_s) c_j(w_s)`` for a steerable basis
image. The *environment groups* (:func:`build_env_group`, :func:`build_env_indirect_group`)
have the sun groups' sockets, so switching swaps the groups' trees and keeps every link; they
hold ``C`` and ``G`` as constants that Python rewrites when the world, its Mapping Z rotation or
the Environment Rotation / Strength change (:func:`update_environment_previews`, one small
matrix product: no re-bake, no texture rewrite). :func:`viewport_relight_env` is its NumPy twin.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

import time

from ...lt_addon.io import exrio, untrusted
from ...lt_addon.transport import sparse_tables as sp
from ...lt_addon.transport import gathered_texture as gt
from ...lt_addon.transport import texture as tt
from ...lt_addon.io.atlas import atlas_layout, pack_atlas
from ..base.meshes import baked_uv_name
from . import preview_nodes as pn

GROUP_PREFIX = "Relight Transport"
ENV_PREFIX = "Relight Transport env"
#: Scene property holding the last environment-preview warning (shown in the panel).
ENV_WARNING_KEY = "relight_texture_env_warning"


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


def write_preview_files(base: str, eig, tables, names=("eigen", "tables"),
                        fmt: str = "relightable_textures.transport_preview") -> dict:
    """Write the two half-float atlases ``<base>_preview_<name>.exr`` (the PCA's by default;
    :func:`write_block_files` the block viewport's); returns their paths and bytes."""
    out = {}
    for name, arr in zip(names, (eig, tables)):
        atlas = pack_atlas(arr.astype(np.float32), "edge")
        path = f"{base}_preview_{name}.exr"
        out[name] = path
        out[f"{name}_bytes"] = exrio.write_exr(
            path, {c: atlas[..., i] for i, c in enumerate("RGB")},
            {"format": fmt, "tiles": len(arr), "resolution": arr.shape[1]}, pixel_type="half")
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


def _sun_group_head(name: str, x_in: float, x_out: float, albedo_input: bool = False):
    """A new sun group (light inputs, Color output) and the light's unit direction: returns
    (group, builder, group input, group output, (dx, dy, dz) sockets, sqrt(1 + dz) socket --
    the disk map's denominator). ``albedo_input``: an (unused) Albedo input before the output,
    so the sockets' identifiers are the environment indirect group's and a group node keeps
    its links when the light mode swaps the trees (Blender matches them by identifier)."""
    group = pn.new_light_group(name)
    if albedo_input:
        s = group.interface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
        s.default_value = (0.8, 0.8, 0.8, 1.0)
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    b = pn._Builder(group)
    gin = b.node("NodeGroupInput", x_in, 0)
    gout = b.node("NodeGroupOutput", x_out, 0)
    d = b.vmath("NORMALIZE", gin.outputs["Light Direction"], x=x_in + 200, y=0)
    sep = b.node("ShaderNodeSeparateXYZ", x_in + 400, 0)
    b.links.new(d, sep.inputs[0])
    dz = sep.outputs["Z"]
    root = b.math("SQRT", b.math("MAXIMUM", b.math("ADD", dz, 1.0, x=x_in + 600, y=-100), 1e-6,
                                 x=x_in + 700, y=-100), x=x_in + 800, y=-100)
    return group, b, gin, gout, (sep.outputs["X"], sep.outputs["Y"], dz), root


def _sun_group_tail(b, gin, gout, irradiance, albedo, dz, x: float) -> None:
    """Output ``albedo * irradiance * Intensity * Color``, 0 with the light below the horizon."""
    lit = b.math("GREATER_THAN", dz, 0.0, x=x, y=-200)
    scale = b.math("MULTIPLY", b.math("MULTIPLY", irradiance, lit, x=x + 200, y=-100),
                   gin.outputs["Intensity"], x=x + 400, y=-100)
    color = b.vmath("SCALE", albedo, x=x + 600, y=-300, scale=scale)
    color = b.vmath("MULTIPLY", color, gin.outputs["Color"], x=x + 800, y=-300)
    b.links.new(color, gout.inputs["Color"])


def _disk_and_uv(b, dx, dy, root, uv_map: str):
    """(the light's disk point as table coordinates in [0, 1]^2, the texel's UV) sockets."""
    tx = b.math("MULTIPLY_ADD", b.math("DIVIDE", dx, root, x=-900, y=100), 0.5, 0.5, x=-800, y=100)
    ty = b.math("MULTIPLY_ADD", b.math("DIVIDE", dy, root, x=-900, y=0), 0.5, 0.5, x=-800, y=0)
    table_uv = b.node("ShaderNodeCombineXYZ", -700, 50)
    b.links.new(tx, table_uv.inputs[0])
    b.links.new(ty, table_uv.inputs[1])
    return table_uv.outputs[0], b.node("ShaderNodeUVMap", -700, -400, uv_map=uv_map).outputs["UV"]


def build_group(n_tiles: int, resolution: int, table_size: int, eig_image, table_image,
                uv_map: str, name: str):
    """The node group: inputs Light Direction, Intensity, Color; output Color (direct light)."""
    group, b, gin, gout, (dx, dy, dz), root = _sun_group_head(name, -1800, 1600)
    table_uv, uv = _disk_and_uv(b, dx, dy, root, uv_map)
    lay_e = atlas_layout(n_tiles + 1, resolution)
    lay_t = atlas_layout(n_tiles, table_size)
    acc = None
    for t in range(n_tiles):
        y = 600 - 220 * t
        c = _lookup(b, table_image, pn.after_sum(b, table_uv, acc, -700, y), lay_t["tiles"][t],
                    -500, y)
        e = _lookup(b, eig_image, pn.after_sum(b, uv, acc, -700, y - 100), lay_e["tiles"][t], -500,
                    y - 100)
        dot = b.vmath("DOT_PRODUCT", c, e, x=-50, y=y)
        acc = dot if acc is None else b.math("ADD", acc, dot, x=150, y=y)
    albedo = _lookup(b, eig_image, uv, lay_e["tiles"][n_tiles], -500, -600)
    _sun_group_tail(b, gin, gout, acc, albedo, dz, 150)
    return group


def build_gathered_group(k: int, resolution: int, table_size: int, eig_image, table_image,
                         uv_map: str, name: str):
    """The gathered indirect term's group (:mod:`...lt_addon.transport.gathered_texture`):
    inputs Light Direction, Intensity, Color; output Color = ``max(0, sum_j c_j(w0) U_j)`` x
    Intensity x Color, 0 with the light below the horizon. ``c_j``: channel ``j % 3`` of table
    tile ``j // 3`` at the sun's disk point; ``U_j``: RGB component image ``j`` (radiance).
    Lookups per pixel: k + ceil(k / 3). Twin: ``gathered_texture.viewport_relight``."""
    group, b, gin, gout, (dx, dy, dz), root = _sun_group_head(name, -1800, 1600, True)
    table_uv, uv = _disk_and_uv(b, dx, dy, root, uv_map)
    n_tiles = -(-k // 3)
    lay_e = atlas_layout(k, resolution)
    lay_t = atlas_layout(n_tiles, table_size)
    acc = None

    def scalar(v, y):        # the running RGB sum as one number (for after_sum's chaining)
        return None if v is None else b.vmath("DOT_PRODUCT", v, (1.0, 0.0, 0.0), x=-900, y=y)

    for t in range(n_tiles):
        y = 600 - 600 * t
        c = _lookup(b, table_image, pn.after_sum(b, table_uv, scalar(acc, y), -700, y),
                    lay_t["tiles"][t], -500, y)
        sep = b.node("ShaderNodeSeparateXYZ", -100, y)
        b.links.new(c, sep.inputs[0])
        for ch in range(min(3, k - 3 * t)):
            j, yj = 3 * t + ch, y - 150 * (ch + 1)
            e = _lookup(b, eig_image, pn.after_sum(b, uv, scalar(acc, yj), -700, yj),
                        lay_e["tiles"][j], -500, yj)
            term = b.vmath("SCALE", e, x=100, y=yj, scale=sep.outputs[ch])
            acc = term if acc is None else b.vmath("ADD", acc, term, x=300, y=yj)
    clamped = b.vmath("MAXIMUM", acc, (0.0, 0.0, 0.0), x=500, y=0)
    lit = b.math("GREATER_THAN", dz, 0.0, x=500, y=-200)
    scale = b.math("MULTIPLY", lit, gin.outputs["Intensity"], x=700, y=-200)
    color = b.vmath("SCALE", clamped, x=900, y=0, scale=scale)
    color = b.vmath("MULTIPLY", color, gin.outputs["Color"], x=1100, y=0)
    b.links.new(color, gout.inputs["Color"])
    return group


def indirect_table_size(settings: dict) -> int:
    """Side of the gathered indirect light's coefficient tables: T's sparse tables' (at least
    :data:`...lt_addon.transport.sparse_tables.TABLE_SIZE`, 64). At 32 a sun 2 degrees high is
    read between table texels 0 and 3.6 degrees high: 18 % too bright on the gallery's Suzanne
    (48 % without the band under the horizon), 1.3 % at 64 (docs/bench/2026-12-gallery.md)."""
    from ...lt_addon.transport import sparse_tables as sp

    return max(sp.TABLE_SIZE, int(settings["table_size"]))


def install_indirect_group(obj, report: dict, bake, base: str, sun_angle: float, uv_map: str):
    """The indirect term's group of ``obj`` (None without one): the gathered term's
    (:func:`build_gathered_group`, its component atlas and tables written beside the bake) or
    the steerable term's (:func:`.preview_nodes.build_group`). Both leave the component /
    basis atlas in the image ``"<obj> indirect atlas"`` the environment group samples."""
    if bake.indirect is None:
        return None, {}
    iname = f"{GROUP_PREFIX} indirect ({obj.name})"
    old = bpy.data.node_groups.get(iname)
    files = {}
    aname = f"{obj.name} indirect atlas"
    stale = bpy.data.images.get(aname)
    # an earlier bake's atlas of the other kind of term (another file): loading ours beside it
    # would name ours "... .001" and leave the World group reading the stale one by name
    gathered = isinstance(bake.indirect, gt.GatheredIndirect)
    # the steerable term's atlas is written beside it: its basename in the report's own folder
    # (a report from elsewhere may name any path; a write there is refused, issue 56)
    indirect_file = untrusted.confined(os.path.dirname(report["report"]),
                                       os.path.basename(str(report["files"]["indirect"])))
    atlas = (f"{base}_preview_indirect_eigen.exr" if gathered else
             os.path.splitext(indirect_file)[0] + "_atlas.exr")
    if stale is not None and stale.get(pn._TAG) and (
            os.path.abspath(bpy.path.abspath(stale.filepath)) != os.path.abspath(atlas)):
        bpy.data.images.remove(stale)
    if gathered:
        s = report["settings"]
        eig, tables = gt.preview_arrays(bake.indirect, sun_angle, indirect_table_size(s),
                                        s.get("kernel", "linear"))
        files = write_preview_files(base, eig, tables, ("indirect_eigen", "indirect_tables"),
                                    "relightable_textures.gathered_indirect_preview")
        iimg = pn.load_atlas_image(files["indirect_eigen"], aname)
        timg = pn.load_atlas_image(files["indirect_tables"], f"{obj.name} indirect tables")
        D = indirect_table_size(s)
        group = build_gathered_group(len(eig), bake.indirect.resolution, D, iimg, timg, uv_map,
                                     iname + " new")
        group["relight_indirect"] = "gathered"
        group["relight_indirect_table_size"] = D      # what a new sun size rewrites
    else:
        atlas_path, _ = pn.write_atlas(bake.indirect, indirect_file)
        iimg = pn.load_atlas_image(atlas_path, aname)
        group = pn.build_group(bake.indirect, iimg, uv_map, name=iname + " new")
        group["relight_indirect"] = "steerable"
    if old is not None:
        bpy.data.node_groups.remove(old)
    group.name = iname
    group[pn.OWNER] = obj.name
    group["relight_indirect_image"] = iimg.name     # what the World group samples
    return group, files


# ---------------------------------------------------------------------------------------------
# the block viewport: a PCA per texel block (lt_addon/transport/block_viewport.py)


def _vmadd(b, a, scale, add, x, y):
    """``a * scale + add`` per component (sockets or 3-tuples)."""
    n = b.node("ShaderNodeVectorMath", x, y, operation="MULTIPLY_ADD")
    for i, v in enumerate((a, scale, add)):
        b._feed(n.inputs[i], v)
    return n.outputs["Vector"]


def build_block_group(n_tiles: int, resolution: int, block: int, table_size: int, eig_image,
                      table_image, uv_map: str, name: str):
    """The block viewport's sun group (the sockets of :func:`build_group`): per pixel its
    block's cell of the eigen atlas and its block's cell of the table atlas, both computed in
    the tree from the UV (:mod:`...lt_addon.transport.block_viewport`); ``n_tiles`` groups of
    three components, the albedo the eigen atlas's last tile."""
    group, b, gin, gout, (dx, dy, dz), root = _sun_group_head(name, -2000, 1600)
    R, B, D = float(resolution), int(block), float(table_size)
    nb = resolution // B
    rp = float(nb * (B + 2))
    uv = b.node("ShaderNodeUVMap", -1700, -400, uv_map=uv_map).outputs["UV"]
    f = b.vmath("SCALE", uv, x=-1500, y=-400, scale=R)                       # texels
    cell = b.vmath("FLOOR", b.vmath("SCALE", f, x=-1400, y=-400, scale=1.0 / B), x=-1300,
                   y=-400)
    cell = b.vmath("MINIMUM", b.vmath("MAXIMUM", cell, (0.0, 0.0, 0.0), x=-1200, y=-400),
                   (nb - 1.0, nb - 1.0, 0.0), x=-1100, y=-400)
    # eigen cell: (f + 2 b + 1) / Rp
    e_uv = b.vmath("SCALE", _vmadd(b, cell, (2.0, 2.0, 0.0), f, -1000, -400), x=-900, y=-400,
                   scale=1.0 / rp)
    e_uv = b.vmath("ADD", e_uv, (1.0 / rp, 1.0 / rp, 0.0), x=-800, y=-400)
    # table cell: (b D + 0.5 + g) / (nb D), g = clamp((x0 + 1) D / 2 - 0.5, 0, D - 1)
    g = []
    for axis, comp in enumerate((dx, dy)):
        y = 200 - 150 * axis
        p = b.math("DIVIDE", comp, root, x=-1500, y=y)
        v = b.math("MULTIPLY_ADD", p, 0.5 * D, 0.5 * D - 0.5, x=-1400, y=y)
        g.append(b.math("MINIMUM", b.math("MAXIMUM", v, 0.0, x=-1300, y=y), D - 1.0, x=-1200,
                        y=y))
    gv = b.node("ShaderNodeCombineXYZ", -1100, 100)
    b.links.new(g[0], gv.inputs[0])
    b.links.new(g[1], gv.inputs[1])
    t_uv = _vmadd(b, cell, (D, D, 0.0), gv.outputs[0], -1000, 100)
    t_uv = b.vmath("SCALE", b.vmath("ADD", t_uv, (0.5, 0.5, 0.0), x=-900, y=100), x=-800, y=100,
                   scale=1.0 / (nb * D))
    lay_e = atlas_layout(n_tiles + 1, nb * (B + 2))
    lay_t = atlas_layout(n_tiles, nb * int(table_size))
    acc = None
    for t in range(n_tiles):
        y = 600 - 220 * t
        c = _lookup(b, table_image, pn.after_sum(b, t_uv, acc, -700, y), lay_t["tiles"][t],
                    -500, y)
        e = _lookup(b, eig_image, pn.after_sum(b, e_uv, acc, -700, y - 100), lay_e["tiles"][t],
                    -500, y - 100)
        dot = b.vmath("DOT_PRODUCT", c, e, x=-50, y=y)
        acc = dot if acc is None else b.math("ADD", acc, dot, x=150, y=y)
    albedo = _lookup(b, eig_image, e_uv, lay_e["tiles"][n_tiles], -500, -600)
    _sun_group_tail(b, gin, gout, acc, albedo, dz, 150)
    return group


def block_preview_arrays(view, albedo, directions, sun_angle: float, table_size: int,
                         kernel: str = "linear"):
    """(eigen tiles (n+1, Rp, Rp, 3) in the cell layout with the albedo last, table tiles
    (n, nb D, nb D, 3)), float32, for :func:`build_block_group`."""
    from ...lt_addon.transport import block_viewport as bv

    eig = np.concatenate([_tiles3(view.eigen),
                          bv.to_cells(np.asarray(albedo, np.float32), view.block)[None]], axis=0)
    tab = bv.tables(view, directions, table_size, sun_angle, kernel)
    return eig, _tiles3(tab)


def write_block_files(base: str, eig, tables) -> dict:
    """Write the block viewport's two half-float atlases (cell-layout eigen images with the
    albedo last; per-block tables); returns their paths and bytes."""
    return write_preview_files(base, eig, tables, ("block_eigen", "block_tables"),
                               "relightable_textures.block_preview")


def viewport_relight_blocks(eig_tiles, table_tiles, direction, block: int, resolution: int,
                            table_size: int) -> np.ndarray:
    """NumPy twin of :func:`build_block_group` at the texel centres (direct light, intensity
    1): (R, R, 3) from the tiles :func:`block_preview_arrays` makes (or read back)."""
    from ...lt_addon.transport import block_viewport as bv

    eig = np.asarray(eig_tiles, np.float64)
    tab = np.asarray(table_tiles, np.float64)
    n = tab.shape[0]
    E = eig[:n].transpose(0, 3, 1, 2).reshape(3 * n, *eig.shape[1:3])
    C = tab.transpose(0, 3, 1, 2).reshape(3 * n, *tab.shape[1:3])
    return bv.viewport_relight(E, C, eig[n], direction, block, resolution, table_size)


# ---------------------------------------------------------------------------------------------
# the viewport from T itself: sparse kernel tables (lt_addon/transport/sparse_tables.py)


def viewport_relight_sparse(tiles, indices, weights, albedo, direction) -> np.ndarray:
    """NumPy twin of :func:`build_sparse_group` (direct light, intensity 1): (R, R, 3) from the
    8-bit atlas tiles (uint8, read as ``q / 255``), the scaled weights and the albedo tile."""
    e = sp.viewport_relight(tiles, indices, weights, direction, 1.0 / 255.0)
    return (e[..., None] * np.asarray(albedo, np.float64)).astype(np.float32)


def table_parts(arr) -> np.ndarray:
    """(D, D, K) -> (D, (K/3) D, 3): taps 0-2 in the first part, 3-5 in the next, ... (one
    image, one sampler, one lookup per part and table texel)."""
    a = np.asarray(arr)
    return np.concatenate([a[..., i:i + 3] for i in range(0, a.shape[-1], 3)], axis=1)


def tables_from_parts(img) -> np.ndarray:
    """Inverse of :func:`table_parts`: (D, (K/3) D, 3) -> (D, D, K)."""
    a = np.asarray(img)
    D = a.shape[0]
    return np.concatenate([a[:, i:i + D] for i in range(0, a.shape[1], D)], axis=-1)


def write_sparse_tables(base: str, indices, weights, scales, sun_angle: float) -> dict:
    """The index table and the weight table (times the directions' atlas scales) as float
    EXRs (indices are exact integers), each (D, (K/3) D) RGB: :func:`table_parts`."""
    out = {}
    for name, arr in (("sparse_index", table_parts(np.asarray(indices, np.float32))),
                      ("sparse_weights", table_parts(sp.scaled_weights(indices, weights,
                                                                       scales)))):
        path = f"{base}_preview_{name}.exr"
        out[name] = path
        out[f"{name}_bytes"] = exrio.write_exr(
            path, {c: arr[..., i] for i, c in enumerate("RGB")},
            {"format": "relightable_textures.transport_sparse_table", "size": arr.shape[0],
             "sun_angle": sun_angle}, pixel_type="float")
    return out


def write_sparse_atlas(base: str, store) -> dict:
    """T's 8-bit atlas (PNG, three directions per RGB tile) and its per-direction scales
    (JSON beside it); returns paths, bytes and the scales."""
    from ...lt_addon.io import atomic
    from ...lt_addon.io.contact_sheet import write_png

    from ...lt_addon.transport.bundle import quantized

    tiles, scales = quantized(store)
    path = f"{base}_preview_transport.png"
    atlas = pack_atlas(tiles, "edge")
    nbytes = write_png(path, atlas[::-1])       # PNG rows top first, Blender's bottom first
    meta = f"{base}_preview_transport.json"
    atomic.write_json(meta, {"format": "relightable_textures.transport_sparse_atlas",
                             "format_version": 1,
                             "tiles": len(tiles), "resolution": tiles.shape[1],
                             "directions": int(len(scales)), "scales": scales.tolist(),
                             "meaning": "texel = q / 255 * scales[direction]"})
    return {"transport_atlas": path, "transport_atlas_bytes": nbytes,
            "transport_scales": meta}, scales


def _scales(path: str) -> np.ndarray:
    from ...lt_addon.io import untrusted
    from ...lt_addon.io.versions import check

    meta = untrusted.read_json(path)   # (a capped regular file; one line naming it)
    check(meta, "relightable_textures.transport_sparse_atlas", path, "a transport atlas's scales")
    try:
        scales = np.asarray(untrusted.field(meta, "scales", path, list), np.float64)
    except (ValueError, TypeError):
        raise untrusted.UntrustedFileError(path, "its scales are not numbers") from None
    untrusted.check_values(path, scales, lo=0.0, what="scales")
    return scales


def _closest(b, image, vector, x, y):
    tex = b.node("ShaderNodeTexImage", x, y, image=image, interpolation="Closest",
                 extension="EXTEND")
    b.links.new(vector, tex.inputs["Vector"])
    sep = b.node("ShaderNodeSeparateColor", x + 200, y)
    b.links.new(tex.outputs["Color"], sep.inputs[0])
    return sep.outputs


def build_sparse_group(n_directions: int, resolution: int, table_size: int, taps: int,
                       atlas_image, index_image, weight_image, albedo_image, albedo_tile,
                       uv_map: str, name: str):
    """The sun group relighting from T: the sockets of :func:`build_group`.

    At the light's disk point the four surrounding table texels are read with Closest lookups
    (``taps`` direction indices, ``taps`` scaled weights each, in ``taps / 3`` parts of the
    tables) and weighted bilinearly; each index ``i`` selects tile ``i // 3`` of the 8-bit atlas
    (its offset computed in the tree) and channel ``i % 3``. 4 x (2 taps / 3 + taps) lookups,
    plus the albedo
    (``albedo_tile`` of the half-float ``albedo_image``: 8 bits would cost a dark albedo its
    precision)."""
    group, b, gin, gout, (dx, dy, dz), root = _sun_group_head(name, -2600, 2200)
    D = int(table_size)
    cell, frac = [], []
    for axis, comp in enumerate((dx, dy)):
        y = 200 - 200 * axis
        p = b.math("DIVIDE", comp, root, x=-1700, y=y)
        f = b.math("MULTIPLY_ADD", p, 0.5 * D, 0.5 * D - 0.5, x=-1600, y=y)
        f = b.math("MINIMUM", b.math("MAXIMUM", f, 0.0, x=-1500, y=y), D - 1.0, x=-1400, y=y)
        c0 = b.math("MINIMUM", b.math("FLOOR", f, x=-1300, y=y), D - 2.0, x=-1200, y=y)
        cell.append(c0)
        frac.append(b.math("SUBTRACT", f, c0, x=-1100, y=y))
    uv = b.node("ShaderNodeUVMap", -1400, -600, uv_map=uv_map).outputs["UV"]
    lay = atlas_layout(-(-n_directions // 3), resolution)
    acc = None
    y = 1200
    for cy in (0, 1):
        for cx in (0, 1):
            fu = frac[0] if cx else b.math("SUBTRACT", 1.0, frac[0], x=-1000, y=y)
            fv = frac[1] if cy else b.math("SUBTRACT", 1.0, frac[1], x=-1000, y=y - 60)
            factor = b.math("MULTIPLY", fu, fv, x=-900, y=y)
            tv = b.math("MULTIPLY_ADD", cell[1], 1.0 / D, (cy + 0.5) / D, x=-1000, y=y - 180)
            idx, wts = [], []
            parts = taps // 3
            for part in range(parts):   # part p of the tables holds taps 3p .. 3p + 2
                yp = y - 400 * part
                tuv = b.node("ShaderNodeCombineXYZ", -900, yp - 120)
                b.links.new(b.math("MULTIPLY_ADD", cell[0], 1.0 / (parts * D),
                                   (cx + 0.5 + part * D) / (parts * D), x=-1000, y=yp - 120),
                            tuv.inputs[0])
                b.links.new(tv, tuv.inputs[1])
                at = pn.after_sum(b, tuv.outputs[0], acc, -800, yp - 120)
                idx += list(_closest(b, index_image, at, -700, yp))[:3]
                wts += list(_closest(b, weight_image, at, -700, yp - 200))[:3]
            for k in range(len(idx)):
                yk = y - 120 * k
                value = _atlas_channel(b, idx[k], uv, lay, atlas_image, resolution, acc,
                                       -300, yk)
                term = b.math("MULTIPLY", value, b.math("MULTIPLY", wts[k], factor, x=700,
                                                        y=yk - 60), x=800, y=yk)
                acc = term if acc is None else b.math("ADD", acc, term, x=900, y=yk)
            y -= 400 * parts + 200
    albedo = _lookup(b, albedo_image, uv, albedo_tile, 700, y - 200)
    _sun_group_tail(b, gin, gout, acc, albedo, dz, 1100)
    return group


# ---------------------------------------------------------------------------------------------
# the horizon viewport: per-texel horizons and normals (lt_addon/transport/horizon_map.py)


def horizon_preview_arrays(hm, albedo):
    """(8-bit horizon tiles (2 to 9 ceil(A/3), Rh, Rh, 3) uint8 -- the lower edges' tiles,
    then the upper edges', then their spreads' where the map has them, then the open bands'
    lower and upper edges' where it has them, then the azimuth gaps' crossings and their
    weights where it has them, then the bands' edges' spreads where it has them, three
    azimuths per RGB tile, at the horizons' side; normal and
    albedo tiles (2, R, R, 3) float32 at the texture's) -- what :func:`build_horizon_group`
    reads."""
    _, A, Rh, _ = hm.q.shape
    n = -(-A // 3)
    planes = ([hm.q[0], hm.q[1]] + ([hm.spread] if hm.spread is not None else [])
              + ([hm.q[2], hm.q[3]] if hm.gaps else [])
              + ([hm.cross[0], hm.cross[1]] if hm.cross is not None else [])
              + ([hm.band_spread[0], hm.band_spread[1]] if hm.band_spread is not None
                 else []))
    q = np.zeros((len(planes), n * 3, Rh, Rh), np.uint8)
    for i, plane in enumerate(planes):
        q[i, :A] = plane
    tiles = q.reshape(len(planes) * n, 3, Rh, Rh).transpose(0, 2, 3, 1)
    na = np.stack([hm.normals.astype(np.float32), np.asarray(albedo, np.float32)])
    return tiles, na


def write_horizon_files(base: str, tiles, na, azimuths: int) -> dict:
    """``<base>_preview_horizons.png`` (8-bit, edge-padded atlas) and
    ``<base>_preview_normals.exr`` (half floats: the normal tile, then the albedo)."""
    from ...lt_addon.io import versions
    from ...lt_addon.io.contact_sheet import write_png

    out = {"horizon_atlas": f"{base}_preview_horizons.png",
           "horizon_normals": f"{base}_preview_normals.exr"}
    out["horizon_atlas_bytes"] = write_png(out["horizon_atlas"], pack_atlas(tiles, "edge")[::-1])
    atlas = pack_atlas(na, "edge")
    out["horizon_normals_bytes"] = exrio.write_exr(
        out["horizon_normals"], {c: atlas[..., i] for i, c in enumerate("RGB")},
        {**versions.stamp("relightable_textures.horizon_preview"), "tiles": 2,
         "azimuths": int(azimuths), "resolution": int(na.shape[1]),
         "horizon_resolution": int(tiles.shape[1])}, pixel_type="half")
    return out


def viewport_relight_horizon(tiles, na, azimuths: int, direction, sun_angle: float,
                             cross: bool = False, band_spread: bool = False):
    """NumPy twin of :func:`build_horizon_group` (direct light, intensity 1): (R, R, 3) from
    the 8-bit horizon tiles and the half-float normal and albedo tiles; ``cross``: the tiles
    end with two sets more, the gaps' crossings and their weights; ``band_spread``: and then
    two more, the bands' edges' spreads."""
    from ...lt_addon.transport.horizon_map import HorizonMap

    A = int(azimuths)
    n, Rh = -(-A // 3), tiles.shape[1]
    planes = len(tiles) // n          # 2: the edges; 3: and their spreads; 4 / 5: and the
    q = np.asarray(tiles).transpose(0, 3, 1, 2).reshape(planes, 3 * n, Rh, Rh)[:, :A]  # bands
    # (2 more with ``cross``, and 2 more with ``band_spread``)
    bs = q[-2:] if band_spread else None       # (last: the bands' edges' spreads)
    planes -= 2 * bool(band_spread)
    c = q[planes - 2:planes] if cross else None     # (then the crossings and their weights)
    planes -= 2 * bool(cross)
    edges = q[[0, 1, planes - 2, planes - 1]] if planes >= 4 else q[:2]
    hm = HorizonMap(edges, np.asarray(na[0], np.float16), q[2] if planes in (3, 5) else None,
                    cross=c, band_spread=bs)
    e = hm.direct(direction, sun_angle)
    return (e[..., None] * np.asarray(na[1], np.float64)).astype(np.float32)


def _atlas_channel(b, index, uv, lay, image, resolution: int, acc, x, y, interpolation="Linear"):
    """The value of channel ``index % 3`` of tile ``index // 3`` of an atlas (``lay``:
    :func:`atlas_layout`) at the texel's ``uv``; ``index`` a socket holding an integer."""
    cols, stride, W, H = lay["cols"], lay["stride"], lay["width"], lay["height"]
    tile = b.math("FLOOR", b.math("MULTIPLY_ADD", index, 1.0 / 3.0, 0.5 / 3.0, x=x, y=y),
                  x=x + 100, y=y)
    ch = b.math("MULTIPLY_ADD", tile, -3.0, index, x=x + 200, y=y)
    row = b.math("FLOOR", b.math("MULTIPLY_ADD", tile, 1.0 / cols, 0.5 / cols, x=x + 300, y=y),
                 x=x + 400, y=y)
    col = b.math("MULTIPLY_ADD", row, -float(cols), tile, x=x + 500, y=y)
    off = b.node("ShaderNodeCombineXYZ", x + 600, y)
    b.links.new(b.math("MULTIPLY_ADD", col, stride / W, 1.0 / W, x=x + 550, y=y), off.inputs[0])
    b.links.new(b.math("MULTIPLY_ADD", row, stride / H, 1.0 / H, x=x + 550, y=y - 40),
                off.inputs[1])
    m = b.node("ShaderNodeVectorMath", x + 700, y, operation="MULTIPLY_ADD")
    b.links.new(pn.after_sum(b, uv, acc, x + 650, y), m.inputs[0])
    m.inputs[1].default_value = (resolution / W, resolution / H, 0.0)
    b.links.new(off.outputs[0], m.inputs[2])
    tex = b.node("ShaderNodeTexImage", x + 800, y, image=image, interpolation=interpolation,
                 extension="EXTEND")
    b.links.new(m.outputs["Vector"], tex.inputs["Vector"])
    onehot = b.node("ShaderNodeCombineXYZ", x + 900, y - 40)
    for c in range(3):
        b.links.new(b.math("COMPARE", ch, float(c), 0.5, x=x + 850, y=y - 40 * c),
                    onehot.inputs[c])
    return b.vmath("DOT_PRODUCT", tex.outputs["Color"], onehot.outputs[0], x=x + 1000, y=y)


#: Node name of the horizon group's sun radius (radians), rewritten by the Sun Size slider.
SUN_RADIUS_NODE = "Sun Radius"


def _disc_part(b, offset, radius, x, y):
    """``disc_fraction(offset / radius)`` in nodes: the part of a disc of ``radius`` beyond a
    line ``offset`` below its centre (:func:`...lt_addon.rays.horizon.disc_fraction`)."""
    t = b.math("DIVIDE", offset, radius, x=x, y=y)
    t = b.math("MINIMUM", b.math("MAXIMUM", t, -1.0, x=x + 100, y=y), 1.0, x=x + 200, y=y)
    root = b.math("SQRT", b.math("MULTIPLY_ADD", t, b.math("MULTIPLY", t, -1.0, x=x + 200,
                                                           y=y - 100),
                                 1.0, x=x + 300, y=y - 100), x=x + 400, y=y - 100)
    seg = b.math("MULTIPLY_ADD", t, root, b.math("ARCSINE", t, x=x + 400, y=y - 200),
                 x=x + 500, y=y)
    return b.math("MULTIPLY_ADD", seg, 1.0 / np.pi, 0.5, x=x + 600, y=y)


def _disc_moment(b, offset, radius, x, y):
    """``radius * disc_moment(offset / radius)`` in nodes: the first moment of the part of a
    disc of ``radius`` beyond a line ``offset`` below its centre
    (:func:`...lt_addon.rays.horizon.disc_moment`)."""
    t = b.math("DIVIDE", offset, radius, x=x, y=y)
    t = b.math("MINIMUM", b.math("MAXIMUM", t, -1.0, x=x + 100, y=y), 1.0, x=x + 200, y=y)
    c = b.math("SUBTRACT", 1.0, b.math("MULTIPLY", t, t, x=x + 300, y=y), x=x + 400, y=y)
    m = b.math("POWER", b.math("MAXIMUM", c, 0.0, x=x + 500, y=y), 1.5, x=x + 600, y=y)
    return b.math("MULTIPLY", b.math("MULTIPLY", m, 2.0 / (3.0 * np.pi), x=x + 700, y=y),
                  radius, x=x + 800, y=y)


def build_horizon_group(azimuths: int, resolution: int, horizon_image, na_image, uv_map: str,
                        name: str, sun_angle: float, horizon_resolution: int | None = None,
                        spread: bool = False, gaps: bool = False, cross: bool = False,
                        band_spread: bool = False):
    """The sun group relighting from horizons (the sockets of :func:`build_group`): at five
    azimuths across the sun's disc (the sun's and two either side, ``horizon_map.STRIPS``) the
    two azimuth channels around each are picked; at each, the sun's disc is cut by the blocked
    interval's edges (``1 - max(0, F((e - lo) / r) - F((e - hi) / r))`` with
    ``F(t) = 0.5 + (t sqrt(1 - t^2) + asin t) / pi``), the two visibilities linear between the
    azimuths, the five weighted by the disc's chord there (``vis``); lit by ``max(0, (N . d)
    vis + (N . g) mom) / pi`` with the baked normal, ``g`` the direction's slope in elevation
    and ``mom`` the visible part's first moment, read likewise (the cosine over the visible
    part: :func:`...lt_addon.rays.horizon.visible_moment`), the disc clipped where that
    linear cosine is negative (the edges clamped into :func:`...lt_addon.rays.horizon.
    lit_range`, the whole disc's part and moment its part's there): 22 lookups (20 horizon
    channels, the normal, the albedo). With
    ``spread`` (the atlas' third set of tiles) the upper edge is cut by the wider disc
    ``sqrt(r^2 + 4 s^2)``, ``s = c^2 SPREAD_MAX`` from the spread channel ``c`` (0..1):
    10 lookups more (:func:`...lt_addon.transport.horizon_map.spread_radius`). With ``gaps``
    (the atlas' last two sets of tiles: an open band inside each interval, a window's sky) the
    disc's part inside the band, clipped to the interval, is lit again: 20 lookups more. With
    ``cross`` (the atlas' last two sets of tiles: where each azimuth gap's horizon jumps,
    :mod:`...lt_addon.rays.crossing`) each strip's place in its gap is read through the gap's
    crossing, by its weight (``crossing.warp``; the codes read linearly between texels, those
    that do not matter filled from their neighbours': ``crossing.fill``): 10 lookups more. With
    ``band_spread`` (the atlas' last two sets of tiles: the bands' edges' spreads over the
    footprint) each band edge is cut by its wider disc as the upper edge is: 20 lookups more.
    The
    horizon atlas may be coarser (``horizon_resolution``) than the normals' (``resolution``):
    its linear lookup reads the codes between its texels, as
    :func:`...lt_addon.transport.horizon_map.upsample`."""
    from ...lt_addon.rays.horizon import BEYOND
    from ...lt_addon.rays.crossing import RAMP
    from ...lt_addon.transport.horizon_map import (COS_MIN, EDGE_MIN, STRIPS,
                                                   SUN_RADIUS_MIN)

    Rh = int(horizon_resolution or resolution)

    group, b, gin, gout, (dx, dy, dz), _ = _sun_group_head(name, -2600, 3000)
    A = int(azimuths)
    n = -(-A // 3)
    az = b.math("ARCTAN2", dy, dx, x=-2000, y=400)                       # atan2(y, x)
    xa = b.math("MULTIPLY", az, A / (2 * np.pi), x=-1900, y=400)
    xa = b.math("ADD", xa, b.math("MULTIPLY", b.math("LESS_THAN", xa, 0.0, x=-1900, y=300),
                                  float(A), x=-1800, y=300), x=-1700, y=400)

    def mod_a(k, x, y):
        wrap = b.math("FLOOR", b.math("MULTIPLY_ADD", k, 1.0 / A, 0.5 / A, x=x, y=y),
                      x=x + 100, y=y)
        return b.math("SUBTRACT", k, b.math("MULTIPLY", wrap, float(A), x=x + 200, y=y),
                      x=x + 300, y=y)
    uv = b.node("ShaderNodeUVMap", -1400, -600, uv_map=uv_map).outputs["UV"]
    lay = atlas_layout((2 + bool(spread) + 2 * bool(gaps) + 2 * bool(cross)
                        + 2 * bool(band_spread)) * n, Rh)
    gap0 = (3 if spread else 2) * 3 * n      # the bands' lower edges' first channel
    cross0 = gap0 + (6 * n if gaps else 0)   # the crossings' first channel
    bs0 = cross0 + (6 * n if cross else 0)   # the bands' edges' spreads' first channel
    el = b.math("ARCSINE", b.math("MINIMUM", dz, 1.0, x=600, y=200), x=700, y=200)
    radius = b.node("ShaderNodeValue", 600, 0)
    radius.name = radius.label = SUN_RADIUS_NODE
    radius.outputs[0].default_value = max(np.radians(sun_angle) / 2, SUN_RADIUS_MIN)
    r = radius.outputs[0]
    # azimuth steps per radian of the disc's width: A / (2 pi) / cos(el)
    across = b.math("DIVIDE", b.math("MULTIPLY", r, A / (2 * np.pi), x=-1500, y=800),
                    b.math("MAXIMUM", b.math("COSINE", el, x=-1500, y=700), COS_MIN,
                           x=-1400, y=700), x=-1300, y=800)
    ntile = atlas_layout(2, resolution)["tiles"]
    nrm = b.vmath("NORMALIZE", _lookup(b, na_image, uv, ntile[0], 1200, -300), x=1600, y=-300)
    d = b.vmath("NORMALIZE", gin.outputs["Light Direction"], x=1600, y=-450)
    # the cosine linear in elevation across the disc: its slope d(d)/d(el) =
    # (-dz dx / ch, -dz dy / ch, ch), ch = |(dx, dy)|
    ch = b.math("SQRT", b.math("MULTIPLY_ADD", dx, dx, b.math("MULTIPLY", dy, dy, x=1400,
                                                                 y=-700), x=1500, y=-700),
                x=1600, y=-700)
    k = b.math("DIVIDE", b.math("MULTIPLY", dz, -1.0, x=1600, y=-800),
               b.math("MAXIMUM", ch, 1e-9, x=1650, y=-750), x=1700, y=-800)
    g = b.node("ShaderNodeCombineXYZ", 1750, -750)
    b.links.new(b.math("MULTIPLY", k, dx, x=1700, y=-850), g.inputs[0])
    b.links.new(b.math("MULTIPLY", k, dy, x=1700, y=-900), g.inputs[1])
    b.links.new(ch, g.inputs[2])
    cos = b.vmath("DOT_PRODUCT", nrm, d, x=1700, y=-300)
    slope = b.vmath("DOT_PRODUCT", nrm, g.outputs[0], x=1800, y=-700)
    # where that cosine is positive, [a, b] (horizon.lit_range): the disc clipped there
    up = b.math("GREATER_THAN", slope, 0.0, x=-1500, y=-1100)
    neg = b.math("MINIMUM", slope, -1e-9, x=-1500, y=-1200)
    safe = b.math("MULTIPLY_ADD", up, b.math("SUBTRACT", b.math("MAXIMUM", slope, 1e-9, x=-1400,
                                                                  y=-1150), neg, x=-1300,
                                               y=-1150), neg, x=-1200, y=-1100)
    e0 = b.math("SUBTRACT", el, b.math("DIVIDE", cos, safe, x=-1100, y=-1100), x=-1000,
                y=-1100)
    e0 = b.math("MINIMUM", b.math("MAXIMUM", e0, -BEYOND, x=-900, y=-1100), BEYOND, x=-800,
                y=-1100)
    far = b.math("MULTIPLY_ADD", up, 2.0 * BEYOND, -BEYOND, x=-700, y=-1150)   # +-BEYOND
    lit_a = b.math("MINIMUM", e0, far, x=-600, y=-1100)
    lit_b = b.math("MAXIMUM", e0, far, x=-600, y=-1200)
    off_a = b.math("SUBTRACT", el, lit_a, x=-500, y=-1100)
    off_b = b.math("SUBTRACT", el, lit_b, x=-500, y=-1200)
    above_a = _disc_part(b, off_a, r, -400, -1100)
    above_b = _disc_part(b, off_b, r, -400, -1300)
    whole = b.math("SUBTRACT", above_a, above_b, x=300, y=-1100)
    whole_m = b.math("SUBTRACT", _disc_moment(b, off_a, r, -400, -1500),
                     _disc_moment(b, off_b, r, -400, -1600), x=500, y=-1500)

    def clamp(h, x, y):
        return b.math("MINIMUM", b.math("MAXIMUM", h, lit_a, x=x, y=y), lit_b, x=x + 50, y=y)
    vis, mom, acc = None, None, None
    for s_i, (x_s, w_s) in enumerate(STRIPS):
        y0 = 500 + 1800 * (len(STRIPS) - 1 - s_i)     # (above the lit range's nodes)
        xs = b.math("MULTIPLY_ADD", across, x_s, xa, x=-1200, y=y0)
        k = b.math("FLOOR", xs, x=-1100, y=y0)
        f = b.math("SUBTRACT", xs, k, x=-1000, y=y0 - 100)
        k0 = mod_a(k, -1000, y0)
        if cross:     # the place in the gap read through its crossing (crossing.warp)
            c = _atlas_channel(b, b.math("ADD", k0, float(cross0), x=-800, y=y0 + 300), uv,
                               lay, horizon_image, Rh, acc, -700, y0 + 300)
            acc = c
            hw_ = _atlas_channel(b, b.math("ADD", k0, float(cross0 + 3 * n), x=-800,
                                           y=y0 + 350), uv, lay, horizon_image, Rh, acc,
                                 -700, y0 + 350)
            acc = hw_
            # t = (255 c / h - 1) / 254 (c read as code / 255, h as its weight)
            t = b.math("MULTIPLY_ADD", b.math("DIVIDE", c, b.math("MAXIMUM", hw_, 1e-6, x=300,
                                                                  y=y0 + 350),
                                              x=350, y=y0 + 300),
                       255.0 / 254.0, -1.0 / 254.0, x=400, y=y0 + 300)
            # (across: the disc's radius in gaps; the ramp RAMP radii either side)
            width = b.math("MAXIMUM", b.math("MULTIPLY", across, 2.0 * RAMP, x=400,
                                             y=y0 + 250), 2e-6, x=500, y=y0 + 250)
            ramp = b.math("MULTIPLY_ADD", b.math("DIVIDE", b.math("SUBTRACT", f, t, x=500,
                                                                  y=y0 + 300),
                                                 width, x=600, y=y0 + 300),
                          1.0, 0.5, x=700, y=y0 + 300)
            ramp = b.math("MINIMUM", b.math("MAXIMUM", ramp, 0.0, x=800, y=y0 + 300), 1.0,
                          x=900, y=y0 + 300)
            # h of the ramp, 1 - h linear
            f = b.math("MULTIPLY_ADD", hw_, b.math("SUBTRACT", ramp, f, x=1000, y=y0 + 250),
                       f, x=1100, y=y0 + 250)
        k1 = mod_a(b.math("ADD", k0, 1.0, x=-700, y=y0 + 100), -600, y0 + 100)
        part, moment = [], []
        for j, kk in enumerate((k0, k1)):
            edge, hs, hv = [], [], []
            for e, upper in enumerate((False, True)):
                y = y0 - 400 * (2 * j + e)
                idx = b.math("ADD", kk, float(3 * n), x=-800, y=y) if upper else kk
                q = _atlas_channel(b, idx, uv, lay, horizon_image, Rh, acc, -700, y)
                acc = q
                h = _decode_edge(b, q, 400, y)
                if not upper:    # code 0: blocked from below (-pi/2)
                    below = b.math("LESS_THAN", q, 0.5 / 255.0, x=400, y=y - 60)
                    h = b.math("MULTIPLY_ADD", below, -np.pi / 2 - EDGE_MIN, h, x=500, y=y)
                r_e = r
                if upper and spread:     # the edge's spread over the footprint widens the disc
                    c = _atlas_channel(b, b.math("ADD", kk, float(6 * n), x=-800, y=y - 200),
                                       uv, lay, horizon_image, Rh, acc, -700, y - 200)
                    acc = c
                    r_e = _spread_disc(b, c, r, 400, y - 200)
                edge_at = h
                h = clamp(h, 600, y - 100)
                hv.append(h)
                offset = b.math("SUBTRACT", el, h, x=800, y=y)
                if upper:    # cut where it is (its own disc), or at lit_b where that is lower
                    cut = _disc_part(b, b.math("SUBTRACT", el, edge_at, x=800, y=y - 50), r_e,
                                     900, y - 50)
                    edge.append(b.math("MAXIMUM", cut, above_b, x=1500, y=y - 50))
                else:
                    edge.append(_disc_part(b, offset, r, 900, y))
                hs.append(_disc_moment(b, offset, r, 900, y - 150))   # the sun's own disc
            blocked = b.math("MINIMUM", b.math("MAXIMUM", b.math(
                "SUBTRACT", edge[0], edge[1], x=1600, y=y0 - 800 * j), 0.0, x=1650,
                y=y0 - 800 * j), whole, x=1660, y=y0 - 800 * j)
            visible = b.math("SUBTRACT", whole, blocked, x=1700, y=y0 - 800 * j)
            # the visible part's first moment: the band's taken from the whole disc's 0
            band = b.math("LESS_THAN", hv[0], hv[1], x=1600, y=y0 - 800 * j - 100)
            mom_j = b.math("MULTIPLY_ADD", b.math("SUBTRACT", hs[1], hs[0], x=1650,
                                                  y=y0 - 800 * j - 100),
                           band, whole_m, x=1700, y=y0 - 800 * j - 100)
            if gaps:     # the open band inside the interval (clipped to it) lit again
                g, gs = [], []
                for e in range(2):
                    y = y0 - 400 * (2 * j + e) - 250
                    c = _atlas_channel(b, b.math("ADD", kk, float(gap0 + 3 * e * n), x=-800,
                                                   y=y),
                                       uv, lay, horizon_image, Rh, acc, -700, y)
                    acc = c
                    h = _decode_edge(b, c, 400, y)
                    h = (b.math("MINIMUM", b.math("MAXIMUM", h, hv[0], x=500, y=y), lit_b,
                                x=550, y=y) if e == 0 else
                         b.math("MAXIMUM", b.math("MINIMUM", h, hv[1], x=500, y=y), lit_a,
                                x=550, y=y))
                    g.append(h)
                    offset = b.math("SUBTRACT", el, h, x=800, y=y)
                    r_g = r
                    if band_spread:     # the edge's spread over the footprint: a wider disc
                        c = _atlas_channel(b, b.math("ADD", kk, float(bs0 + 3 * e * n),
                                                     x=-800, y=y - 150),
                                           uv, lay, horizon_image, Rh, acc, -700, y - 150)
                        acc = c
                        r_g = _spread_disc(b, c, r, 400, y - 150)
                    gs.append((_disc_part(b, offset, r_g, 900, y),
                               _disc_moment(b, offset, r, 900, y - 100)))
                reopened = b.math("MAXIMUM", b.math("SUBTRACT", gs[0][0], gs[1][0], x=1600,
                                                    y=y0 - 800 * j - 250), 0.0, x=1650,
                                  y=y0 - 800 * j - 250)
                visible = b.math("MINIMUM", b.math("ADD", visible, reopened, x=1750,
                                                   y=y0 - 800 * j - 250), whole, x=1800,
                                 y=y0 - 800 * j - 250)          # (at most the lit disc)
                open_band = b.math("LESS_THAN", g[0], g[1], x=1600, y=y0 - 800 * j - 350)
                mom_j = b.math("MULTIPLY_ADD", b.math("SUBTRACT", gs[0][1], gs[1][1], x=1650,
                                                      y=y0 - 800 * j - 350),
                               open_band, mom_j, x=1750, y=y0 - 800 * j - 350)
            part.append(visible)
            moment.append(mom_j)
        strip = b.math("MULTIPLY_ADD", b.math("SUBTRACT", part[1], part[0], x=1750, y=y0),
                       f, part[0], x=1800, y=y0)
        vis = (b.math("MULTIPLY", strip, w_s, x=1900, y=y0) if vis is None else
               b.math("MULTIPLY_ADD", strip, w_s, vis, x=1900, y=y0))
        strip = b.math("MULTIPLY_ADD", b.math("SUBTRACT", moment[1], moment[0], x=1750,
                                              y=y0 - 100), f, moment[0], x=1800, y=y0 - 100)
        mom = (b.math("MULTIPLY", strip, w_s, x=1900, y=y0 - 100) if mom is None else
               b.math("MULTIPLY_ADD", strip, w_s, mom, x=1900, y=y0 - 100))
    e = b.math("MULTIPLY_ADD", cos, vis, b.math("MULTIPLY", slope, mom, x=1850, y=-600),
               x=1900, y=-300)
    irr = b.math("MULTIPLY", b.math("MAXIMUM", e, 0.0, x=1950, y=0), 1.0 / np.pi, x=2000,
                 y=0)
    albedo = _lookup(b, na_image, uv, ntile[1], 1800, -600)
    _sun_group_tail(b, gin, gout, irr, albedo, dz, 2200)
    group["relight_azimuths"] = A
    return group


def _spread_disc(b, c, r, x, y):
    """The disc that cuts an edge spread over the footprint: ``sqrt(r^2 + 4 s^2)`` with ``s =
    c^2 SPREAD_MAX`` from its spread channel ``c`` (0..1, as the 8-bit image reads it) --
    :func:`...lt_addon.transport.horizon_map.spread_radius` of ``decode_spread``."""
    from ...lt_addon.transport.horizon_map import SPREAD_MAX

    c2 = b.math("MULTIPLY", c, c, x=x, y=y)
    s4 = b.math("MULTIPLY", b.math("MULTIPLY", c2, c2, x=x + 100, y=y), 4.0 * SPREAD_MAX ** 2,
                x=x + 200, y=y)
    return b.math("SQRT", b.math("MULTIPLY_ADD", r, r, s4, x=x + 300, y=y), x=x + 400, y=y)


def _decode_edge(b, q, x, y):
    """An edge's code ``q`` (0..1, as the 8-bit image reads it) -> elevation (radians):
    :func:`...lt_addon.transport.horizon_map.decode`'s rule in five nodes."""
    from ...lt_addon.transport.horizon_map import CODE_ZERO, CURVE, STEP_BELOW, STEP_HORIZON

    u = b.math("MULTIPLY_ADD", q, 255.0, -float(CODE_ZERO), x=x, y=y)
    up = b.math("MAXIMUM", u, 0.0, x=x + 20, y=y - 20)
    h = b.math("MULTIPLY", b.math("MULTIPLY_ADD", up, CURVE, STEP_HORIZON, x=x + 40, y=y - 30),
               up, x=x + 60, y=y - 40)
    return b.math("MULTIPLY_ADD", b.math("MINIMUM", u, 0.0, x=x + 20, y=y - 60), STEP_BELOW, h,
                  x=x + 80, y=y - 50)


def set_horizon_sun(group, sun_angle: float) -> bool:
    """Set a horizon group's sun size in place (True if ``group`` is one)."""
    from ...lt_addon.transport.horizon_map import SUN_RADIUS_MIN

    node = group.nodes.get(SUN_RADIUS_NODE) if group is not None else None
    if node is None:
        return False
    node.outputs[0].default_value = max(np.radians(sun_angle) / 2, SUN_RADIUS_MIN)
    return True


def pca_atlas_gpu_bytes(model) -> int:
    """GPU memory of the PCA's eigen atlas: a tile per three components and the albedo's, RGBA
    half floats (what Blender uploads for a half-float EXR)."""
    return (-(-model.k // 3) + 1) * model.resolution ** 2 * 8


def _write_pca_atlas(obj, model, albedo, store, angle, s, base):
    """Write and load the PCA's eigen and table atlases: (files, eigen image, eigen tiles)."""
    eig, tables = preview_arrays(model, albedo, store.directions, angle, s["table_size"],
                                 s.get("kernel", "linear"))
    files = write_preview_files(base, eig, tables)
    n = len(eig)
    del eig
    eig_img = pn.load_atlas_image(files["eigen"], f"{obj.name} transport eigen atlas")
    pn.load_atlas_image(files["tables"], f"{obj.name} transport tables")
    return files, eig_img, n


def pca_atlas_image(obj, bake, store, report: dict):
    """``obj``'s PCA eigen atlas image, written and loaded first when the preview left it out
    (over the GPU budget; environment lighting reads it)."""
    img = bpy.data.images.get(f"{obj.name} transport eigen atlas")
    if img is not None:
        return img
    s = report["settings"]
    base = os.path.splitext(report["report"])[0].removesuffix("_texture_report")
    return _write_pca_atlas(obj, bake.model, bake.albedo, store, float(s["sun_angle"]), s,
                            base)[1]


def install_transport_preview(scene, obj, report: dict, bake, store, sun_angle: float | None = None,
                              sun=None) -> dict:
    """Write the atlases, build the group(s) and wire them into ``obj``'s materials (replacing
    an earlier preview of ``obj``). The indirect term, when baked, goes through its own group
    (:func:`install_indirect_group`)."""
    s = report["settings"]
    angle = float(s["sun_angle"] if sun_angle is None else sun_angle)
    model = bake.model
    if not getattr(model, "live_preview", False):
        raise ValueError("the live preview shows PCA models (model 'pca'); this bake has "
                         f"{report['model']['kind']!r}")
    base = os.path.splitext(report["report"])[0].removesuffix("_texture_report")
    uv_map = baked_uv_name(obj, report)
    gname = f"{GROUP_PREFIX} ({obj.name})"
    old = bpy.data.node_groups.get(gname)
    info = report.get("viewport") or {}
    if bake.view is not None:
        viewport, why = "blocks", info.get("why", "")
    elif info.get("shows") == "pca":
        viewport, why = "pca", info.get("why", "")
    else:   # (reports before the block viewport: T when it fits, else the PCA)
        viewport, why = sp.choose_viewport(s.get("viewport", "pca"), store.directions.size,
                                           model.resolution,
                                           budget_mib=s.get("gpu_budget",
                                                            sp.DEFAULT_BUDGET_MIB),
                                           table_size=s["table_size"])
        viewport = "pca" if viewport == "blocks" else viewport
    sparse = {}
    if bake.horizon is not None:
        viewport, why = "horizon", info.get("why", "")
    # the PCA's eigen-texture atlas: what the PCA and T viewports read (T its albedo tile), and
    # environment lighting; over the GPU budget and not shown it is made when environment
    # lighting asks for it (pca_atlas_image): at 4096^2 with 96 components it is 33 tiles,
    # 4.4 GB of GPU memory, and its float32 arrays would hold ~13 GB while it is written
    # (from their shapes, not measured)
    budget = int(s.get("gpu_budget", sp.DEFAULT_BUDGET_MIB)) << 20
    files, eig_img = {}, None
    if viewport in ("pca", "transport") or pca_atlas_gpu_bytes(model) <= budget:
        files, eig_img, eig_tiles = _write_pca_atlas(obj, model, bake.albedo, store, angle, s,
                                                     base)
    else:   # an earlier bake's atlas of this object would be read for this one: gone
        stale = bpy.data.images.get(f"{obj.name} transport eigen atlas")
        if stale is not None:
            bpy.data.images.remove(stale)
        if os.path.exists(f"{base}_preview_eigen.exr"):
            os.remove(f"{base}_preview_eigen.exr")
        files = {"eigen_skipped": f"the PCA's eigen atlas ({pca_atlas_gpu_bytes(model) / 2**20:.0f}"
                                  f" MiB of GPU memory) is over the {budget >> 20} MiB budget "
                                  f"and the {viewport} viewport does not read it; environment "
                                  "lighting makes it when asked"}
    if viewport == "horizon":
        htiles, na = horizon_preview_arrays(bake.horizon, bake.albedo)
        sparse = {**write_horizon_files(base, htiles, na, bake.horizon.azimuths),
                  "azimuths": bake.horizon.azimuths,
                  "horizon_resolution": bake.horizon.horizon_resolution,
                  # the atlas' third set of tiles: the upper edges' spreads
                  "horizon_spread": bake.horizon.spread is not None,
                  # then two: the open bands inside the intervals
                  "horizon_gaps": bool(bake.horizon.gaps),
                  # then: where each azimuth gap's horizon jumps
                  "horizon_cross": bake.horizon.cross is not None,
                  # and last: the bands' edges' spreads over the footprints
                  "horizon_band_spread": bake.horizon.band_spread is not None}
        h_img = pn.load_atlas_image(sparse["horizon_atlas"], f"{obj.name} transport horizons")
        n_img = pn.load_atlas_image(sparse["horizon_normals"], f"{obj.name} transport normals")
        group = build_horizon_group(bake.horizon.azimuths, model.resolution, h_img, n_img,
                                    uv_map, gname + " new", angle,
                                    bake.horizon.horizon_resolution,
                                    spread=bake.horizon.spread is not None,
                                    gaps=bool(bake.horizon.gaps),
                                    cross=bake.horizon.cross is not None,
                                    band_spread=bake.horizon.band_spread is not None)
    elif viewport == "blocks":
        view = bake.view
        beig, btab = block_preview_arrays(view, bake.albedo, store.directions, angle,
                                          s["table_size"], s.get("kernel", "linear"))
        sparse = {**write_block_files(base, beig, btab), "block": view.block,
                  "block_components": view.k}
        be_img = pn.load_atlas_image(sparse["block_eigen"], f"{obj.name} transport block eigen")
        bt_img = pn.load_atlas_image(sparse["block_tables"],
                                     f"{obj.name} transport block tables")
        group = build_block_group(len(btab), model.resolution, view.block, s["table_size"],
                                  be_img, bt_img, uv_map, gname + " new")
    elif viewport == "transport":
        D = max(sp.TABLE_SIZE, int(s["table_size"]))
        idx, wts, kept = sp.cached_tables(store.directions, D, angle, s.get("kernel", "linear"))
        atlas_files, scales = write_sparse_atlas(base, store)
        sparse = {**atlas_files, **write_sparse_tables(base, idx, wts, scales, angle),
                  "sparse_table_size": D, "taps": int(idx.shape[-1]),
                  "kernel_mass_kept": round(kept, 4)}
        t_img = pn.load_atlas_image(sparse["transport_atlas"], f"{obj.name} transport T atlas")
        i_img = pn.load_atlas_image(sparse["sparse_index"], f"{obj.name} transport T index")
        w_img = pn.load_atlas_image(sparse["sparse_weights"], f"{obj.name} transport T weights")
        group = build_sparse_group(store.directions.size, model.resolution, D, idx.shape[-1],
                                   t_img, i_img, w_img, eig_img,
                                   atlas_layout(eig_tiles, model.resolution)["tiles"][-1],
                                   uv_map, gname + " new")
        group["relight_taps"] = int(idx.shape[-1])
    else:
        tab_img = bpy.data.images.get(f"{obj.name} transport tables")
        group = build_group(-(-model.k // 3), model.resolution, s["table_size"], eig_img,
                            tab_img, uv_map, gname + " new")
    if old is not None:
        bpy.data.node_groups.remove(old)
    group.name = gname
    group["relight_viewport"] = viewport
    group["relight_report"] = report["report"]
    group[pn.OWNER] = obj.name
    indirect_group, ifiles = install_indirect_group(obj, report, bake, base, angle, uv_map)
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
                        label=f"Indirect ({indirect_group['relight_indirect']})")
            for k, v in (("Light Direction", direction), ("Intensity", intensity),
                         ("Color", col)):
                b.links.new(v, gi.inputs[k])
            out = b.vmath("ADD", out, gi.outputs["Color"], x=900, y=700)
        return out

    notes = pn._wire_preview(obj, color, "transport_texture")
    # environment groups of an earlier bake are stale: rebuilt from this one when shown
    for name in (f"{ENV_PREFIX} ({obj.name})", f"{ENV_PREFIX} indirect ({obj.name})"):
        stale = bpy.data.node_groups.get(name)
        if stale is not None:
            bpy.data.node_groups.remove(stale)
    _ENV_CACHE.pop(obj.name, None)
    props = getattr(scene, "relight", None)
    if props is not None and props.texture_light == "WORLD":
        set_light_mode(scene, obj, "WORLD")
    return {**files, **sparse, **ifiles, "group": gname, "group_nodes": len(group.nodes),
            "sun_angle": angle, "tiles": -(-model.k // 3), "viewport": viewport,
            "viewport_why": why, "copied_materials": notes}


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
    group = bpy.data.node_groups.get(f"{GROUP_PREFIX} ({obj.name})")
    if group is not None and group.get("relight_viewport") == "blocks" and bake.view is not None:
        from ...lt_addon.transport import block_viewport as bv

        btab = _tiles3(bv.tables(bake.view, store.directions, s["table_size"], sun_angle,
                                 s.get("kernel", "linear")))
        atlas = pack_atlas(btab, "edge")
        path = f"{base}_preview_block_tables.exr"
        exrio.write_exr(path, {c: atlas[..., i] for i, c in enumerate("RGB")},
                        {"format": "relightable_textures.block_preview", "tiles": len(btab),
                         "resolution": btab.shape[1], "sun_angle": sun_angle},
                        pixel_type="half")
        pn.load_atlas_image(path, f"{obj.name} transport block tables")
    if group is not None and group.get("relight_viewport") == "horizon":
        set_horizon_sun(group, sun_angle)
    if isinstance(bake.indirect, gt.GatheredIndirect):   # its tables follow the sun's size
        # at the side its group was built for (a group from before 64 had the bake's own)
        igroup = bpy.data.node_groups.get(f"{GROUP_PREFIX} indirect ({obj.name})")
        D = int(igroup.get("relight_indirect_table_size", s["table_size"])) if igroup else \
            indirect_table_size(s)
        _, itab = gt.preview_arrays(bake.indirect, sun_angle, D, s.get("kernel", "linear"))
        atlas = pack_atlas(itab, "edge")
        path = f"{base}_preview_indirect_tables.exr"
        exrio.write_exr(path, {c: atlas[..., i] for i, c in enumerate("RGB")},
                        {"format": "relightable_textures.gathered_indirect_preview",
                         "tiles": len(itab), "resolution": itab.shape[1],
                         "sun_angle": sun_angle}, pixel_type="half")
        pn.load_atlas_image(path, f"{obj.name} indirect tables")
    if group is not None and group.get("relight_viewport") == "transport":
        D = max(sp.TABLE_SIZE, int(s["table_size"]))
        idx, wts, _ = sp.cached_tables(store.directions, D, sun_angle, s.get("kernel", "linear"))
        files = write_sparse_tables(base, idx, wts, _scales(f"{base}_preview_transport.json"),
                                    sun_angle)
        i_img = pn.load_atlas_image(files["sparse_index"], f"{obj.name} transport T index")
        w_img = pn.load_atlas_image(files["sparse_weights"], f"{obj.name} transport T weights")
        if group.get("relight_taps") != idx.shape[-1]:   # a wider sun needs more taps
            uv_map = baked_uv_name(obj, report)
            eig_img = bpy.data.images.get(f"{obj.name} transport eigen atlas")
            new = build_sparse_group(
                store.directions.size, bake.model.resolution, D, idx.shape[-1],
                bpy.data.images.get(f"{obj.name} transport T atlas"), i_img, w_img, eig_img,
                atlas_layout(-(-bake.model.k // 3) + 1, bake.model.resolution)["tiles"][-1],
                uv_map, group.name + " new")
            for key in group.keys():
                new[key] = group[key]
            new["relight_taps"] = int(idx.shape[-1])
            for node in _group_nodes(obj, (group,)):
                node.node_tree = new
            new.use_fake_user = group.use_fake_user
            name = group.name
            bpy.data.node_groups.remove(group)
            new.name = name


# ---------------------------------------------------------------------------------------------
# the world's environment: constant coefficients rewritten from Python per change


def env_coefficients(V, B, directions, env, rotation_deg: float, strength: float = 1.0,
                     row_order: str = "bottom_first", validate: bool = True):
    """RGB coefficients of an environment for the environment groups.

    Parameters
    ----------
    V : ndarray, shape (S, K)
        The PCA's light loadings (T ~ V U).
    B : ndarray, shape (S, J) or None
        :func:`..lt_addon.transport.texture.steering_matrix` (None: no indirect term).
    env : ndarray, shape (H, W, 3) or (H, W)
        Equirectangular radiance (W m^-2 sr^-1), rows in ``row_order``.
    rotation_deg : float
        As :func:`..lt_addon.transport.texture.environment_weights` (``-`` the Mapping Z
        rotation).

    Returns
    -------
    C : ndarray, shape (3, K), float64 -- per colour channel, per component (W m^-2)
    G : ndarray, shape (3, J), float64, or None
    """
    W = tt.environment_weights(directions, env, row_order=row_order, rotation_deg=rotation_deg,
                               validate=validate)
    if W.ndim == 1:
        W = np.repeat(W[:, None], 3, axis=1)
    W = float(strength) * W[:, :3]
    C = W.T @ np.asarray(V, np.float64)
    G = None if B is None else W.T @ B
    return C, G


def viewport_relight_env(eig_tiles, C, indirect_images=None, G=None) -> np.ndarray:
    """NumPy twin of the environment groups: (R, R, 3). ``eig_tiles`` as
    :func:`preview_arrays` (albedo last); ``indirect_images`` (J, R, R, 3) at the same
    resolution (the node tree samples the indirect atlas at the texture's own texels)."""
    eig = np.asarray(eig_tiles, np.float64)
    n = eig.shape[0] - 1
    Cp = np.zeros((3, 3 * n))
    Cp[:, :C.shape[1]] = C
    e = np.einsum("ctk,tyxk->yxc", Cp.reshape(3, n, 3), eig[:n])
    out = e * eig[n]
    if G is not None:
        ind = np.einsum("cj,jyxc->yxc", G, np.asarray(indirect_images, np.float64))
        out = out + np.maximum(ind, 0.0)
    return out.astype(np.float32)


def build_env_group(n_tiles: int, resolution: int, eig_image, uv_map: str, name: str):
    """Direct light under an environment: per tile of three components, the eigen lookup
    dotted with three constant vectors (the components' R, G and B coefficients, nodes named
    ``C{t}{R|G|B}``, driven from the group's :data:`ENV_VALUES`), summed per channel, times the
    albedo tile."""
    group = pn.new_light_group(name)
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    b = pn._Builder(group)
    b.node("NodeGroupInput", -1400, 0)
    gout = b.node("NodeGroupOutput", 1400, 0)
    uv = b.node("ShaderNodeUVMap", -1200, -400, uv_map=uv_map).outputs["UV"]
    lay = atlas_layout(n_tiles + 1, resolution)
    acc = [None, None, None]
    driven = []
    for t in range(n_tiles):
        y = 600 - 300 * t
        e = _lookup(b, eig_image, pn.after_sum(b, uv, acc[0], -1200, y), lay["tiles"][t], -1000, y)
        for ch, cname in enumerate("RGB"):
            const = b.node("ShaderNodeCombineXYZ", -500, y - 80 * ch)
            const.name = const.label = f"C{t}{cname}"
            driven += [(const, i) for i in range(3)]
            dot = b.vmath("DOT_PRODUCT", const.outputs[0], e, x=-300, y=y - 80 * ch)
            acc[ch] = dot if acc[ch] is None else b.math("ADD", acc[ch], dot, x=-100 + 60 * ch,
                                                         y=y - 80 * ch)
    rgb = b.node("ShaderNodeCombineXYZ", 300, 0)
    for ch in range(3):
        b.links.new(acc[ch], rgb.inputs[ch])
    albedo = _lookup(b, eig_image, uv, lay["tiles"][n_tiles], -1000, -900)
    color = b.vmath("MULTIPLY", rgb.outputs[0], albedo, x=600, y=0)
    b.links.new(color, gout.inputs["Color"])
    _drive_constants(group, driven)
    return group


def build_env_indirect_group(texture, atlas_image, uv_map: str, name: str):
    """The steerable indirect term under an environment: ``max(0, sum_j G[:, j] * I_j)``
    (constant RGB vectors named ``G{j}``, driven from :data:`ENV_VALUES`), times the Albedo input in irradiance mode -- the
    sockets of :func:`.preview_nodes.build_group`."""
    group = pn.new_light_group(name)
    s = group.interface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
    s.default_value = (0.8, 0.8, 0.8, 1.0)
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    b = pn._Builder(group)
    gin = b.node("NodeGroupInput", -1400, 0)
    gout = b.node("NodeGroupOutput", 1000, 0)
    uv = b.node("ShaderNodeUVMap", -1200, -400, uv_map=uv_map).outputs["UV"]
    n = len(texture.basis_images)
    lay = atlas_layout(n, texture.resolution)
    acc = None
    driven = []
    for j in range(n):
        y = 600 - 160 * j
        img = _lookup(b, atlas_image, pn.after_sum(b, uv, None if acc is None else b.vmath(
            "DOT_PRODUCT", acc, (1.0, 0.0, 0.0), x=-1300, y=y), -1200, y), lay["tiles"][j],
            -1000, y)
        const = b.node("ShaderNodeCombineXYZ", -500, y)
        const.name = const.label = f"G{j}"
        driven += [(const, ch) for ch in range(3)]
        term = b.vmath("MULTIPLY", const.outputs[0], img, x=-300, y=y)
        acc = term if acc is None else b.vmath("ADD", acc, term, x=-100, y=y)
    out = b.vmath("MAXIMUM", acc, (0.0, 0.0, 0.0), x=300, y=0)
    if texture.settings.get("mode") == "irradiance":
        out = b.vmath("MULTIPLY", out, gin.outputs["Albedo"], x=500, y=0)
    b.links.new(out, gout.inputs["Color"])
    _drive_constants(group, driven)
    return group


#: ID property of an environment group holding its constants (driven into its nodes)
ENV_VALUES = "relight_env_values"


def _drive_constants(group, nodes_inputs) -> None:
    """Drive each (node, input index) from ``group[ENV_VALUES][k]`` in order (simple
    expressions: no Python when they evaluate). Writing 300 socket values from Python costs
    ~0.6 ms each (every write runs the node tree's update); one array property and one
    depsgraph update cost about a millisecond in all."""
    group[ENV_VALUES] = [0.0] * len(nodes_inputs)
    for k, (node, i) in enumerate(nodes_inputs):
        pn._drive(node.inputs[i], "default_value", -1, "NODETREE", group,
                  f'["{ENV_VALUES}"][{k}]')


def set_env_constants(group, prefix: str, values) -> None:
    """Write (3, K) coefficients into the group's driven constants: ``C`` (per tile of three
    components, the R, G, B rows; components beyond K get 0) or ``G`` (per basis image)."""
    values = np.asarray(values, np.float64)
    n = len(group[ENV_VALUES])
    if prefix == "C":
        tiles = n // 9
        padded = np.zeros((3, 3 * tiles))
        padded[:, :values.shape[1]] = values
        flat = padded.reshape(3, tiles, 3).transpose(1, 0, 2).ravel()   # [t][ch][i]
    else:
        flat = values.T.ravel()                                         # [j][ch]
    group[ENV_VALUES] = flat.tolist()
    group.update_tag()


_ENV_CACHE: dict = {}


def _env_data(obj):
    """The object's previewed transport bake as the environment preview needs it (loaded once
    per file): {"V", "B", "directions", "bake"}, or None without a PCA preview."""
    from ...lt_addon.transport.bundle import load_bake

    group = bpy.data.node_groups.get(f"{GROUP_PREFIX} ({obj.name})")
    path = None if group is None else group.get("relight_report")
    if not path or not os.path.exists(path):
        return None
    key = (path, os.path.getmtime(path))
    hit = _ENV_CACHE.get(obj.name)
    if hit is not None and hit["key"] == key:
        return hit
    bake, store, report = load_bake(path)
    if not getattr(bake.model, "live_preview", False):
        return None
    B = None if bake.indirect is None else gt.direction_matrix(bake.indirect, store.directions)
    data = {"key": key, "V": np.asarray(bake.model.V, np.float64), "B": B,
            "directions": store.directions, "bake": bake, "store": store, "report": report}
    _ENV_CACHE[obj.name] = data
    return data


def _group_nodes(obj, trees):
    """Group nodes in ``obj``'s materials whose tree is one of ``trees``."""
    out = []
    for mat in {s.material for s in obj.material_slots if s.material}:
        if mat.node_tree is None:
            continue
        out += [n for n in mat.node_tree.nodes
                if n.bl_idname == "ShaderNodeGroup" and n.node_tree in trees]
    return out


def set_light_mode(scene, obj, mode: str) -> bool:
    """Show ``obj``'s transport-texture preview lit by the sun sliders (``"SUN"``) or by the
    world's environment (``"WORLD"``): swaps the preview's group trees (building the
    environment groups the first time) and, for the world, writes its coefficients. False
    when ``obj`` has no such preview."""
    sun_g = bpy.data.node_groups.get(f"{GROUP_PREFIX} ({obj.name})")
    sun_i = bpy.data.node_groups.get(f"{GROUP_PREFIX} indirect ({obj.name})")
    env_name, envi_name = f"{ENV_PREFIX} ({obj.name})", f"{ENV_PREFIX} indirect ({obj.name})"
    if sun_g is None:
        return False
    env_g, env_i = bpy.data.node_groups.get(env_name), bpy.data.node_groups.get(envi_name)
    if mode == "WORLD":
        data = _env_data(obj)
        if data is None:
            return False
        if env_g is None:
            bake = data["bake"]
            n_tiles = -(-bake.model.k // 3)
            eig_img = bpy.data.images.get(f"{obj.name} transport eigen atlas")
            if eig_img is None:   # left out of the preview (over the GPU budget): made now
                eig_img = pca_atlas_image(obj, bake, data["store"], data["report"])
            uv_map = baked_uv_name(obj, data["report"])
            env_g = build_env_group(n_tiles, bake.model.resolution, eig_img, uv_map, env_name)
            env_g[pn.OWNER] = obj.name
            if sun_i is not None and bake.indirect is not None:
                iimg = bpy.data.images.get(sun_i.get("relight_indirect_image",
                                                     f"{obj.name} indirect atlas"))
                env_i = build_env_indirect_group(bake.indirect, iimg, uv_map, envi_name)
                env_i[pn.OWNER] = obj.name
        swaps = ((sun_g, env_g), (sun_i, env_i))
    else:
        swaps = ((env_g, sun_g), (env_i, sun_i))
    for old, new in swaps:
        if old is None or new is None:
            continue
        for node in _group_nodes(obj, (old,)):
            node.node_tree = new
        # the group not shown is kept for switching back (Remove Preview purges both)
        old.use_fake_user, new.use_fake_user = True, False
    if mode == "WORLD":
        update_environment_previews(scene, [obj])
    return True


_FINITE: list = [None, False]


def _finite(env) -> bool:
    """All texels finite? Checked once per image array (the world's pixels are cached)."""
    if _FINITE[0] is not env:
        _FINITE[:] = [env, bool(np.all(np.isfinite(env)))]
    return _FINITE[1]


def update_environment_previews(scene, objects=None) -> dict:
    """Rewrite the environment coefficients of every object (or of ``objects``) whose
    transport preview shows the world; returns {object: ms} and ``"warnings"`` (also kept in
    ``scene[ENV_WARNING_KEY]`` for the panel)."""
    from .vertex_relight import shade_rotation, world_light, world_rotation

    props = getattr(scene, "relight", None)
    timings, messages = {}, []
    objs = [o for o in (objects if objects is not None else scene.objects)
            if o.type == "MESH" and bpy.data.node_groups.get(f"{ENV_PREFIX} ({o.name})")]
    objs = [o for o in objs
            if _group_nodes(o, (bpy.data.node_groups[f"{ENV_PREFIX} ({o.name})"],))]
    if objs:
        t0 = time.perf_counter()
        env, world_strength = world_light(scene)
        world_z, note = world_rotation(scene)
        rotation = shade_rotation(world_z + (props.env_rotation if props else 0.0))
        strength = world_strength * (props.env_strength if props else 1.0)
        read_ms = 1e3 * (time.perf_counter() - t0)
        if env is not None and not _finite(env):
            messages.append("the world's Environment Texture has NaN or inf texels: the "
                            "environment preview is black")
            env = None
        if env is None and not messages:
            messages.append("the world has no Environment Texture or plain Background colour "
                            "the preview can read: the environment preview is black")
        if env is None:
            env = np.zeros((8, 16, 3))
        elif note:
            messages.append(note)
        for o in objs:
            t1 = time.perf_counter()
            data = _env_data(o)
            if data is None:
                continue
            C, G = env_coefficients(data["V"], data["B"], data["directions"], env, rotation,
                                    strength, validate=False)
            set_env_constants(bpy.data.node_groups[f"{ENV_PREFIX} ({o.name})"], "C", C)
            gi = bpy.data.node_groups.get(f"{ENV_PREFIX} indirect ({o.name})")
            if G is not None and gi is not None:
                set_env_constants(gi, "G", G)
            timings[o.name] = {"read_world_ms": read_ms,
                               "update_ms": 1e3 * (time.perf_counter() - t1)}
    text = "; ".join(messages)
    if scene.get(ENV_WARNING_KEY, "") != text:
        scene[ENV_WARNING_KEY] = text
    timings["warnings"] = messages
    return timings


def refresh_preview_tables(scene, obj, sun_angle: float) -> dict | None:
    """Rewrite ``obj``'s preview coefficient tables for a new sun size (no re-bake); returns
    {"seconds": ...} or None when ``obj`` has no transport preview."""
    from ...lt_addon.transport.bundle import KIND, load_bake
    from ..base.blend_files import object_bakes

    records = [b for b in object_bakes(obj) if b.get("kind") == KIND]
    if not records or bpy.data.node_groups.get(f"Relight Transport ({obj.name})") is None:
        return None
    t0 = time.perf_counter()
    bake, store, report = load_bake(bpy.path.abspath(records[-1]["path"]))
    if not getattr(bake.model, "live_preview", False):
        return None
    rewrite_tables(obj, report, bake, store, sun_angle)
    return {"seconds": time.perf_counter() - t0}
