"""Godot LightmapGI files from L1 SH (bpy-free): the stacked EXR, its ``.import``, the
``LightmapGIData`` resource and a scene that puts them on the object.

What Godot reads (godotengine/godot master; scene/3d/lightmap_gi.cpp @ 0058f27,
forward_clustered/scene_forward_clustered.glsl @ 000ae03, modules/lightmapper_rd/
lm_compute.glsl @ 015dffd; PRs #95888 and #96114 for what changed in 4.4):

* **One EXR per atlas, its layers stacked vertically**, layer 0 the top band; a directional
  atlas has 4 layers, in the order L0, L1 y, L1 z, L1 x (the baker writes
  ``{l0, dir.y, dir.z, dir.x}`` at ``slice * 4 + j``; the shader reads ``uvw.z = slice * 4
  + j``). It is imported as a ``2d_array_texture`` with ``slices/vertical`` = layers.
* **Coefficients.** The shaded value is ``f(n) = L0 + L1 . n`` (irradiance over pi, "ready to
  apply"), n the normal in the LightmapGI node's frame (Y up, right-handed):

  - 4.4+ store packed, pre-convolved L1: layer 0 holds ``a`` = f's constant term, layers 1-3
    hold ``t = clamp(b / (8 a) + 0.5, 0, 1)`` (the lm_compute pack pass), and the shader does
    ``a + 4 a (2 t - 1) . n`` times the exposure normalisation (1 unless camera attributes are
    set). Data without ``_uses_packed_directional`` is refused by the node ("...isn't
    supported anymore. Please bake lightmaps again").
  - 4.0-4.3 store raw SH coefficients and decode ``0.282095 L0 + 0.32573 (L1 . n)``.

* **Frame.** The baker works in the LightmapGI node's frame; a node at the origin with no
  rotation makes it world space in Godot's axes. Blender's glTF exporter maps Blender's
  (x, y, z) to (x, z, -y), so the SH's world-frame L1 is turned by the same map.
* **UV.** Godot samples the lightmap with UV2, (0, 0) the image's top-left; glTF's
  ``TEXCOORD_1`` becomes UV2 on import, and Blender's glTF exporter writes v as 1 - v, so a
  band's top row is texture v = 1.

Arrays: SH ``L`` (P, 4, 3) in Sloan's order 00, 1-1, 10, 11 (y, z, x) of Blender's world
frame, P = R * R texels with row 0 at v = 0 (as our textures).
"""

from __future__ import annotations

import os
import shutil

import numpy as np

from ..io import atomic, exrio
from . import sh_lightmap as sh

VERSIONS = ("4.4", "4.3")

#: Godot's axes from Blender's (glTF's +Y up): (x, y, z)_godot = (x, z, -y).
BLENDER_TO_GODOT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

def _l1_godot(L) -> np.ndarray:
    """The L1 vector of world-frame SH (P, 4, 3) in Godot's axes: (P, xyz, 3)."""
    L = np.asarray(L, np.float64)
    vec = np.stack([L[:, 3], L[:, 1], L[:, 2]], axis=1)                  # (P, xyz, C) Blender
    return np.einsum("ij,pjc->pic", BLENDER_TO_GODOT, vec)


def encode(L, version: str) -> np.ndarray:
    """The four layers (4, P, 3) float64 Godot ``version`` reads: L0, then the L1 y, z, x
    terms. 4.3: the raw SH coefficients (its shader applies 0.282095 and 0.32573); 4.4+: the
    ready-to-apply ``a = 0.282095 L00`` and ``t = clamp(b / (8 a) + 0.5)`` of
    ``b = 0.32573 L1`` (the lm_compute pack pass)."""
    if version not in VERSIONS:
        raise ValueError(f"Godot version must be one of {', '.join(VERSIONS)}, got {version}")
    L = np.asarray(L, np.float64)
    g = _l1_godot(L)
    order = (1, 2, 0)                                                    # y, z, x
    if version == "4.3":
        return np.stack([L[:, 0]] + [g[:, i] for i in order])
    a, b = sh.K0 * L[:, 0], sh.K1 * g
    safe = np.where(a != 0, a, 1.0)
    t = [np.clip(np.where(a != 0, b[:, i] / (8.0 * safe), 0.0) + 0.5, 0.0, 1.0) for i in order]
    return np.stack([a] + t)


def decoded_sh(layers, version: str) -> np.ndarray:
    """World-frame SH (P, 4, 3) equivalent to what Godot shows of ``layers`` (4, P, 3): the
    inverse of :func:`encode` after its clamps and storage (for the export's error figures)."""
    lay = np.asarray(layers, np.float64)
    if version == "4.3":
        L00, g_yzx = lay[0], lay[1:]
    else:
        L00 = lay[0] / sh.K0
        g_yzx = 4.0 * lay[0][None] * (2.0 * lay[1:] - 1.0) / sh.K1
    g = np.stack([g_yzx[2], g_yzx[0], g_yzx[1]], axis=1)                  # (P, xyz, C) Godot
    vec = np.einsum("ji,pjc->pic", BLENDER_TO_GODOT, g)                  # back to Blender's
    L = np.empty((L00.shape[0], 4, 3))
    L[:, 0] = L00
    L[:, 3], L[:, 1], L[:, 2] = vec[:, 0], vec[:, 1], vec[:, 2]
    return L


def stacked(layers, resolution: int) -> np.ndarray:
    """The EXR's pixels (4 R, R, 3), top row first: layer 0 the top band, each band's top row
    texture v = 1."""
    R = resolution
    lay = np.asarray(layers).reshape(4, R, R, 3)
    return np.concatenate([band[::-1] for band in lay], axis=0)


def import_text(slices: int = 4) -> str:
    """The EXR's ``.import`` as the LightmapGI bake writes it (remap and params; Godot adds
    the uid, dest files and the other params at the first import). Compression: VRAM
    Uncompressed (mode 3, what 4.3's bake uses) so the half-float values stay as measured;
    4.4's own bake picks VRAM Compressed (mode 2, BC6H), which users may set."""
    return ("[remap]\n\nimporter=\"2d_array_texture\"\ntype=\"CompressedTexture2DArray\"\n\n"
            "[params]\n\ncompress/mode=3\ncompress/channel_pack=1\nmipmaps/generate=false\n"
            f"slices/horizontal=1\nslices/vertical={slices}\n")


def tres_text(exr_name: str, user_path: str, version: str) -> str:
    """A ``LightmapGIData`` resource: the EXR as its one lightmap texture, the object as its
    user (``user_path``: a NodePath from the LightmapGI node), SH on; 4.4 adds
    ``_uses_packed_directional``. No light probes (the probe data's required keys, empty)."""
    lines = ['[gd_resource type="LightmapGIData" load_steps=2 format=3]', "",
             f'[ext_resource type="CompressedTexture2DArray" path="{exr_name}" id="1_lm"]',
             "", "[resource]",
             'lightmap_textures = Array[TextureLayered]([ExtResource("1_lm")])',
             "uses_spherical_harmonics = true",
             f'user_data = [NodePath("{user_path}"), Rect2(0, 0, 1, 1), 0, -1]',
             "probe_data = {", '"baked_exposure": 1.0,', '"bounds": AABB(0, 0, 0, 0, 0, 0),',
             '"bsp": PackedInt32Array(),', '"interior": false,',
             '"points": PackedVector3Array(),', '"sh": PackedColorArray(),',
             '"tetrahedra": PackedInt32Array()', "}"]
    if version == "4.4":
        lines.append("_uses_packed_directional = true")
    return "\n".join(lines) + "\n"


def tscn_text(glb_name: str, tres_name: str, node: str) -> str:
    """A scene with the glTF's scene as ``node`` and a LightmapGI at the origin holding the
    data (its user path ``../<node>/<node>``: the glTF root, then its mesh node)."""
    return "\n".join([
        '[gd_scene load_steps=3 format=3]', "",
        f'[ext_resource type="PackedScene" path="{glb_name}" id="1_mesh"]',
        f'[ext_resource type="LightmapGIData" path="{tres_name}" id="2_lm"]', "",
        f'[node name="{node}_lightmapped" type="Node3D"]', "",
        f'[node name="{node}" parent="." instance=ExtResource("1_mesh")]', "",
        '[node name="LightmapGI" type="LightmapGI" parent="."]', "directional = true",
        'light_data = ExtResource("2_lm")', ""])


def names(stem: str) -> dict:
    """The files of a Godot export folder ``<stem>/``."""
    return {"exr": f"{stem}.exr", "import": f"{stem}.exr.import", "tres": f"{stem}.tres",
            "tscn": f"{stem}.tscn", "glb": f"{stem}.glb"}


def write(folder: str, L, resolution: int, version: str, node: str, glb_path: str,
          metadata: dict) -> dict:
    """Write the folder atomically (staged under a temporary name, swapped in whole): the
    stacked half EXR, its ``.import``, the ``.tres``, a ``.tscn``, and the glTF moved in from
    ``glb_path``. Returns {role: absolute path}."""
    folder = os.path.abspath(folder)
    stem = os.path.basename(folder)
    n = names(stem)
    with atomic.staged_folder(folder) as tmp:
        img = stacked(encode(L, version), resolution)
        exrio.write_exr(os.path.join(tmp, n["exr"]),
                        {c: img[::-1, :, i] for i, c in enumerate("RGB")},   # exrio: row 0 at the bottom
                        {**metadata, "godot": version}, pixel_type="half")
        atomic.write_text(os.path.join(tmp, n["import"]), import_text())
        atomic.write_text(os.path.join(tmp, n["tres"]),
                          tres_text(n["exr"], f"../{node}/{node}", version))
        atomic.write_text(os.path.join(tmp, n["tscn"]), tscn_text(n["glb"], n["tres"], node))
        shutil.move(glb_path, os.path.join(tmp, n["glb"]))
    return {k: os.path.join(folder, v) for k, v in n.items()}
