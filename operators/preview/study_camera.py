"""A sun study's shadow-study sheet from the scene's camera, and one of its cells next to a
Cycles render of the same hour (bpy; issue 58).

A cell is what the texture-space sheet shows -- each baked object's direct sun on a white
surface, ``cos x visibility`` from its T at that hour's Sun (:func:`...lt_addon.sun.
sunlight_hours.direct_light`), 1 facing the Sun unshadowed -- seen from the scene camera.
One Cycles render finds, for every pixel, the baked object and its UV there (an emission
material override showing ``(u, v, object)``, pixel centres, at twice the sheet's size);
every cell is then a texture lookup per pixel, averaged 2 x 2: no render per hour. Pixels of
objects that were not baked (and the background) are black. The frames are also written one
PNG each (an image sequence, in sheet order).

The check cell is rendered by Cycles as well: every material overridden by a white diffuse
one, direct light only (0 bounces: the cells are the direct sun), under a Sun lamp of that
hour's direction and the study's sun size with strength pi (so a white surface facing it
shows 1, as the cells do), the world off and the scene's lamps hidden. The picture
``from the bake | Cycles | |difference| x 4`` and the relative RMSE over the baked objects'
pixels go into the study's report.
"""

from __future__ import annotations

import math
import os
import tempfile
import time

import bpy
import numpy as np

from ...lt_addon.io.contact_sheet import linear_to_srgb8, write_png
from ...lt_addon.sun import study_images
from ..base.compat import ensure_node_tree
from ..base.meshes import baked_uv_name
from . import compare_render

#: Files and folder the camera sheet writes into the study's folder.
SHEET_PNG = "camera_sheet.png"
FRAMES_DIR = "camera_frames"
CHECK_PNG = "camera_check.png"
#: Lowest Sun elevation (degrees) the default check cell may have: lower suns leave the
#: picture mostly in shadow, so its error says little about the lit parts.
CHECK_MIN_ELEVATION = 5.0
#: The UV pass renders this many pixels a side per sheet pixel (then averaged).
SUPERSAMPLE = 2
_ID = "relight_study_camera_id"


def output_names(check: bool = True) -> list:
    """The names (in the study's folder) a camera sheet writes; the frames' folder included."""
    return [SHEET_PNG, FRAMES_DIR] + ([CHECK_PNG] if check else [])


def check_cell(cells, chosen: str | None = None) -> int | None:
    """The index of the cell to check against Cycles: ``chosen`` ("DATE,HH:MM"; ValueError
    unless it is a cell of the sheet with the Sun up), else the cell with the lowest Sun at
    least :data:`CHECK_MIN_ELEVATION` up (a low sun shows a bake's faults most), else the
    highest Sun; None when the Sun is down in every cell."""
    if chosen:
        day, _, clock = chosen.replace(" ", ",").partition(",")
        clock = clock.strip()
        if clock.isdigit() and len(clock) <= 2:
            clock = f"{int(clock):02d}:00"
        for i, c in enumerate(cells):
            if c["date"] == day.strip() and c["clock"] == clock:
                if c["direction"] is None:
                    raise ValueError(f"the Sun is down (or the time does not exist) at {chosen}")
                return i
        raise ValueError(f"{chosen} is not a cell of the sheet; its cells are "
                         + ", ".join(f"{c['date']},{c['clock']}" for c in cells[:6])
                         + (" ..." if len(cells) > 6 else ""))
    up = [(c["elevation"], i) for i, c in enumerate(cells) if c["direction"] is not None]
    if not up:
        return None
    high = [u for u in up if u[0] >= CHECK_MIN_ELEVATION]
    return min(high)[1] if high else max(up)[1]


class _Overrides:
    """Context manager: the render settings, world, lamps, material override and bounces the
    camera sheet changes, restored on exit (the .blend is not changed)."""

    def __init__(self, scene, size: int):
        self.scene, self.size = scene, int(size)

    def __enter__(self):
        s = self.scene
        r, c = s.render, s.cycles
        cam = s.camera.data
        # what would change the UV pass's values (u, v and an object index, read back as
        # numbers): clamping, exposure, a render region, motion blur, depth of field
        self.saved = [(r, "resolution_x", r.resolution_x), (r, "resolution_y", r.resolution_y),
                      (r, "resolution_percentage", r.resolution_percentage),
                      (r, "use_border", r.use_border), (r, "use_motion_blur", r.use_motion_blur),
                      (c, "max_bounces", c.max_bounces), (c, "filter_width", c.filter_width),
                      (c, "sample_clamp_direct", c.sample_clamp_direct),
                      (c, "sample_clamp_indirect", c.sample_clamp_indirect),
                      (c, "film_exposure", c.film_exposure), (cam.dof, "use_dof", cam.dof.use_dof),
                      (s, "world", s.world)]
        self.restore_render = compare_render.saved_render_settings(s)
        self.view_layer = bpy.context.view_layer
        self.override = self.view_layer.material_override
        self.lamps = [(o, o.hide_render) for o in s.objects if o.type == "LIGHT"]
        self.made = []
        base = (r.resolution_x * r.resolution_percentage / 100.0,
                r.resolution_y * r.resolution_percentage / 100.0)
        f = self.size / max(base)
        r.resolution_x, r.resolution_y = (max(1, round(b * f)) for b in base)
        r.resolution_percentage = 100
        r.use_border = r.use_motion_blur = cam.dof.use_dof = False
        c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
        c.film_exposure = 1.0
        s.world = None
        c.max_bounces = 0
        for o, _ in self.lamps:
            o.hide_render = True
        return self

    def material(self, name: str):
        mat = bpy.data.materials.new(name)
        self.made.append(mat)
        return mat

    def __exit__(self, *exc):
        self.view_layer.material_override = self.override
        for mat in self.made:
            bpy.data.materials.remove(mat)
        for o, h in self.lamps:
            o.hide_render = h
        for owner, name, value in self.saved:
            setattr(owner, name, value)
        self.restore_render()
        return False


def _uv_material(ov, uv_map: str):
    """Emission of ``(u, v, object id)``: the UV pass's override material."""
    mat = ov.material("RelightStudyUV")
    tree = ensure_node_tree(mat)
    tree.nodes.clear()
    uv = tree.nodes.new("ShaderNodeUVMap")
    uv.uv_map = uv_map
    sep = tree.nodes.new("ShaderNodeSeparateXYZ")
    ident = tree.nodes.new("ShaderNodeAttribute")
    ident.attribute_type, ident.attribute_name = "OBJECT", _ID
    comb = tree.nodes.new("ShaderNodeCombineXYZ")
    em = tree.nodes.new("ShaderNodeEmission")
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(uv.outputs["UV"], sep.inputs[0])
    tree.links.new(sep.outputs[0], comb.inputs[0])
    tree.links.new(sep.outputs[1], comb.inputs[1])
    tree.links.new(ident.outputs["Fac"], comb.inputs[2])
    tree.links.new(comb.outputs[0], em.inputs["Color"])
    tree.links.new(em.outputs[0], out.inputs["Surface"])
    return mat


def uv_pass(scene, objects, uv_maps, tmp: str, ov):
    """Per pixel of the camera (at the scene's current size, row 0 at the bottom): the index
    into ``objects`` of the object seen there (-1: none of them) and its ``(u, v)``.
    ``uv_maps[i]`` is the UV map ``objects[i]`` was baked in; one render per distinct map.
    ``ov``: the :class:`_Overrides` in force (it removes the materials made here)."""
    index = uv = None
    for k, o in enumerate(objects):
        o[_ID] = float(k + 1)
    scene.cycles.filter_width = 0.01        # one sample at each pixel's centre
    try:
        for name in sorted(set(uv_maps)):
            bpy.context.view_layer.material_override = _uv_material(ov, name)
            img = compare_render.render_camera(scene, os.path.join(tmp, "uv.exr"), 1)
            ident = np.rint(img[..., 2]).astype(np.int64) - 1
            mine = np.isin(ident, [k for k, m in enumerate(uv_maps) if m == name])
            if index is None:
                index = np.full(ident.shape, -1, np.int64)
                uv = np.zeros(ident.shape + (2,), np.float64)
            index[mine] = ident[mine]
            uv[mine] = img[..., :2][mine]
    finally:
        for o in objects:
            if _ID in o:
                del o[_ID]
    return index, uv


def _sample(tex, uv) -> np.ndarray:
    """Bilinear lookup of ``tex`` (R, R), row 0 at v = 0, at ``uv`` (N, 2), texel centres at
    ``(i + 0.5) / R``; clamped at the edges."""
    R = tex.shape[0]
    x = np.clip(uv[:, 0] * R - 0.5, 0.0, R - 1.0)
    y = np.clip(uv[:, 1] * R - 0.5, 0.0, R - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), R - 2) if R > 1 else np.zeros_like(x, int)
    y0 = np.minimum(np.floor(y).astype(np.int64), R - 2) if R > 1 else np.zeros_like(y, int)
    fx, fy = x - x0, y - y0
    x1, y1 = np.minimum(x0 + 1, R - 1), np.minimum(y0 + 1, R - 1)
    return ((tex[y0, x0] * (1 - fx) + tex[y0, x1] * fx) * (1 - fy)
            + (tex[y1, x0] * (1 - fx) + tex[y1, x1] * fx) * fy)


def shade(index, uv, textures) -> np.ndarray:
    """A camera picture (H, W) from one cell's per-object textures (``textures[k]`` (R, R) or
    None) at the UV pass's pixels; 0 where no baked object is seen."""
    out = np.zeros(index.shape, np.float64)
    for k, tex in enumerate(textures):
        if tex is None:
            continue
        m = index == k
        if m.any():
            out[m] = _sample(np.asarray(tex, np.float64), uv[m])
    return out


def _down(img, k: int) -> np.ndarray:
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    return img[:h, :w].reshape(h // k, k, w // k, k).mean(axis=(1, 3))


def camera_sheet(scene, folder: str, cells, n_cols: int, title, textures: dict, *,
                 sun_angle: float, size: int = 320, check: str | None = None,
                 check_size: int = 640, check_samples: int = 128) -> dict:
    """Draw the sheet's ``cells`` (:func:`...lt_addon.sun.sun_study._sheet_cells`) from the
    scene camera into ``folder``: :data:`SHEET_PNG` and one frame a cell in
    :data:`FRAMES_DIR`; with ``check_samples`` > 0 one cell against Cycles in
    :data:`CHECK_PNG`. ``textures``: per baked object's name ``{"uv_map": ..., "cells": [a
    cell's direct-light texture (R, R) or None, ...]}``. ``size`` / ``check_size``: the longer
    side in pixels. Returns the figures for the study's report."""
    if scene.camera is None or scene.camera.type != "CAMERA":
        raise ValueError(f"scene {scene.name!r} has no camera")
    t0 = time.perf_counter()
    frames_dir = os.path.join(folder, FRAMES_DIR)
    if os.path.islink(frames_dir) or (os.path.exists(frames_dir)
                                      and not os.path.isdir(frames_dir)):
        raise ValueError(f"{frames_dir} is a link or a file: remove it or choose another --out")
    os.makedirs(frames_dir, exist_ok=True)
    for name in os.listdir(frames_dir):     # an earlier study's frames (--force)
        path = os.path.join(frames_dir, name)
        if name.startswith("frame_") and name.endswith(".png") and os.path.isfile(path) \
                and not os.path.islink(path):
            os.remove(path)
    names = [n for n in textures if n in scene.objects and scene.objects[n].type == "MESH"]
    missing = [n for n in textures if n not in names]
    if not names:
        raise ValueError("none of the study's objects (" + ", ".join(textures)
                         + f") is a mesh of scene {scene.name!r}")
    objects = [scene.objects[n] for n in names]
    uv_maps = [baked_uv_name(o, {"uv_map": textures[o.name].get("uv_map")}) for o in objects]

    def picture(index, uv, c, k):
        return _down(shade(index, uv, [textures[n]["cells"][c] for n in names]), k)

    tiles, frames = [], []
    with tempfile.TemporaryDirectory() as tmp:
        with _Overrides(scene, size * SUPERSAMPLE) as ov:
            index, uv = uv_pass(scene, objects, uv_maps, tmp, ov)
        t_pass = time.perf_counter() - t0
        for c, cell in enumerate(cells):
            if cell["direction"] is None and cell["elevation"] is None:
                tiles.append((None, cell["line1"], cell["line2"]))
                continue
            img = picture(index, uv, c, SUPERSAMPLE)
            tiles.append((img, cell["line1"], cell["line2"]))
            name = f"frame_{c + 1:04d}.png"
            write_png(os.path.join(frames_dir, name),
                      np.repeat(linear_to_srgb8(img[::-1])[..., None], 3, axis=2))
            frames.append(name)
    write_png(os.path.join(folder, SHEET_PNG), study_images.sheet(
        tiles, n_cols, ["the scene camera: direct sun on white surfaces, from the bake",
                        *title], min_width=max(size, 256)))
    info = {"sheet_png": SHEET_PNG, "frames": [f"{FRAMES_DIR}/{f}" for f in frames],
            "size": [int(index.shape[1] // SUPERSAMPLE), int(index.shape[0] // SUPERSAMPLE)],
            "objects": names, "not_in_scene": missing,
            "shows": "cos x visibility of each baked object's T at the hour's Sun (a white "
                     "surface's direct sun, 1 facing it), seen from the scene camera",
            "seconds": {"uv_pass": round(t_pass, 3),
                        "cells": round(time.perf_counter() - t0 - t_pass, 3)}}
    i = check_cell(cells, check) if check_samples > 0 else None
    if i is not None:
        info["check"] = _check(scene, objects, uv_maps, names, textures, cells, i, folder,
                               sun_angle, check_size, check_samples)
    info["seconds"]["total"] = round(time.perf_counter() - t0, 3)
    return info


def _check(scene, objects, uv_maps, names, textures, cells, i, folder, sun_angle, size,
           samples) -> dict:
    """Cell ``i`` from the bake next to Cycles (module docstring): the report's figures."""
    from mathutils import Vector

    t0 = time.perf_counter()
    cell = cells[i]
    with tempfile.TemporaryDirectory() as tmp:
        with _Overrides(scene, size * SUPERSAMPLE) as ov:
            index, uv = uv_pass(scene, objects, uv_maps, tmp, ov)
        ours = _down(shade(index, uv, [textures[n]["cells"][i] for n in names]), SUPERSAMPLE)
        # the pixels wholly on baked objects (edges against others or the sky left out)
        mask = _down((index >= 0).astype(np.float64), SUPERSAMPLE) == 1.0
        with _Overrides(scene, size) as ov:
            white = ov.material("RelightStudyWhite")
            tree = ensure_node_tree(white)
            tree.nodes.clear()
            bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
            bsdf.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            out = tree.nodes.new("ShaderNodeOutputMaterial")
            tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
            bpy.context.view_layer.material_override = white
            scene.cycles.filter_width = 1.5
            data = bpy.data.lights.new("RelightStudySun", type="SUN")
            sun = bpy.data.objects.new("RelightStudySun", data)
            data.energy, data.angle = math.pi, math.radians(sun_angle)
            sun.rotation_euler = (-Vector(cell["direction"])).to_track_quat("-Z", "Y") \
                .to_euler()
            scene.collection.objects.link(sun)
            try:
                t1 = time.perf_counter()
                truth = compare_render.render_camera(scene, os.path.join(tmp, "truth.exr"),
                                                     samples)[..., 0]
                t_cycles = time.perf_counter() - t1
            finally:
                bpy.data.objects.remove(sun)
                bpy.data.lights.remove(data)
    ours3, truth3 = np.repeat(ours[..., None], 3, -1), np.repeat(truth[..., None], 3, -1)
    err = compare_render.rel_rmse(ours3, truth3, mask)
    captions = [f"{cell['date']} {cell['clock']}, from the bake",
                f"Cycles, Sun {sun_angle:.3g} deg, {samples} spp",
                f"|diff| x4, rel {err:.3f}"]
    write_png(os.path.join(folder, CHECK_PNG),
              compare_render.comparison_row(ours3, truth3, captions))
    return {"png": CHECK_PNG, "date": cell["date"], "clock": cell["clock"],
            "elevation": cell["elevation"], "azimuth": cell["azimuth"],
            "size": [int(ours.shape[1]), int(ours.shape[0])], "cycles_samples": samples,
            "cycles": "white diffuse override, direct light only (0 bounces), Sun lamp of "
                      "the cell's direction and the study's size, world off, lamps hidden",
            "rel_rmse_baked_pixels": err,
            "seconds": {"all": round(time.perf_counter() - t0, 3),
                        "cycles_render": round(t_cycles, 3)}}
