"""Look at a bake the way a user does: the live preview next to a Cycles render of the same Sun,
rendered from the scene camera (bpy).

:func:`compare` renders the open scene twice with Cycles -- once through the preview materials
(emission: exactly what the viewport preview computes), once with the user's own materials under a
real Sun lamp of the same direction, size and strength with the scene's bounces -- and writes
``preview | Cycles | |difference| x 4`` side by side as a PNG (sRGB, values clipped at 1), each
panel captioned with what it is (light, sun size, samples, the error), plus the relative RMSE
over the pixels the relit objects cover.
"""

from __future__ import annotations

import math
import os
import tempfile

import bpy
import numpy as np

from ...lt_addon.io import exrio
from ...lt_addon.io.contact_sheet import linear_to_srgb8, write_png
from ...lt_addon.io.label import labelled_row
from ..base.cycles_bake import BakeInputError
from . import preview_nodes


def render_camera(scene, path: str, samples: int, engine: str = "CYCLES") -> np.ndarray:
    """F12 from the scene camera with ``engine`` (Cycles: ``samples``, no denoiser, no
    adaptive sampling; EEVEE: ``samples`` anti-aliasing samples), written to ``path`` as a
    32-bit EXR and read back: (H, W, 3) linear RGB, row 0 at the bottom."""
    scene.render.engine = engine
    if engine == "CYCLES":
        scene.cycles.samples = samples
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
    else:
        scene.eevee.taa_render_samples = samples
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    ch, _ = exrio.read_exr(path)
    return np.stack([ch["R"], ch["G"], ch["B"]], -1).astype(np.float64)


def saved_render_settings(scene):
    """What :func:`render_camera` changes, saved; returns the callable that restores it."""
    r, c, im = scene.render, scene.cycles, scene.render.image_settings
    saved = [(r, "engine", r.engine), (r, "filepath", r.filepath),
             (c, "samples", c.samples), (c, "use_denoising", c.use_denoising),
             (c, "use_adaptive_sampling", c.use_adaptive_sampling),
             (im, "file_format", im.file_format), (im, "color_depth", im.color_depth)]

    def restore():
        for owner, name, value in saved:
            try:
                setattr(owner, name, value)
            except (TypeError, ValueError):   # e.g. a depth the restored format lacks
                pass
    return restore


def rel_rmse(preview, truth, mask=None) -> float:
    """Relative RMSE of ``preview`` against ``truth`` (H, W, 3) over ``mask`` (default: the
    pixels the preview covers, the relit objects: it renders nothing else); NaN where none."""
    if mask is None:
        mask = preview.sum(-1) > 0
    return (float(np.linalg.norm((preview - truth)[mask]) / np.linalg.norm(truth[mask]))
            if mask.any() else float("nan"))


def comparison_row(preview, truth, captions) -> np.ndarray:
    """``preview | truth | |difference| x 4`` (linear RGB, row 0 at the bottom) as one
    captioned sRGB row, PNG order."""
    diff = np.abs(preview - truth)
    # captions readable at any size: about 40 characters across a panel
    scale = max(2, preview.shape[1] // 256)
    # renders come bottom row first; PNG rows go top first
    return labelled_row([(linear_to_srgb8(img[::-1]), text) for img, text in
                         zip((preview, truth, 4.0 * diff), captions)],
                        gap=2 * scale, scale=scale)


def compare(scene, objects, azimuth: float, elevation: float, sun_angle: float, out_png: str,
            samples: int = 128, resolution: int | None = None) -> dict:
    """Render preview vs Cycles Sun from the scene camera; write the PNG; return figures.

    ``resolution`` (pixels) is the longer side of the renders, the camera's aspect kept;
    None renders at the scene's own size. The scene's render settings, world, lamps and the
    preview sliders are restored afterwards (the .blend is not changed)."""
    from ...lt_addon.sphere.hemisphere import direction_from_az_el
    from mathutils import Vector

    from .transport_preview import refresh_preview_tables

    if scene.camera is None:
        raise BakeInputError(f"scene {scene.name!r} has no camera to render the comparison from")
    previews = [o for o in objects if any(
        n.get("relight_preview") for s in o.material_slots if s.material and s.material.node_tree
        for n in s.material.node_tree.nodes)]
    if not previews:
        raise BakeInputError("none of the objects has a relight preview; bake first")
    saved = {k: scene.get(k) for k in ("relight_azimuth", "relight_elevation",
                                       "relight_intensity", "relight_follow_sun")}
    world, res = scene.world, (scene.render.resolution_x, scene.render.resolution_y,
                               scene.render.resolution_percentage)
    render = saved_render_settings(scene)
    hidden = [(o, o.hide_render) for o in scene.objects if o.type == "LIGHT"]
    undo = []
    data = bpy.data.lights.new("RelightCompareSun", type="SUN")
    sun = bpy.data.objects.new("RelightCompareSun", data)
    try:
        for o in previews:
            refresh_preview_tables(scene, o, sun_angle)
        if resolution:
            f = int(resolution) / max(res[0], res[1])
            scene.render.resolution_x = max(1, round(res[0] * f))
            scene.render.resolution_y = max(1, round(res[1] * f))
            scene.render.resolution_percentage = 100
        scene["relight_azimuth"], scene["relight_elevation"] = float(azimuth), float(elevation)
        scene["relight_intensity"], scene["relight_follow_sun"] = 1.0, 0.0
        scene.world = None
        for o, _ in hidden:
            o.hide_render = True
        scene.update_tag()
        bpy.context.view_layer.update()
        with tempfile.TemporaryDirectory() as tmp:
            # Cycles sees the preview for this render only (its output targets EEVEE)
            undo = preview_nodes.render_previews(previews, "CYCLES")
            try:
                preview = render_camera(scene, os.path.join(tmp, "preview.exr"), 1)
            finally:
                for f in undo:
                    f()
                undo = []
            scene.collection.objects.link(sun)
            data.energy, data.angle = 1.0, math.radians(sun_angle)
            towards = Vector(direction_from_az_el(azimuth, elevation).tolist())
            sun.rotation_euler = (-towards).to_track_quat("-Z", "Y").to_euler()
            truth = render_camera(scene, os.path.join(tmp, "truth.exr"), samples)
        err = rel_rmse(preview, truth)
        # short enough to fit a 256 px panel at scale 2 (20 characters)
        captions = [f"preview, az {azimuth:.0f} el {elevation:.0f}",
                    f"Cycles Sun {sun_angle:.3g} deg",
                    f"|diff| x4, rel {err:.3f}"]
        write_png(out_png, comparison_row(preview, truth, captions))
        return {"png": os.path.abspath(out_png), "azimuth": azimuth, "elevation": elevation,
                "sun_angle": sun_angle, "truth_samples": samples,
                "rel_rmse_covered_pixels": err, "panels": " | ".join(captions)}
    finally:
        for f in reversed(undo):
            f()
        bpy.data.objects.remove(sun)
        bpy.data.lights.remove(data)
        for o, h in hidden:
            o.hide_render = h
        scene.world = world
        scene.render.resolution_x, scene.render.resolution_y, \
            scene.render.resolution_percentage = res
        render()
        for k, v in saved.items():
            if v is not None:
                scene[k] = v


def report_comparison(scene, objects, lights, sun_angle: float, out_png: str, samples: int,
                      resolution: int = 256) -> dict:
    """The comparison image of a bake report: :func:`compare` at the lowest of the held-out
    ``lights`` ((azimuth, elevation) degrees; low suns show a bake's faults most), rendered
    from the scene camera at ``resolution`` px on the longer side. Without a camera, returns
    ``{"skipped": why}`` (the report's UV-space contact sheet, where there is one, is then
    the picture). ``samples`` is capped at 64. Adds ``seconds`` (wall) to the figures."""
    import time

    if scene.camera is None:
        return {"skipped": f"scene {scene.name!r} has no camera; no camera-space comparison"}
    azimuth, elevation = min(lights, key=lambda light: light[1])
    t0 = time.perf_counter()
    # a picture to look at, not the measured error (the truth bakes are): 64 spp at most
    # keeps it at seconds (9 s at 64 spp, 256 px on the test statue, 2 cores)
    info = compare(scene, objects, azimuth, elevation, sun_angle, out_png, min(samples, 64),
                   resolution)
    info["seconds"] = round(time.perf_counter() - t0, 3)
    return info
