"""Direction-sampled transport textures baked with Cycles (bpy): the default texture bake.

For every selected object, in the same Cycles calls:

1. an **albedo** texture (DIFFUSE colour pass, no light);
2. the **direct transport** ``T[s]``: one irradiance bake per direction ``w_s`` of a hemisphere
   set under a hard Sun (angle 0, strength 1, 1 sample: noise-free apart from anti-aliasing),
   streamed to a float16 store on disk (:class:`..lt_addon.transport.texture.TransportStore`)
   one direction at a time, so memory holds one image, never ``T``;
3. the **indirect** light as its own term, when the scene has bounces: by default gathered by
   rays over T's own directions and kept as a PCA over them (:mod:`.indirect_gather`,
   ``indirect="gather"``); or a low-order steerable bake of Cycles' indirect pass
   (``"steerable"``, the earlier default: Ashikhmin & Shirley's lobes), in radiance units.

Relit radiance for a sun of angular size ``a`` from ``w0`` and normal irradiance ``I``::

    I * (albedo * sum_s k_s(w0, a) T[s]  +  max(0, sum_s k_s(w0, a) V[s] @ U))   (gathered)
    I * (albedo * sum_s k_s(w0, a) T[s]  +  steer(indirect, w0))               (steerable)

The same geometry-of-the-generator as the other bakes: a generator yielding Progress and
returning the result; stopping it restores the scene and deletes the partial store.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from dataclasses import dataclass

import numpy as np

from ... import __version__
from ...lt_addon.io.transaction import after_commit
from ...lt_addon import blas_threads, faults
from ...lt_addon.peak_memory import PeakMemory
from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem
from ...lt_addon.caveats import report_warnings
from ...lt_addon.transport import texture as tt
from ...lt_addon.transport.gathered_texture import indirect_images
from ...lt_addon.sphere.hemisphere import direction_from_az_el
from ..base import cycles_device
from ..base.cycles_bake import BakeInputError, EnvironmentBake, check_bakeable, check_memory
from ..base.bake_inputs import CACHE_FOLDER, cache_root
from ..base.jobs import Progress
# The bundle (settings, files, report, reading and relighting) is bpy-free; re-exported here for
# the bake and its callers.
from ...lt_addon.transport.bundle import (INDIRECT, KIND, MODELS, TRUTH_LIGHTS, VIEWPORTS,  # noqa: F401
                                          ObjectBake, TransportTextureResult,
                                          TransportTextureSettings, fit_model, fit_viewport,
                                          load_bake,
                                          model_fidelity, model_summary, preview_cost,
                                          quantized, rel_rmse, relight, relight_environment,
                                          steerable_from_store, upsample as _upsample,
                                          viewport_direct, viewport_tables, write_bundle)

#: Directions per chunk of the direct stage: the unit a cancelled bake resumes from (16 hard-sun
#: bakes at 256^2 are about 2 s here; a chunk of 16 x 256^2 half floats is 2 MiB per object).
CHUNK_DIRECTIONS = 16

#: Cycles samples of the albedo (its colour pass): a texture finer than a texel is averaged over
#: the texel as a converged bake averages it, not read at its centre. A 2 m plane at 128^2
#: against its 256-spp colour bake (2026-12-07, bpy 5.0.1): a Checker of scale 40 / 150 (3.2 /
#: 0.85 texels a square) 0.176 / 0.389 at 1 spp, 0.025 / 0.061 at 16, 0.006 / 0.016 at 64; a
#: Brick texture's colour 0.142 / 0.018 / 0.004; a Noise of scale 60, detail 8 0.026 / 0.004 /
#: 0.001. 16 spp took 0.07-0.29 s there (the Noise the slowest), a 64-spp lit bake about 1 s.
ALBEDO_SAMPLES = 16


def check_space(n_objects: int, dset, settings: TransportTextureSettings, out_dir: str,
                resume: bool = True) -> int:
    """Refuse up front, with the figure, when T would not fit on disk -- twice, with the chunk
    cache of ``resume`` -- (and the fit's working set in memory). Returns the bytes needed."""
    P = settings.resolution ** 2
    need = n_objects * tt.transport_bytes(dset.size, P) * (2 if resume else 1)
    folder = out_dir
    while folder and not os.path.isdir(folder):
        folder = os.path.dirname(folder)
    free = shutil.disk_usage(folder or ".").free
    if need > 0.9 * free:
        raise BakeInputError(
            f"the transport textures need {need / 2**20:.0f} MiB on disk ({n_objects} object(s) "
            f"x {dset.size} directions x {settings.resolution}^2 texels, half floats"
            f"{', and as much again for the resumable chunks' if resume else ''}) but "
            f"{free / 2**20:.0f} MiB are free in {folder}; use fewer directions or a lower "
            "resolution" + (" (or --no-resume)" if resume else ""))
    # in memory: the largest stage's working set (lt_addon/transport/bake_memory.py)
    from .bake_cost import memory_bytes

    ram, stage = memory_bytes(settings, dset, n_objects)
    check_memory(ram, f"the bake of {n_objects} object(s) at {settings.resolution}^2 texels "
                      f"({stage} stage)", "use a lower resolution, fewer objects per bake, or "
                                          "fewer components")
    return need


def bake_transport_textures(scene, objects, settings: TransportTextureSettings, out_dir: str,
                            resume: bool = True, client=None, blend_path: str | None = None):
    """Generator: bake albedo, direct transport and indirect light of ``objects``; fit models.

    Writes the stores (temporary names until complete) into ``out_dir``; the models and
    reports are written by :func:`write_bake`. With ``resume``, the direct bakes' finished
    chunks of :data:`CHUNK_DIRECTIONS` directions are kept in ``<out_dir>/.relight_cache/`` and
    reused by a rerun of the same bake of the same scene (:func:`direct_chunk_cache`);
    :func:`write_bake` removes them. With a Dask ``client`` the missing chunks are baked on
    its workers from the saved ``blend_path`` first (:mod:`.distributed`); the result is the
    same bit for bit. Returns a TransportTextureResult, whose peak memory a thread sampled
    (:class:`...lt_addon.peak_memory.PeakMemory`; the report says it per stage).
    """
    mem = PeakMemory()
    try:
        return (yield from _bake_transport_textures(scene, objects, settings, out_dir, resume,
                                                    client, blend_path, mem))
    finally:
        mem.stop()


def scene_light_settings(scene, settings):
    """``(settings, from_scene)``: the settings with what they leave to the scene (-1) taken
    from it -- the bounces from its Light Paths (:func:`..base.scene_sun.scene_bounces`), the
    Sun size from its Sun (Blender's default 0.526 degrees; 2 without a Sun) -- and
    ``{field: value}`` of those taken, for the report."""
    from dataclasses import replace

    from ..base.scene_sun import DEFAULT_SUN_ANGLE, scene_bounces, scene_sun_angle

    taken = {}
    if settings.bounces is not None and settings.bounces < 0:
        taken["bounces"] = scene_bounces(scene)
    if settings.sun_angle is not None and settings.sun_angle < 0:
        angle = scene_sun_angle(scene)
        taken["sun_angle"] = round(angle, 4) if angle is not None else DEFAULT_SUN_ANGLE
    fields = dict(taken)
    if "sun_angle" in taken and scene_sun_angle(scene) is None:
        taken["no_sun"] = True
    return (replace(settings, **fields) if fields else settings), taken


def _bake_transport_textures(scene, objects, settings, out_dir, resume, client, blend_path, mem):
    """:func:`bake_transport_textures`, with ``mem`` started once the inputs are checked."""
    settings, from_scene = scene_light_settings(scene, settings)
    dset, path_info = resolve_directions(scene, settings)
    settings, raised = path_horizons(settings, path_info)
    if client is not None and (not resume or not blend_path):
        raise BakeInputError("a distributed bake needs the chunk cache (no --no-resume) and a "
                             "saved .blend the workers can open")
    objects = list(objects)
    for o in objects:
        check_bakeable(o)
    check_space(len(objects), dset, settings, out_dir, resume)
    t_start = time.perf_counter()
    mem.start()
    mem.stage("albedo")
    peak = mem.base
    R = settings.resolution
    S = dset.size
    do_indirect = settings.bounces > 0 and settings.indirect == "steerable"
    n_ind = (settings.indirect_order ** 2 if do_indirect else
             1 if settings.bounces > 0 and settings.indirect == "gather" else 0)
    total = 1 + S + n_ind + 1
    calls = 0
    seconds = {}

    # which engine bakes the direct term (rays where the scene allows, else Cycles calls)
    from . import ray_direct

    engine = ray_direct.choose(scene, objects, settings)
    engine["direction_set"] = {"size": dset.size, "spec": settings.directions,
                               "under_horizon": {
                                   "directions": int(dset.params.get("under_directions", 0)),
                                   "deg": dset.params.get("under_horizon_deg", 0.0)},
                               **(path_info if path_info and "study" in path_info else
                                  {"sun_path": path_info} if path_info else {})}
    rays = engine["engine"] == "rays"
    if raised and rays and ray_direct.horizon_count(settings):
        engine["horizons_raised"] = raised
    mapped = ray_direct.needs_normals(objects) if rays else [False] * len(objects)

    # 1. albedo (colour pass only, averaged over each texel), and the shading normals rays need
    # for normal maps
    normals = [None] * len(objects)
    with EnvironmentBake(scene, objects, R, ALBEDO_SAMPLES, 0, (8, 16), mode="irradiance",
                         seed=settings.seed, world_sampling="none", passes="color") as session:
        albedos = session.bake_all(np.zeros((8, 16), np.float32))
        seconds["albedo_cycles"] = session.bake_seconds
        calls += session.bake_calls
    if any(mapped):   # sampled over each texel (lt_addon/rays/normal_samples.py)
        normals, engine["shading_normals"] = ray_direct.sampled_normals(
            scene, objects, mapped, R, settings.seed)
        seconds["normals_cycles"] = engine["shading_normals"]["seconds"]
        calls += engine["shading_normals"]["bakes"]
    yield Progress(1, total, "albedo baked")
    mem.stage("direct")

    # 2. direct transport, streamed to disk in chunks of directions; each finished chunk is
    # also kept in the chunk cache, so a cancelled or killed bake run again redoes only the
    # chunks it is missing (the cache goes once the bake's files are written)
    os.makedirs(out_dir, exist_ok=True)
    # (rays put no chunks in the cache: a rerun casts them again in less time than reading them
    # back; the cache folder still holds the indirect stage's chunks)
    cache = direct_chunk_cache(scene, objects, settings, out_dir, dset) if resume else None
    stores = [tt.TransportStore.create(
        os.path.join(out_dir, f"{object_stem(o.name)}_transport_texture.npy"), dset, R,
        {"object": o.name, "kind": "direct_irradiance_over_pi", "samples": 1,
         "seed": settings.seed, "direct_engine": engine["engine"],
         "texel_sampling": (
             "each texel's footprint as a converged Cycles bake sees it: 16 rays over the "
             "texel where a shadow edge or a thin triangle passes, else its centre "
             "(lt_addon/rays/footprint.py); rays from Cycles' shading point and shadow-ray "
             "rules" if rays and settings.texel_sampling == "footprint" else
             "1 sample at the texel centre (Cycles' first bake sample)"
             + ("; rays from Cycles' shading point and shadow-ray rules" if rays else "")),
         "addon_version": __version__}) for o in objects]
    chunks = ([] if rays else
              [range(a, min(a + CHUNK_DIRECTIONS, S)) for a in range(0, S, CHUNK_DIRECTIONS)])
    # a kept chunk is checked: its checksum, finite, (objects, directions, texels) in half
    # floats, and irradiance / pi of a unit hard sun: within [0, 1]
    cached = [cache.get(f"direct_{c.start:05d}", (len(objects), len(c), R * R), np.float16,
                        0.0, 1.0) if cache else None for c in chunks]
    reused = sum(c is not None for c in cached)
    distributed = None
    if client is not None and reused < len(chunks):   # the workers fill the cache first
        from ..farm.distributed import fill_chunks

        try:
            distributed = yield from fill_chunks(
                client, blend_path, objects, settings, cache,
                [c for c, kept in zip(chunks, cached) if kept is None], 1, total, direct_stage)
        except BaseException:
            for store in stores:
                store.abort()
            raise
        seconds["distributed_wall"] = distributed["wall_seconds"]
        cached = [kept if kept is not None else cache.get(f"direct_{c.start:05d}")
                  for c, kept in zip(chunks, cached)]
    finished = False
    first = peak
    seconds["direct_cycles"] = 0.0
    horizon_maps = None
    try:
        if rays:
            engine.update((yield from ray_direct.bake(scene, objects, settings, dset, stores,
                                                      normals, 2, total)))
            horizon_maps = engine.pop("horizon_maps", None)
            checks = engine.pop("horizon_checks", None)
            if horizon_maps:    # a check's rays, or the trial that decided on sampled tiles
                horizon_maps = [(m, (checks["directions"], rows) if rows is not None else trial)
                                for m, rows, trial in zip(horizon_maps, checks["rows"],
                                                          checks["trials"])]
            seconds["direct_rays"] = engine["seconds"]
            seconds["horizons"] = engine.get("horizon_seconds", 0.0)
            faults.checkpoint("directions")
            peak = first = max(peak, mem.peak_mb)
        missing = any(c is None for c in cached)
        with (EnvironmentBake(scene, objects, R, 1, 0, (8, 16), mode="irradiance",
                              seed=settings.seed, world_sampling="none", passes="direct")
              if missing else contextlib.nullcontext()) as session:
            for chunk, kept in zip(chunks, cached):
                if kept is not None:     # (objects, directions in the chunk, texels), half
                    for s in chunk:
                        for store, row in zip(stores, kept[:, s - chunk.start]):
                            store.write(s, row)
                        yield Progress(2 + s, total, f"direction {s + 1}/{S} (reused)")
                    continue
                for s in chunk:
                    images = session.bake_sun_all(dset.directions[s], 1.0, 0.0)
                    for store, img in zip(stores, images):
                        store.write(s, img[..., 0])
                    peak = max(peak, mem.peak_mb)
                    if s == 0:
                        first = peak   # Cycles' own session memory is allocated by now
                    yield Progress(2 + s, total, f"direction {s + 1}/{S}")
                if cache:
                    cache.put(f"direct_{chunk.start:05d}",
                              np.stack([np.asarray(st._array[chunk.start:chunk.stop])
                                        for st in stores]))
                faults.checkpoint("directions")   # (tests: killed with a chunk kept)
            if session is not None:
                seconds["direct_cycles"] = session.bake_seconds
                calls += session.bake_calls
        readers = [store.finish() for store in stores]
        finished = True
    finally:
        if not finished:
            for store in stores:
                store.abort()
    seconds["direct_total"] = time.perf_counter() - t_start

    lights = None
    # (the gathered term falls back to the steerable lights when objects not baked reflect much
    # of the light: their chunks are kept as the steerable term's)
    if resume and settings.bounces > 0 and settings.indirect in ("steerable", "gather"):
        from .light_chunks import light_cache

        lights = light_cache(scene, objects, indirect_spec(settings),
                             os.path.join(cache.root, "indirect"))
    elif resume:   # no indirect stage now: an earlier bake's indirect chunks are stale
        import shutil

        shutil.rmtree(os.path.join(cache.root, "indirect"), ignore_errors=True)
    try:
        result = yield from _indirect_and_models(scene, objects, settings, dset, albedos,
                                                 readers, seconds, calls, t_start, mem, peak,
                                                 first, 2 + S, total, lights, client,
                                                 blend_path, horizon_maps)
    except BaseException:   # cancelled or failed after the directions: drop the stores too
        for r in readers:
            r.abort()
        raise
    result.direct = engine
    result.cache = [c for c in (lights, cache) if c is not None]   # cleared in this order
    ind = result.indirect_chunks or {}
    result.chunks = {"chunks_total": len(chunks) + ind.get("chunks_total", 0),
                     "chunks_reused": reused + ind.get("chunks_reused", 0),
                     "chunk_directions": CHUNK_DIRECTIONS,
                     "direct_chunks": len(chunks), "indirect_chunks": ind.get("chunks_total", 0),
                     # kept chunks refused on reuse (checksum, NaN) and baked again
                     "chunks_rejected": sum(c.rejected for c in result.cache)}
    other, mixed = {}, {}
    for c in result.cache:
        for dev, n in c.other_devices.items():
            other[dev] = other.get(dev, 0) + n
        for dev, n in c.mixed_devices.items():
            mixed[dev] = mixed.get(dev, 0) + n
    if other:   # a resume on another device: those chunks were baked again here
        result.chunks["other_device_chunks"] = other
    if mixed:   # ... or reused, because the user said so (--mix-devices)
        result.chunks["mixed_device_chunks"] = mixed
    if distributed is not None or "distributed" in ind:
        both = [d for d in (distributed, ind.get("distributed")) if d]
        result.chunks["distributed"] = {
            "chunks": sum(d["chunks"] for d in both),
            "wall_seconds": round(sum(d["wall_seconds"] for d in both), 3),
            "file_loads": sum(d["file_loads"] for d in both),
            "chunk_seconds": [x for d in both for x in d["chunk_seconds"]],
            "cycles_seconds": round(sum(d["cycles_seconds"] for d in both), 3),
            "workers": sorted({w for d in both for w in d["workers"]}),
            "worker_devices": {k: v for d in both for k, v in d.get("worker_devices", {}).items()},
            "cycles_threads_per_worker": both[0]["cycles_threads_per_worker"]}
    result.from_scene = from_scene
    return result


def resolve_directions(scene, settings):
    """The bake's direction set and where it came from: the settings' set, plus directions
    along the scene Sun's animated path (``sun_path`` auto and a Sun that moves, or a
    ``+sun-path[:STEP]`` spec, which requires one), plus the band just above the horizon
    mirrored under it, for a soft sun's disc there (:mod:`...lt_addon.sphere.under_horizon`:
    down to the bake Sun's radius, at least 5 degrees). Returns ``(DirectionSet, info or
    None)``."""
    from ...lt_addon.sphere.directions import MAX_DIRECTIONS
    from ...lt_addon.sphere.under_horizon import depth_for, with_under

    dset, info = _above_horizon(scene, settings)
    dset = with_under(dset, depth_for(settings.sun_angle, settings.under_horizon))
    if dset.size > MAX_DIRECTIONS:     # (what a bake folder's reader accepts)
        raise BakeInputError(f"the bake would have {dset.size} directions (the set's, a Sun's "
                             f"path and the band under the horizon); at most {MAX_DIRECTIONS}: "
                             "use fewer directions, a coarser path step or --under-horizon 0")
    return dset, info


def _above_horizon(scene, settings):
    """:func:`resolve_directions`' set above the horizon."""
    from ...lt_addon.sphere.sun_path import with_path
    from ...lt_addon.transport.bundle import split_sun_path
    from ..base.scene_sun import sun_path

    base = settings.validate()
    _, forced = split_sun_path(settings.directions)
    if settings.study:     # a sun study's hours and paths (lt_addon/sun/study_directions.py)
        from ...lt_addon.sun.study_directions import direction_set

        if forced is not None:
            raise BakeInputError("--study and +sun-path both add a Sun's path: give one (the "
                                 "study's place and dates, or the scene Sun's animation)")
        from ...lt_addon.sun.study_directions import parse, place_from_sun_position
        from ..base import sun_position

        place = None
        if parse(settings.study).from_scene:     # 'scene,...': the Sun Position add-on's place
            values = sun_position.read(scene)
            place = place_from_sun_position(values) if values is not None else None
        dset, info = direction_set(base, settings.study, settings.sun_path_step, place)
        moving = sun_path(scene) if settings.sun_path == "auto" else None
        if moving is not None:
            info["note"] = (f"the scene's Sun {moving['object']} is animated; its path was not "
                            "added (--study takes the study's)")
        return dset, {"study": info}
    if forced is None and settings.sun_path == "off":
        return base, None
    path = sun_path(scene)
    if path is None:
        if forced is not None:
            raise BakeInputError("--directions ...+sun-path: the scene has no Sun lamp that "
                                 "moves over its frame range (animate its rotation, or drop "
                                 "+sun-path)")
        return base, None
    step = forced if forced is not None else settings.sun_path_step
    dset = with_path(base, path["directions"], step)
    info = {"object": path["object"], "frames": path["frames"],
            "frames_sampled": path["samples"], "base": base.spec,
            "base_directions": dset.params["base_kept"],
            "path_directions": dset.params["sun_path_directions"],
            "step_deg": step, "elevation_deg": dset.params["sun_path_elevation_deg"],
            "why": "asked for (+sun-path)" if forced is not None else "the scene's Sun is animated"}
    return dset, info


def path_horizons(settings, path_info):
    """``(settings, note or None)``: with the scene Sun's path in the direction set
    (``path_info`` of :func:`resolve_directions`), the horizons at the texture's side and at
    least :data:`...lt_addon.transport.horizon_map.PATH_AZIMUTHS` azimuths, within the GPU
    budget (:func:`...lt_addon.transport.horizon_map.for_sun_path`): a low Sun on its path
    needs them finer than the presets' (the note says from what, to what and why)."""
    from dataclasses import replace

    from ...lt_addon.transport import horizon_map as hmap

    if not path_info:
        return settings, None
    R, A = settings.resolution, int(settings.horizon_azimuths)
    a, h = hmap.for_sun_path(R, A, settings.horizon_resolution,
                             int(settings.gpu_budget) << 20)
    before = (A, hmap.side(R, settings.horizon_resolution))
    if (a, hmap.side(R, h)) == before:
        return settings, None
    note = {"from": {"azimuths": before[0], "side": before[1]},
            "to": {"azimuths": a, "side": hmap.side(R, h)},
            "why": ("the study's Sun runs low at its dates' mornings and evenings: its path "
                    "needs horizons at the texture's side" if "study" in path_info else
                    "the scene's Sun is animated: a low Sun on its path needs horizons at the "
                    "texture's side (--sun-path off keeps the settings' horizons)")}
    return replace(settings, horizon_azimuths=a, horizon_resolution=h), note


def bake_directions(scene, objects, settings, start: int, stop: int, cache,
                    threads: int = 0) -> float:
    """Bake directions ``start:stop`` of ``settings``' direction set for ``objects`` exactly as
    the single-process bake does (1 spp hard suns, same seed) and put them into ``cache`` as the
    chunk ``direct_<start>`` ((objects, directions, texels), half floats); ``threads`` Cycles
    threads (0: all cores). Returns Cycles' seconds. Used by the Dask task and ``relight
    bake-chunk`` (farms)."""
    dset, _ = resolve_directions(scene, settings)
    if threads:   # workers sharing a machine: no more Cycles threads than their share of cores
        scene.render.threads_mode, scene.render.threads = "FIXED", int(threads)
    rows = [[] for _ in objects]
    with EnvironmentBake(scene, objects, settings.resolution, 1, 0, (8, 16), mode="irradiance",
                         seed=settings.seed, world_sampling="none", passes="direct") as session:
        for i in range(start, stop):
            for row, img in zip(rows, session.bake_sun_all(dset.directions[i], 1.0, 0.0)):
                row.append(np.asarray(img[..., 0], np.float32).reshape(-1).astype(np.float16))
        seconds = session.bake_seconds
    cache.put(f"direct_{start:05d}", np.stack([np.stack(r) for r in rows]))
    return seconds


def direct_stage(scene, objects, settings: dict, start: int, stop: int, cache, threads: int = 0,
                 part=None) -> float:
    """The texture bake's chunk function for :func:`..farm.distributed.fill_chunks`: directions
    ``start:stop`` of the TransportTextureSettings ``settings`` (sent as a dict) into ``cache``
    (:func:`bake_directions`); returns Cycles' seconds."""
    return bake_directions(scene, objects, TransportTextureSettings(**settings), start, stop,
                           cache, threads)


def indirect_spec(settings: TransportTextureSettings) -> dict:
    """The indirect stage's basis lights (:func:`.light_chunks.light_spec`): the paper's
    steerable basis of ``indirect_order`` on 64-row environments, the indirect pass only."""
    from .light_chunks import light_spec

    return light_spec(settings.indirect_order, 64, settings.indirect_resolution,
                      settings.indirect_samples, settings.bounces, "radiance", settings.seed,
                      "importance", passes="indirect")


def direct_chunk_cache(scene, objects, settings: TransportTextureSettings, out_dir: str,
                       dset=None):
    """The chunk cache of the direct stage of a bake of ``objects`` into ``out_dir``: keyed
    by the scene content the bake depends on (:func:`.bake_inputs.scene_key`) and the settings
    the direct bakes use, ``dset`` the resolved direction set (None: resolved here, which steps
    through the frames for an animated Sun); the folders of other keys (stale chunks) are
    removed."""
    from ...lt_addon.io.chunk_cache import ChunkCache, digest
    from ..base.bake_inputs import scene_key
    from ..base.cycles_device import current

    if dset is None:
        dset, _ = resolve_directions(scene, settings)
    key = {"stage": "direct", "scene": scene_key(scene, objects), "device": current().id,
           "directions": settings.directions, "resolution": settings.resolution,
           **({"direction_set": digest(dset.directions.round(9).tolist())}
              if dset.kind == "custom" else {}),
           "seed": settings.seed, "chunk_directions": CHUNK_DIRECTIONS}
    root = os.path.join(cache_root(out_dir), "+".join(object_stem(o.name) for o in objects))
    cache = ChunkCache(root, key)
    cache.prune_others(adopt_devices=current().mix_devices)   # --mix-devices
    return cache


def _indirect_and_models(scene, objects, settings, dset, albedos, readers, seconds, calls,
                         t_start, mem, peak, first, step, total, cache=None, client=None,
                         blend_path=None, horizon_maps=None):
    """Steps 3 and 4 of :func:`bake_transport_textures` (the stores are not committed yet).
    The indirect stage's basis lights are chunks (:mod:`.light_chunks`): from ``cache``, from
    ``client``'s workers, or baked here."""
    do_indirect = settings.bounces > 0 and settings.indirect == "steerable"
    indirects = [None] * len(objects)
    indirect_chunks = None
    fallback = None
    steer_total = total
    mem.stage("indirect")
    if settings.bounces > 0 and settings.indirect == "gather":
        # 3. indirect light gathered by rays over T's own directions (.indirect_gather); when
        # the objects not baked reflect much of it (a statue baked without its ground), Cycles'
        # steerable term instead: the gather reads T, which those objects do not have
        from . import indirect_gather

        t0 = time.perf_counter()
        got, figures = yield from indirect_gather.bake(
            scene, objects, [r.array for r in readers], albedos, dset,
            resolution=settings.indirect_resolution, bounces=settings.bounces,
            rays=settings.indirect_rays, components=settings.indirect_components,
            seed=settings.seed, step=step, total=total)
        seconds["indirect_rays"] = figures["seconds"]["rays"]
        if got is None:
            do_indirect, fallback = True, figures
            steer_total = step + settings.indirect_order ** 2    # its lights, then the models
        else:
            indirects = got
            seconds["indirect_pca"] = figures["seconds"]["pca"]
            yield Progress(step, total, "indirect light gathered")
            faults.checkpoint("indirect")
            seconds["indirect_total"] = time.perf_counter() - t0
        peak = max(peak, mem.peak_mb)
    # 3. indirect light: a low-order steerable bake of the indirect pass
    if do_indirect:
        from ...lt_addon.steerable.sampled_basis import build_sampled_basis
        from ...lt_addon.steerable.basis import paper_basis
        from ...lt_addon.steerable.texture import SteerableTexture
        from .light_chunks import light_stacks

        t0 = time.perf_counter()
        basis = paper_basis(settings.indirect_order)
        sampled = build_sampled_basis(basis)
        ri = settings.indirect_resolution
        stacks, indirect_chunks = yield from light_stacks(
            scene, objects, indirect_spec(settings), cache, client if cache else None,
            blend_path, step - 1, steer_total, "indirect bake")
        seconds["indirect_cycles"] = indirect_chunks["cycles_seconds"]
        calls += indirect_chunks["calls"]
        t0 -= sum(fallback["seconds"].values()) if fallback else 0.0   # the gather's check too
        from ...lt_addon.geometry.uv_layout import uv_coverage
        from ..base.meshes import uv_triangles

        for i, o in enumerate(objects):
            images = sampled.to_basis_images(stacks[i], dtype=np.float32)
            if settings.indirect_smoothing > 0:
                covered = uv_coverage(uv_triangles(o), ri) > 0
                images = tt.smooth_in_coverage(images, covered, settings.indirect_smoothing)
            indirects[i] = SteerableTexture(
                images, settings.indirect_order,
                basis.width, sampled.centres, frame="world", calibration="steerable_cos",
                settings={"resolution": ri, "samples": settings.indirect_samples,
                          "bounces": settings.bounces, "mode": "radiance", "passes": "indirect",
                          "smoothing_texels": settings.indirect_smoothing,
                          "object": o.name, "seed": settings.seed,
                          **({"why": fallback["why"], "gather_check": {
                              k: v for k, v in fallback.items() if k != "why"}}
                             if fallback else {})})
        seconds["indirect_total"] = time.perf_counter() - t0

    # 4. models (BLAS on --threads N when given, else as NumPy started it: every core)
    faults.checkpoint("fit")
    mem.stage("fit")
    results = []
    n_fit = cycles_device.current().threads if cycles_device.blas_policy() else 0
    for i, o in enumerate(objects):
        t0 = time.perf_counter()
        with blas_threads.limited(n_fit) if n_fit else contextlib.nullcontext():
            model = fit_model(readers[i], settings, albedos[i])
            hm, check = horizon_maps[i] if horizon_maps else (None, None)
            view, viewport = fit_viewport(readers[i], settings, model, horizon=hm,
                                          horizon_check=check)
        results.append(ObjectBake(o.name, readers[i].path, albedos[i], indirects[i], model,
                                  time.perf_counter() - t0, readers[i], view, viewport,
                                  horizon=hm if viewport.get("shows") == "horizon" else None,
                                  found_horizon=hm))
        peak = max(peak, mem.peak_mb)
    seconds["fit"] = sum(r.fit_seconds for r in results)
    seconds["fit_choose"] = sum((r.viewport or {}).get("choose_seconds", 0.0) for r in results)
    # the block viewport's fit and check, once chosen (made only where auto does not show the
    # horizons: the estimate counts it apart)
    seconds["fit_blocks"] = sum(max(0.0, (r.viewport or {}).get("fit_seconds", 0.0)
                                    - (r.viewport or {}).get("choose_seconds", 0.0))
                                for r in results)
    seconds["bake_total"] = time.perf_counter() - t_start
    yield Progress(steer_total, steer_total, "models fitted")
    mem.read()
    peak = max(peak, mem.peak_mb)
    out = TransportTextureResult(results, dset, settings, seconds, calls, peak - mem.base,
                                 peak - first)
    out.peak_by_stage_mb = mem.above_base()
    out.indirect_chunks = indirect_chunks
    return out


# ----------------------------------------------------------------------------------------------
# relighting (NumPy)


# ----------------------------------------------------------------------------------------------
# ground truth and the report


def truth_bakes(scene, objects, lights, sun_angle: float, bounces: int, samples: int,
                resolution: int, seed: int = 1):
    """Generator: Cycles radiance bakes of ``objects`` under Sun lamps (strength 1, angle
    ``sun_angle``) from ``lights`` [(az, el) degrees]; returns {light: [image per object]}."""
    out = {}
    t0 = time.perf_counter()
    with EnvironmentBake(scene, list(objects), resolution, samples, bounces, (8, 16),
                         mode="radiance", seed=seed, world_sampling="none") as session:
        for i, (az, el) in enumerate(lights):
            out[(az, el)] = session.bake_sun_all(direction_from_az_el(az, el), 1.0, sun_angle)
            yield Progress(i + 1, len(lights), f"truth {i + 1}/{len(lights)}")
    out["seconds"] = time.perf_counter() - t0
    return out


def truth_errors(result: TransportTextureResult, truths: dict, sun_angle: float,
                 lights=TRUTH_LIGHTS) -> dict:
    """Relative RMSE of the transport relight, of the model and of the viewport (when it
    relights from T through sparse tables) against the truths, per object and light, and one
    headline figure: ``sqrt(mean(rel^2))`` over lights of what the viewport shows. Compared at
    the truths' side (a bake's own truths have its side; the presets' bench scores a 128^2
    bake against 256^2 truths, bilinearly upsampled as a GPU sampler reads it)."""
    def err(img, truth):
        return rel_rmse(_upsample(img, truth.shape[0]), truth)

    rows = []
    for oi, b in enumerate(result.objects):
        store = b.store or tt.TransportStore.open(b.store_path)
        tables = (None if b.view is not None or b.horizon is not None else
                  viewport_tables(result.settings, store, sun_angle))
        for az, el in lights:
            truth = truths[(az, el)][oi]
            d = direction_from_az_el(az, el)
            row = {"object": b.name, "azimuth": az, "elevation": el,
                   "transport": err(relight(b, store, d, sun_angle, source="transport",
                                            kernel=result.settings.kernel), truth)}
            if b.model is not None:
                row["model"] = err(relight(b, store, d, sun_angle, source="model",
                                           kernel=result.settings.kernel), truth)
            ind = (None if b.indirect is None else _upsample(indirect_images(
                b.indirect, d, sun_angle, result.settings.kernel), store.resolution))
            view = None
            if b.horizon is not None:   # the horizon viewport
                view = b.horizon.direct(d, sun_angle)[..., None] * b.albedo
            elif b.view is not None:   # the block viewport
                idx, w = tt.sun_weights(store.directions, d, sun_angle, result.settings.kernel)
                view = b.view.relight_weights(idx, w)[..., None] * b.albedo
            elif tables is not None:   # the viewport relights from T through sparse tables
                view = viewport_direct(store, tables, d)[..., None] * b.albedo
            if view is not None:
                row["viewport"] = err(view if ind is None else view + ind, truth)
            if ind is not None:
                row["indirect_share"] = float(np.mean(ind) / max(np.mean(truth), 1e-12))
            rows.append(row)
    key = ("viewport" if all("viewport" in r for r in rows) else
           "model" if all("model" in r for r in rows) else "transport")
    head = float(np.sqrt(np.mean([r[key] ** 2 for r in rows])))
    return {"sun_angle": sun_angle, "lights": rows, "headline_rel_rmse": head,
            "headline_of": key,
            "transport_rel_rmse": float(np.sqrt(np.mean([r["transport"] ** 2 for r in rows]))),
            "meaning": "relative RMSE ||relit - Cycles||_F / ||Cycles||_F over texels and RGB "
                       "against Cycles Sun-lamp radiance bakes (with the bake's bounces) at "
                       "held-out lights; combined as sqrt(mean(rel^2)); 0.05 = 5 %"}


def retire_globs(objects) -> tuple:
    """Names of a previous texture bake's files in the output folder that a new bake of
    ``objects`` removes when it does not write them again (a preview of another viewport, an
    indirect term, a model kind, a camera comparison): they would belong to no bake."""
    out = []
    for o in objects:
        safe = object_stem(o.name)
        out += [f"{safe}_preview_{part}" for part in (
                    "eigen.exr", "tables.exr", "sparse_index.exr", "sparse_weights.exr",
                    "transport.png", "transport.json", "block_eigen.exr", "block_tables.exr")]
        out += [f"{safe}_indirect.exr", f"{safe}_indirect_atlas.exr", f"{safe}_indirect.npz",
                f"{safe}_preview_indirect_eigen.exr", f"{safe}_preview_indirect_tables.exr",
                f"{safe}_transport_model.npz", f"{safe}_transport_steerable.exr",
                f"{safe}_viewport_blocks.npz"]
    return tuple(out) + (f"{object_stem(objects[0].name)}_compare.png",)


def write_bake(result: TransportTextureResult, objects, out_dir: str, figures: dict | None = None,
               started: float | None = None) -> list:
    """Write the bundle of every object (:func:`..lt_addon.transport.bundle.write_bundle`) and
    record the bake on the object. Returns the reports, each naming the UV map baked into
    (``"uv_map"``; written to the file with the preview's figures by :func:`bake_job`)."""
    from ..base.blend_files import record_kind
    from ..base.meshes import bake_uv_name

    reports = write_bundle(result, [o.name for o in objects], out_dir, figures, started,
                           cycles_device.current().report(), __version__)
    s = result.settings
    for report, obj in zip(reports, objects):
        report["uv_map"] = bake_uv_name(obj)   # the map every stage baked into (the preview's)
        # what the settings left to the scene (-1): its Light Paths' bounces, its Sun's size
        report["from_scene"] = dict(getattr(result, "from_scene", None) or {})
        record_kind(obj, KIND, report["report"],
                    {"directions": result.directions.spec, "resolution": s.resolution,
                     "model": s.model, "bytes": report["bytes"]["total"],
                     "bake_seconds": round(result.seconds.get("bake_total", 0), 2)})
    for cache in result.cache or ():   # once the bake is committed the chunks have served
        after_commit(out_dir, cache.clear)
    return reports


# ----------------------------------------------------------------------------------------------
# presets, the pilot for --target-error, and the whole job


#: Direction counts the pilot tries for ``--target-error``, cheapest first.
PILOT_COUNTS = (64, 100, 200, 400, 800, 1600)
#: When no count meets the target, the pilot takes the fewest directions whose error is within
#: this factor of the best it tried: where more directions stop helping (the horizon viewport's
#: direct light does not depend on them: 0.0668-0.0676 over 64-1600 directions on the bumps
#: demo at 64^2), more cost time and bytes for nothing; T's own relight there went 0.080 / 0.086
#: at 800 / 1600 directions (the truths' noise).
PILOT_PLATEAU = 1.05


def truth_lights(count: int) -> list:
    """``count`` held-out (azimuth, elevation) lights: the four of :data:`TRUTH_LIGHTS` first,
    then elevations 5..85 degrees with golden-angle azimuths."""
    extra = [((17.0 + 137.508 * i) % 360.0, float(el))
             for i, el in enumerate((20.0, 45.0, 70.0, 5.0, 38.0, 63.0, 15.0, 85.0))]
    lights = list(TRUTH_LIGHTS) + extra
    if not 1 <= count <= len(lights):
        raise BakeInputError(f"--truth takes 1..{len(lights)} lights, got {count}")
    return lights[:count]


def settings_from_preset(name: str, **overrides) -> TransportTextureSettings:
    """A transport bake's settings: preset ``name`` (:data:`.presets.TRANSPORT`) with
    ``overrides``; a --tol or --components of one's own replaces the preset's count."""
    from .presets import TRANSPORT

    return TRANSPORT.settings(name, **overrides)


def pilot(scene, objects, settings: TransportTextureSettings, target: float, out_dir: str,
          resolution: int = 64, truth_samples: int = 256):
    """Generator: choose the fewest directions whose relight meets ``target`` (relative RMSE
    vs Cycles Sun truths with the bake's bounces at the four held-out lights, sun of
    ``settings.sun_angle``) on a small bake at ``resolution``; the model tolerance is then set
    to a third of the target so the fitted model adds little. The relight scored is what the
    bake's viewport will show: with a PCA model the pilot bakes as the bake does (its horizons
    found where the viewport may show them, the held-out check choosing per object) and scores
    the viewport, as the report's ``achieved``; else T's relight. Returns a dict of what was
    tried and chosen."""
    import tempfile

    from dataclasses import replace

    settings, _ = scene_light_settings(scene, settings)
    t0 = time.perf_counter()
    truths = yield from truth_bakes(scene, objects, TRUTH_LIGHTS, settings.sun_angle,
                                    settings.bounces, truth_samples, resolution)
    tried = []
    from ...lt_addon.transport.bundle import SUN_PATH_SUFFIX, split_sun_path

    # the counts over the settings' hemisphere power, keeping an asked +sun-path[:STEP]
    base, step = split_sun_path(settings.directions)
    power = base.split(":")[2] if base.count(":") == 2 else "1.5"
    path = "" if step is None else f"{SUN_PATH_SUFFIX}:{step:g}"
    viewport = settings.model == "pca"     # (the live preview: what the user will look at)
    chosen = None
    with tempfile.TemporaryDirectory(dir=out_dir if os.path.isdir(out_dir) else None) as tmp:
        for n in PILOT_COUNTS:
            s = replace(settings, directions=f"hemi:{n}:{power}{path}", resolution=resolution,
                        indirect_resolution=min(settings.indirect_resolution, resolution),
                        model="pca" if viewport else "none")
            res = yield from bake_transport_textures(scene, objects, s, tmp, resume=False)
            errs = truth_errors(res, truths, settings.sun_angle)
            err = errs["headline_rel_rmse" if viewport else "transport_rel_rmse"]
            tried.append({"directions": s.directions, "rel_rmse": err,
                          "bake_seconds": round(res.seconds["bake_total"], 2),
                          **({"shows": [(b.viewport or {}).get("shows") for b in res.objects]}
                             if viewport else {})})
            for b in res.objects:
                if b.store is not None:
                    b.store.abort()
            if err <= target:
                chosen = s.directions
                break
    met, why = chosen is not None, "the fewest directions that met the target"
    if not met:
        best = min(t["rel_rmse"] for t in tried)
        chosen = next(t["directions"] for t in tried if t["rel_rmse"] <= PILOT_PLATEAU * best)
        why = (f"no count met the target at the pilot's size: the fewest directions within "
               f"{round(100 * (PILOT_PLATEAU - 1))} % of the best error tried ({best:.3f}); more "
               f"bought nothing")
    out = {"target_error": target, "pilot_resolution": resolution, "tried": tried,
           "scored": "the viewport" if viewport else "the relight from T",
           "chosen_directions": chosen, "why": why,
           "met_in_pilot": met,
           "tol": round(target / 3.0, 5), "seconds": round(time.perf_counter() - t0, 2)}
    return out


@dataclass
class TextureBakeOutput:
    """What :func:`bake_job` produced: per object baked together, the JSON-safe report (as
    written to its ``report`` path) and the fitted model (TexturePCA, BlockPCA, steerable
    texture, or None for ``--model none``) -- objects, not report entries."""
    reports: list
    models: list


def _with_eta(gen, started: float, seconds: dict):
    """``gen``'s steps with the time left appended to each message: the estimate's stages
    ``seconds`` scaled by the bake's own pace (:func:`..lt_addon.transport.estimate.time_left`)."""
    from ...lt_addon.transport.estimate import readable_seconds, time_left

    left = None
    while True:
        try:
            step = next(gen)
        except StopIteration as stop:
            return stop.value
        left = time_left(seconds, step.message, time.perf_counter() - started, left)
        msg = step.message if step.message.startswith("warning:") else \
            f"{step.message} (about {readable_seconds(left)} of the bake left)"
        yield Progress(step.done, step.total, msg)


def bake_job(scene, objects, settings: TransportTextureSettings, out_dir: str, *,
             resolutions: dict | None = None, truth: int = 4, truth_samples: int = 256,
             preview: bool = True, compare: bool = True, **kw):
    """The whole ``bake-textures --method transport`` verb (:func:`bake_group`'s arguments)
    with a texture side per object: ``resolutions`` {object name: side} (0 or absent: the
    settings' resolution). Objects of one side are baked together as one group, the largest
    side first; every object of the scene casts shadows on every group. With several groups
    the camera comparison is rendered once, after all of them, and each report says the
    sides (``object_resolutions``). Returns a :class:`TextureBakeOutput` of all objects."""
    from dataclasses import replace

    from ...lt_addon.io.names import StemCollision, check_stems
    from ...lt_addon.transport import object_resolution as orr

    objects = list(objects)
    lit = scene_light_settings(scene, settings)[0]   # the scene's bounces and Sun size
    bounces = lit.bounces                             # (decides the groups' term)
    try:   # two objects whose files would be one (a hash collision, or case on macOS/Windows)
        check_stems([o.name for o in objects])
    except StemCollision as exc:
        raise BakeInputError(str(exc)) from None
    parts = orr.groups([o.name for o in objects], settings.resolution, resolutions)
    kw.update(truth=truth, truth_samples=truth_samples, preview=preview)
    if len(parts) == 1:
        return (yield from bake_group(scene, objects, replace(settings, resolution=parts[0][0]),
                                      out_dir, compare=compare, **kw))
    started = time.perf_counter()
    sides = {o.name: side for side, idx in parts for o in (objects[i] for i in idx)}
    reports, models = [], []
    why = None
    if bounces > 0 and settings.indirect == "gather":
        # the gathered light reads T of the objects baked together only: the bounce light
        # between groups (the statue's on a ground of its own side, and back) would be lost
        settings = replace(settings, indirect="steerable")
        why = ("objects baked at different texture sides: the gathered indirect light reads "
               "only T of the objects baked together, so each group takes Cycles' steerable "
               "term, which keeps the bounce light between the groups")
        yield Progress(0, 1, f"indirect light: steerable ({why})")
    for n, (side, idx) in enumerate(parts):
        group = [objects[i] for i in idx]
        yield Progress(0, 1, f"group {n + 1}/{len(parts)}: {', '.join(o.name for o in group)} "
                             f"at {side}^2")
        out = yield from bake_group(scene, group, replace(settings, resolution=side), out_dir,
                                    compare=False, **kw)
        reports += out.reports
        models += out.models
    if truth and preview and settings.model == "pca" and compare:
        # at the Sun size the groups' truths took (the scene's Sun's by default: -1 is no size)
        yield from _camera_comparison(scene, objects, replace(settings, sun_angle=lit.sun_angle),
                                      out_dir, reports, truth, truth_samples)
    wall = round(time.perf_counter() - started, 3)
    for rep in reports:   # each report: the sides of all groups, and the whole job's wall time
        rep["object_resolutions"] = sides
        rep["timings"]["wall_total"] = wall
        if why:
            rep["indirect"]["why"] = why
        rep["warnings"] = report_warnings(rep)
        atomic.write_json(rep["report"], {k: v for k, v in rep.items() if k != "report"},
                          default=float)
    return TextureBakeOutput(reports, models)


def bake_group(scene, objects, settings: TransportTextureSettings, out_dir: str, *,
               truth: int = 4, truth_samples: int = 256, target_error: float | None = None,
               preview: bool = True, compare: bool = True, resume: bool = True, client=None,
               blend_path: str | None = None, estimator=None):
    """Objects baked together at one texture side: the whole ``bake-textures --method
    transport`` verb as one generator: optional pilot (``target_error``), the bake, Cycles
    truths at held-out lights, files, preview and -- with ``truth``, a preview and ``compare``
    and a scene camera -- ``<object>_compare.png`` (the first object's name): the previews next
    to a Cycles Sun render from the camera at the lowest held-out light. With ``resume`` a rerun
    after a cancel or crash reuses the direct bakes' finished chunks (``chunks_reused`` in the
    reports); a Dask ``client`` bakes the missing ones on its workers from ``blend_path``.
    Returns a :class:`TextureBakeOutput` (the reports' ``timings.wall_total`` covers all of it)."""
    from dataclasses import replace

    started = time.perf_counter()
    figures = {}
    # what the settings leave to the scene (its Light Paths' bounces, its Sun's size), for
    # every stage from here: the pilot, the bake, its truths (the report's from_scene)
    settings, from_scene = scene_light_settings(scene, settings)
    if preview and settings.model == "pca":   # refuse an impossible viewport before baking
        from ...lt_addon.transport import sparse_tables as sp

        try:
            sp.choose_viewport(settings.viewport, settings.validate().size, settings.resolution,
                               budget_mib=settings.gpu_budget, table_size=settings.table_size)
        except ValueError as exc:
            raise BakeInputError(str(exc)) from None
        if settings.viewport == "horizon":
            from ...lt_addon.transport import horizon_map as hmap

            if settings.direct == "cycles" or settings.horizon_azimuths < 3:
                raise BakeInputError("--viewport horizon needs horizons found by rays: "
                                     "--direct auto or rays, and --horizon-azimuths 3 or more")
            mib = hmap.gpu_bytes(settings.horizon_azimuths, settings.resolution,
                                 settings.horizon_resolution) / 2**20
            if mib > settings.gpu_budget:
                side = hmap.side(settings.resolution, settings.horizon_resolution)
                raise BakeInputError(
                    f"the horizon viewport would take {mib:.0f} MiB of GPU memory at "
                    f"{settings.resolution}^2 with {settings.horizon_azimuths} azimuths at "
                    f"{side}^2 (over --gpu-budget {settings.gpu_budget}); use fewer azimuths, "
                    f"a smaller --horizon-resolution or raise the budget")
    if target_error is not None:
        if not 0.0 < target_error < 1.0:
            raise BakeInputError(f"--target-error must be in (0, 1), got {target_error}")
        chosen = yield from pilot(scene, objects, settings, target_error, out_dir,
                                  resolution=min(64, settings.resolution),
                                  truth_samples=truth_samples)
        settings = replace(settings, directions=chosen["chosen_directions"], tol=chosen["tol"])
        figures["target_error"] = chosen
        truth = max(truth, 4)
    bake = bake_transport_textures(scene, objects, settings, out_dir, resume, client, blend_path)
    if estimator is not None:   # (.estimate.estimate: the bake's cost, before it starts)
        e = yield from estimator(scene, objects, settings, truth, truth_samples)
        figures["estimate"] = {k: v for k, v in e.items() if k != "lines"}
        for line in e["lines"]:
            yield Progress(1, 1, line)
        bake = _with_eta(bake, time.perf_counter(), e["seconds"])
    result = yield from bake
    result.from_scene = from_scene or getattr(result, "from_scene", {})
    try:
        figures.update((yield from _truth_figures(scene, objects, settings, result, truth,
                                                  truth_samples, target_error, figures)))
    except BaseException:   # cancelled during the truths: the previous bake stays as it was
        for b in result.objects:
            if b.store is not None:
                b.store.abort()
        raise
    figures["glossy"] = glossy_note(objects)
    reports = write_bake(result, objects, out_dir, figures)
    from ..base.uv_layout import uv_layout

    for rep, obj in zip(reports, objects):   # texels two faces claim (overlaps, Mirror copies)
        rep["uv_layout"] = uv_layout(obj, settings.resolution)

    previewed = preview and settings.model == "pca"
    if previewed:
        for rep, b, obj in zip(reports, result.objects, objects):
            t_prev = time.perf_counter()
            store = tt.TransportStore.open(b.store_path)
            rep["preview"] = install_transport_preview(scene, obj, rep, b, store)
            faults.checkpoint("preview")
            rep["timings"]["preview_seconds"] = round(time.perf_counter() - t_prev, 3)
    if truth and previewed and compare:
        yield from _camera_comparison(scene, objects, settings, out_dir, reports, truth,
                                      truth_samples)
    wall = round(time.perf_counter() - started, 3)
    from ..base.visibility import baked_notes

    for rep, obj in zip(reports, objects):   # the wall time of everything the verb did, too
        rep["timings"]["wall_total"] = wall
        notes = baked_notes(obj)
        if notes:
            rep["notes"] = notes
        rep["warnings"] = report_warnings(rep)   # its caveats, as the CLI and panel say them
        if "estimate" in rep and not rep.get("chunks_reused"):   # how good the prediction was
            rep["estimate"]["measured_bake_seconds"] = rep["timings"].get("bake_total")
            rep["estimate"]["measured_over_estimated"] = round(
                rep["timings"].get("bake_total", 0.0) / max(rep["estimate"]["bake"], 1e-9), 3)
        atomic.write_json(rep["report"], {k: v for k, v in rep.items() if k != "report"},
                          default=float)
    for b in result.objects:   # no memory map of T stays open for the swap (Windows)
        if b.store is not None:
            b.store.close()
        b.store = None
    return TextureBakeOutput(reports, [b.model for b in result.objects])


def _camera_comparison(scene, objects, settings, out_dir: str, reports: list, truth: int,
                       truth_samples: int):
    """Generator: ``<first object>_compare.png`` -- the previews of ``objects`` next to a
    Cycles Sun render from the scene camera at the lowest held-out light -- and its figures in
    every report (``comparison``, ``timings.compare_seconds``)."""
    from ..preview.compare_render import report_comparison

    yield Progress(1, 1, "rendering the comparison from the scene camera")
    png = os.path.join(out_dir, f"{object_stem(objects[0].name)}_compare.png")
    cmp = report_comparison(scene, objects, truth_lights(truth), settings.sun_angle, png,
                            truth_samples)
    for rep in reports:
        rep["comparison"] = cmp
        rep["timings"]["compare_seconds"] = cmp.get("seconds", 0.0)


def _truth_figures(scene, objects, settings, result, truth, truth_samples, target_error,
                   figures):
    """Generator: the ground-truth block of the report (empty without ``truth``)."""
    out = {}
    if not truth:
        return out
    lights = truth_lights(truth)
    t0 = time.perf_counter()
    truths = yield from truth_bakes(scene, objects, lights, settings.sun_angle,
                                    settings.bounces, truth_samples, settings.resolution)
    errs = truth_errors(result, truths, settings.sun_angle, lights)
    errs["truth_samples"] = truth_samples
    errs["truth_seconds"] = round(time.perf_counter() - t0, 2)
    out["ground_truth"] = errs
    if target_error is not None:
        figures["target_error"]["achieved"] = errs["headline_rel_rmse"]
        figures["target_error"]["met"] = errs["headline_rel_rmse"] <= target_error
    return out


def install_transport_preview(scene, obj, report, bake, store, **kw):
    from ..preview.transport_preview import install_transport_preview as install

    return install(scene, obj, report, bake, store, **kw)


def glossy_note(objects) -> dict:
    """Which materials have a non-negligible specular part the diffuse bake leaves out."""
    found = []
    for o in objects:
        for slot in o.material_slots:
            mat = slot.material
            tree = getattr(mat, "node_tree", None)
            if tree is None:
                continue
            for node in tree.nodes:
                if node.bl_idname != "ShaderNodeBsdfPrincipled":
                    continue
                spec = node.inputs.get("Specular IOR Level") or node.inputs.get("Specular")
                rough = node.inputs.get("Roughness")
                metal = node.inputs.get("Metallic")
                s = spec.default_value if spec is not None and not spec.is_linked else 0.5
                r = rough.default_value if rough is not None and not rough.is_linked else 0.5
                m = metal.default_value if metal is not None and not metal.is_linked else 0.0
                if (s > 0.05 and r < 0.6) or m > 0.1:
                    found.append({"object": o.name, "material": mat.name,
                                  "specular": round(float(s), 3), "roughness": round(float(r), 3),
                                  "metallic": round(float(m), 3)})
            if any(n.bl_idname == "ShaderNodeBsdfGlossy" for n in tree.nodes):
                found.append({"object": o.name, "material": mat.name, "glossy_bsdf": True})
    return {"materials": found,
            "note": ("the bake is diffuse-only (Cycles DIFFUSE pass): these materials' "
                     "view-dependent reflection is not in the relit texture and the preview "
                     "shows them darker than a render") if found else "all diffuse"}
