"""A transport-texture bake's time, disk, RAM and GPU memory, predicted before it starts (bpy).

Two calibration bakes of the same objects and settings at 64^2 and 128^2 (the indirect term at
the same sizes), and one held-out truth light at each, give each stage's fixed and per-texel
cost on this machine and scene (:mod:`...lt_addon.transport.estimate`). These costs are then
applied to the asked sizes. A bake of 128^2 or less is calibrated at its own size and half of
it instead (:func:`small_calibration`). Where the UV map's triangles are narrower than a
texel at 64^2 but not at the asked size, the calibration moves up (:func:`calibration_sizes`):
a texel footprint refines such texels at every direction, so the small bake's cost per texel
is not the large one's. The calibration takes a few seconds. It writes nothing that stays:
the calibration bakes go to a temporary folder, without chunk caches.
"""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import replace

import numpy as np

from ...lt_addon.transport import estimate as est
from .bake_cost import memory_bytes, viewport_gpu
from ...lt_addon.transport import horizon_map as hmap
from ...lt_addon.transport import texture as tt
from ..base.cycles_bake import _size, available_memory_bytes
from ..base.jobs import Progress

#: calibration sizes (texels across), and the larger pairs tried when thin triangles make the
#: small ones unlike the asked size (:func:`calibration_sizes`)
CALIBRATION = (64, 128)
CALIBRATION_LADDER = ((64, 128), (128, 256), (256, 512))
#: How far the share of the UV area in thin triangles (:func:`...lt_addon.rays.footprint.
#: thin_area_share`) may differ between a calibration size and the asked one. On the test-size
#: bumps at 256^2 under Blender 5.3 (whole-texel jitter boxes) 64^2 had every texel thin and
#: 128^2 none: calibrated at 64^2 and 128^2 the bake took 1.56-1.76x its estimate (2026-12-06).
THIN_SHARE_TOLERANCE = 0.05


def calibration_sizes(objects, settings) -> tuple:
    """The calibration pair for ``settings.resolution``: a bake no larger than
    :data:`CALIBRATION`'s larger size is calibrated at its own size and half of it
    (:func:`small_calibration`); a larger one at the first of :data:`CALIBRATION_LADDER` below
    it whose sizes both hold as much of the UV area in thin triangles as the asked size (within
    :data:`THIN_SHARE_TOLERANCE`), else (64, 128)."""
    import bpy

    from ...lt_addon.rays.footprint import thin_area_share
    from ..base.ray_scene import mesh_arrays

    if settings.resolution <= CALIBRATION[1]:
        return small_calibration(settings.resolution)
    if getattr(settings, "texel_sampling", "footprint") != "footprint":
        return CALIBRATION
    depsgraph = bpy.context.evaluated_depsgraph_get()
    uvs = []
    for o in objects:
        m = mesh_arrays(o, depsgraph)
        if m.uv is not None:
            uvs.append(m.uv[m.loops.ravel()].reshape(-1, 3, 2))
    if not uvs:
        return CALIBRATION
    uv = np.concatenate(uvs)
    want = thin_area_share(uv, settings.resolution)
    for pair in CALIBRATION_LADDER:
        if pair[1] > settings.resolution:
            break
        if all(abs(thin_area_share(uv, r) - want) <= THIN_SHARE_TOLERANCE for r in pair):
            return pair
    return CALIBRATION


def small_calibration(resolution: int) -> tuple:
    """The calibration pair of a bake no larger than 128^2: its own size and half of it, so
    that from 8^2 up an estimate bakes 1.25 times the texels of the bake it predicts and
    measures the asked size itself (at 64^2 and 128^2 a 32^2 bake's estimate baked 20 times
    its texels); under 8^2, 4^2 and 8^2."""
    lo = max(4, int(resolution) // 2)
    return lo, max(2 * lo, int(resolution))


#: the calibration bakes' indirect grid: the bake's own, at most this side (texels across).
#: The gathered term's cost depends on the grid (its points and rays) and on the texture (its
#: PCA reads T's rows) apart; with the grid fixed, the calibration measures the texture's share.
#: (A term whose PCA grows its components, :data:`.indirect_gather.COMPONENT_TAIL`, grows them
#: in the calibration too, up to the cap of its grid: over a 256^2 grid the bake may keep fewer
#: than the calibration did, so its PCA is then overestimated, never under.)
CALIBRATION_GRID = 256
#: a bake at or above this resolution is estimated (and the estimate printed) before it starts
ESTIMATE_FROM = 512


def wanted(settings, client=None, env: str | None = None, resolutions: dict | None = None):
    """:func:`estimate` when a bake should be estimated before it starts (at
    :data:`ESTIMATE_FROM` texels across or more -- the settings' or an object's own side in
    ``resolutions`` --, not on Dask workers; ``env``, the value of ``$RELIGHT_ESTIMATE``: "1"
    always, "0" never), else None: what ``bake_job`` takes as its ``estimator``."""
    side = max([settings.resolution, *(resolutions or {}).values()])
    if env == "1" or (env != "0" and side >= ESTIMATE_FROM and client is None):
        return estimate
    return None


def calibrate(scene, objects, settings, truth: int, truth_samples: int):
    """Generator: the calibration bakes; returns the stage costs (:func:`.est.fit_costs`) and
    the seconds the calibration took."""
    from .texture_transport import scene_light_settings

    settings, _ = scene_light_settings(scene, settings)
    from .texture_transport import bake_transport_textures, truth_bakes, truth_lights

    from ...lt_addon.transport import sparse_tables as sp

    t0 = time.perf_counter()
    samples = []
    lights = truth_lights(1) if truth else []
    try:   # the calibration fits the viewport the asked size will show (T's fits at 96^2)
        from .texture_transport import resolve_directions

        shown, _ = sp.choose_viewport(settings.viewport,
                                      resolve_directions(scene, settings)[0].size,
                                      settings.resolution, budget_mib=settings.gpu_budget,
                                      table_size=settings.table_size)
    except Exception:
        shown = settings.viewport
    from .ray_direct import calibration_horizons, horizon_count

    # the bake times a block fit where T's atlas will not fit, and finds horizons where it
    # will make them: which of the two auto then shows is decided after both
    A = horizon_count(settings)
    grid = min(settings.indirect_resolution, CALIBRATION_GRID)
    sizes = calibration_sizes(objects, settings)
    for R in sizes:
        s = replace(settings, resolution=R, indirect_resolution=grid,
                    viewport="blocks" if shown == "blocks" else settings.viewport)
        with tempfile.TemporaryDirectory(prefix="relight-estimate-") as tmp, \
                calibration_horizons(A):
            res = yield from bake_transport_textures(scene, objects, s, tmp, resume=False)
            for b in res.objects:
                if b.store is not None:
                    b.store.abort()
        seconds = est.stage_seconds(res.seconds)
        u = {st: est.units(st, R, grid if settings.bounces > 0 and
                           settings.indirect != "none" else 0, len(objects), 1,
                           hmap.side(R, s.horizon_resolution))
             for st in est.STAGES}
        if lights:
            tr = yield from truth_bakes(scene, objects, lights, settings.sun_angle,
                                        settings.bounces, truth_samples, R)
            seconds["truth"] = tr["seconds"]
        samples.append((u, seconds))
        yield Progress(len(samples), len(sizes), f"calibration bake at {R}^2")
    return est.fit_costs(samples), time.perf_counter() - t0, sizes


def estimate(scene, objects, settings, truth: int = 4, truth_samples: int = 256):
    """Generator: the estimate of a bake of ``objects`` with ``settings`` (its truths:
    ``truth`` lights at ``truth_samples``). Returns a dict: ``seconds`` per stage, ``bake``
    and ``total``; ``disk_bytes``, ``ram_bytes`` (the peak, in stage ``ram_stage``),
    ``ram_available_bytes``,
    ``viewport_gpu_bytes`` and the viewport it would use; ``calibration_seconds``; ``lines``
    (what the CLI prints and the panel shows)."""
    from .texture_transport import scene_light_settings

    settings, _ = scene_light_settings(scene, settings)
    from .ray_direct import horizon_count
    from .texture_transport import path_horizons, resolve_directions

    # the bake's own direction set (with an animated Sun's path) and the horizons it then makes
    dset, path = resolve_directions(scene, settings)
    settings, _ = path_horizons(settings, path)
    costs, cal, sizes = yield from calibrate(scene, objects, settings, truth, truth_samples)
    # the indirect term's Cycles bakes (steerable) or points and rays (gathered) scale with the
    # indirect grid's texels (calibrated at this grid up to CALIBRATION_GRID); the gathered
    # term's PCA is a stage of its own, scaling with the texture's texels
    ri = (0 if settings.bounces == 0 or settings.indirect == "none" else
          settings.indirect_resolution)
    seconds = est.predict(costs, settings.resolution, ri, len(objects), truth,
                          hmap.side(settings.resolution, settings.horizon_resolution))
    P = settings.resolution ** 2
    disk = len(objects) * tt.transport_bytes(dset.size, P)
    viewport, gpu, blocks_if_not_horizons = viewport_gpu(settings, dset, len(objects))
    ram, ram_stage = memory_bytes(settings, dset, len(objects))
    blocks = 0.0
    if blocks_if_not_horizons:
        # the block viewport is chosen and fitted only for an object whose horizons auto does
        # not show: said apart, not in the bake's time (the statue and its ground at 2048^2 were
        # estimated at 570 s with it, and baked in 374 s, the ground showing its horizons)
        blocks = seconds.pop("fit_choose", 0.0) + seconds.pop("fit_blocks", 0.0)
        seconds["bake"] -= blocks
        seconds["total"] -= blocks
    out = {"seconds": {k2: round(v, 2) for k2, v in seconds.items()},
           "bake": round(seconds["bake"], 2), "total": round(seconds["total"], 2),
           "disk_bytes": int(disk), "ram_bytes": int(ram), "ram_stage": ram_stage,
           "ram_available_bytes": int(available_memory_bytes()),
           "viewport": viewport, "viewport_gpu_bytes": int(gpu),
           "calibration_seconds": round(cal, 2),
           "blocks_seconds": round(blocks, 2),
           # auto first finds the horizons on sampled tiles (horizon_trial): where T is then
           # clearly closer, the rest is not found; the calibration bakes find them whole
           "horizons_whole": (bool(horizon_count(settings)) and settings.viewport == "auto"
                              and settings.direct != "cycles"),
           "costs": {s: {"fixed_seconds": round(c.fixed, 4),
                         "seconds_per_million_units": round(c.per_unit * 1e6, 4)}
                     for s, c in costs.items()},
           "calibration_sizes": list(sizes),
           "method": f"stage costs fitted to calibration bakes at {sizes[0]}^2 and "
                     f"{sizes[1]}^2 of the same objects and settings on this machine, "
                     "linear in texels (lt_addon/transport/estimate.py)"}
    out["lines"] = describe(out, settings, len(objects))
    return out


def estimate_groups(scene, objects, settings, resolutions: dict | None = None, truth: int = 4,
                    truth_samples: int = 256):
    """Generator: :func:`estimate` of each group of objects of one texture side
    (``resolutions`` {name: side}, as ``texture_transport.bake_job`` bakes them). Returns
    ``{"groups": [estimate, ...], "lines": every group's lines}``."""
    from ...lt_addon.transport import object_resolution as orr

    objects = list(objects)
    parts = orr.groups([o.name for o in objects], settings.resolution, resolutions)
    out = {"groups": [], "lines": []}
    for side, idx in parts:
        e = yield from estimate(scene, [objects[i] for i in idx],
                                replace(settings, resolution=side), truth, truth_samples)
        out["groups"].append(e)
        out["lines"] += e["lines"]
    return out


def describe(e: dict, settings, n_objects: int) -> list:
    """The estimate in a few lines."""
    s = dict(e["seconds"])
    s["indirect"] = s.get("indirect", 0.0) + s.pop("indirect_pca", 0.0)   # one figure for users
    s["fit"] = s.get("fit", 0.0) + s.pop("fit_choose", 0.0) + s.pop("fit_blocks", 0.0)
    parts = [f"{name} {est.readable_seconds(s[name])}" for name in
             est.STAGES if name in s and (name != "horizons" or s[name] >= 0.5)]
    lines = [f"estimate for {n_objects} object(s) at {settings.resolution}^2: about "
             f"{est.readable_seconds(e['total'])} ({', '.join(parts)})",
             f"  disk {_size(e['disk_bytes'])} for T, memory {_size(e['ram_bytes'])} at most "
             f"(its {e.get('ram_stage', 'fit')} stage) of "
             f"{_size(e['ram_available_bytes'])} available, viewport ({e['viewport']}) "
             f"{_size(e['viewport_gpu_bytes'])} of GPU memory; calibrated in "
             f"{e['calibration_seconds']:.1f} s"]
    if e.get("horizons_whole") and s.get("horizons", 0.0) >= 0.5:
        lines.append("  the horizons are timed whole; for an object whose sampled tiles show T "
                     "clearly closer, only about an eighth is found (then the bake is shorter)")
    if e.get("blocks_seconds", 0.0) >= 0.5:
        lines.append(f"  an object whose horizons auto does not show gets the block viewport: "
                     f"up to {est.readable_seconds(e['blocks_seconds'])} more for all of them")
    return lines
