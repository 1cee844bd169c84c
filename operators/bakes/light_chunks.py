"""Bakes under the K lights of a sampled steerable basis, one chunk per light (bpy).

Both the lobes method (``bake-textures --method lobes``: K = order^2 basis lights, the whole
bake) and the transport method's indirect stage (order 3: 9 lights of the indirect pass) bake
one Cycles environment bake per basis light. Each light's images is a chunk: kept in a chunk
cache (:mod:`..lt_addon.io.chunk_cache`) so a cancelled bake resumes, and bakeable on Dask
workers (:mod:`.distributed`, stage "lights") bit for bit as here: same seed, same environment
image, same Cycles call.

A light set is described by a JSON-able ``spec`` (:func:`light_spec`), which is also what the
chunks' key holds besides the scene.
"""

from __future__ import annotations

import time

import numpy as np

from ...lt_addon import faults
from ..base.jobs import Progress, run


def light_spec(order: int, env_height: int, resolution: int, samples: int, bounces: int,
               mode: str, seed: int, world_sampling: str, passes: str | None = None) -> dict:
    """What a basis-light bake depends on besides the scene: the basis ``order`` (K =
    order^2 lights) and ``env_height`` of its equirect images, and the EnvironmentBake
    arguments (texture side ``resolution``, ``samples``, ``bounces``, ``mode``, ``seed``,
    ``world_sampling``, ``passes``: None for Cycles' default diffuse passes)."""
    return {"order": int(order), "env_height": int(env_height),
            "resolution": int(resolution), "samples": int(samples), "bounces": int(bounces),
            "mode": mode, "seed": int(seed), "world_sampling": world_sampling,
            "passes": passes}


def _sampled(order: int):
    from ...lt_addon.steerable.basis import paper_basis
    from ...lt_addon.steerable.sampled_basis import build_sampled_basis

    return build_sampled_basis(paper_basis(order))


def chunk_name(k: int) -> str:
    return f"light_{k:05d}"


def lights_stage(scene, objects, spec: dict, start: int, stop: int, cache, threads: int = 0,
                 part=None) -> float:
    """The basis lights' chunk function for :func:`..farm.distributed.fill_chunks`: lights
    ``start:stop`` of ``spec`` (:func:`light_spec`) into ``cache``; returns Cycles' seconds."""
    return run(bake_lights(scene, objects, spec, range(start, stop), cache.put, threads))[0]


def bake_lights(scene, objects, spec: dict, lights, put, threads: int = 0):
    """Generator: bake basis lights ``lights`` (indices) of ``spec`` for ``objects``, handing
    each light's images, shape (objects, R, R, 3) float32, to ``put(name, array)``; yields
    the light index after each Cycles call; returns ``(Cycles seconds, calls)``. ``threads``:
    Cycles threads (0: all cores)."""
    from ..base.cycles_bake import EnvironmentBake

    sampled = _sampled(spec["order"])
    h = spec["env_height"]
    if threads:   # workers sharing a machine: no more Cycles threads than their share of cores
        scene.render.threads_mode, scene.render.threads = "FIXED", int(threads)
    kw = {"passes": spec["passes"]} if spec.get("passes") else {}
    with EnvironmentBake(scene, list(objects), spec["resolution"], spec["samples"],
                         spec["bounces"], (h, 2 * h), mode=spec["mode"], seed=spec["seed"],
                         world_sampling=spec["world_sampling"], **kw) as session:
        for k in lights:
            env = sampled.light_environment(k, h, 2 * h, row_order="bottom_first")
            put(chunk_name(k), np.stack(session.bake_all(env)).astype(np.float32, copy=False))
            yield k
        return session.bake_seconds, session.bake_calls


def light_cache(scene, objects, spec: dict, root: str):
    """The chunk cache of ``spec``'s lights for ``objects`` under ``root``, keyed by the scene
    content (:func:`.bake_inputs.scene_key`) and ``spec``; stale keys there are removed."""
    from ...lt_addon.io.chunk_cache import ChunkCache
    from ..base.bake_inputs import scene_key
    from ..base.cycles_device import current

    cache = ChunkCache(root, {"stage": "lights", "scene": scene_key(scene, list(objects)),
                              "device": current().id, "spec": spec})
    cache.prune_others(adopt_devices=current().mix_devices)   # --mix-devices
    return cache


def light_stacks(scene, objects, spec: dict, cache=None, client=None,
                 blend_path: str | None = None, step0: int = 0, total: int | None = None,
                 label: str = "light"):
    """Generator (a job's steps ``step0 + 1 ..``): the images of every light of ``spec``, one
    array (K, R, R, 3) float32 per object, from ``cache`` where it has them, else from
    ``client``'s workers (saved ``blend_path``), else baked here. Returns ``(stacks,
    figures)``: figures has ``chunks_total``, ``chunks_reused``, ``cycles_seconds``,
    ``calls`` and, when workers baked, ``distributed``."""
    K = spec["order"] ** 2
    total = total if total is not None else step0 + K
    R = spec["resolution"]
    have = {}
    for k in range(K) if cache is not None else ():
        arr = cache.get(chunk_name(k), (len(objects), R, R, 3))   # checked; a bad one: rebaked
        if arr is not None:
            have[k] = arr
    reused = len(have)
    done = step0 + reused
    if reused:
        yield Progress(done, total, f"{reused} of {K} {label}s kept by an earlier bake")
    figures = {"chunks_total": K, "chunks_reused": reused, "cycles_seconds": 0.0, "calls": 0}
    if client is not None and reused < K:
        from ..farm.distributed import fill_chunks

        todo = [range(k, k + 1) for k in range(K) if k not in have]
        figures["distributed"] = yield from fill_chunks(client, blend_path, objects, spec,
                                                        cache, todo, done, total,
                                                        lights_stage)
        for c in todo:
            arr = cache.get(chunk_name(c.start), (len(objects), R, R, 3))
            if arr is not None:
                have[c.start] = arr
                done += 1
    todo = [k for k in range(K) if k not in have]
    if todo:
        def put(name, arr):
            have[int(name.rsplit("_", 1)[1])] = arr
            if cache is not None:
                cache.put(name, arr)

        gen = bake_lights(scene, objects, spec, todo, put)
        t0 = time.perf_counter()
        while True:
            try:
                k = next(gen)
            except StopIteration as stop:
                figures["cycles_seconds"], figures["calls"] = stop.value
                break
            done += 1
            yield Progress(done, total, f"{label} {k + 1}/{K}")
            faults.checkpoint("indirect")
        figures["bake_seconds"] = time.perf_counter() - t0
    stacks = [np.stack([have[k][i] for k in range(K)]) for i in range(len(objects))]
    return stacks, figures
