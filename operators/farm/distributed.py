"""Bake a bake's chunks on a Dask cluster (``--workers N`` / ``--scheduler ADDRESS``): the
transport bakes' ranges of directions (texture and vertex), basis lights (the lobes bake and the
indirect stage, :mod:`..bakes.light_chunks`) and material terms (:mod:`..bakes.material_bake`).
Each bake hands :func:`fill_chunks` its own chunk function; nothing here imports a bake.

The coordinator (the CLI process, with the .blend open) knows the bake's chunks and which of
them the chunk cache (:mod:`..lt_addon.io.chunk_cache`) still misses. It submits one Dask task
per missing chunk; a worker process opens the .blend once (again only when the file changes),
checks that its scene has the coordinator's cache key -- so a worker never bakes a different
scene (an unsaved edit, another file at the same path) -- bakes the chunk's hard suns exactly
as the single-process bake does and writes it into the shared chunk cache. Then the ordinary
bake runs and finds every chunk there, so the distributed T is bit for bit the single-process
one (same seed, same Cycles calls per direction).

Failure behaviour: a worker process that dies is replaced and its chunk rerun elsewhere (Dask
gives up after 3 deaths of the same task with ``KilledWorker``); an exception in a chunk is
retried once and then reported with the chunk named; an unreachable scheduler is one clear
error before any work. Chunks finished before a failure stay in the cache for the next run.

Workers must have this package, bpy and Dask installed and reach the .blend and the output
folder at the same paths (shared storage); ``bpy`` holds one scene per process, so each worker
runs one thread. Dask is a development / CLI dependency (``requirements.txt``), not bundled in
the extension zip: the panel's *Run On* hands the bake to a ``relight`` that has it
(:mod:`.external_bake`).
"""

from __future__ import annotations

import os
import time

from ..base.jobs import Progress

#: One worker process's open file, so many chunks share one load: (path, mtime, size).
_OPENED: dict = {}


class DistributedError(RuntimeError):
    """A distributed bake could not finish (the message says what and which chunk)."""


def connect(workers: int | None = None, scheduler: str | None = None, timeout: float = 10.0):
    """A Dask client: a new local cluster of ``workers`` processes (one thread each), or the
    scheduler at ``scheduler``. Raises DistributedError with one clear line when Dask is
    missing or the scheduler cannot be reached. The caller closes it (``close(client)``).

    ``scheduler`` must be an address the user gave (the CLI's ``--scheduler``, or the Dask
    Scheduler of the add-on's preferences), never one read from a .blend or a bake folder: the
    client unpickles what the scheduler sends, so a scheduler can run code here."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise DistributedError("--workers / --scheduler need Dask: pip install "
                               "'dask[distributed]' in the environment that runs relight") from None
    if scheduler:
        try:
            return Client(scheduler, timeout=timeout, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise DistributedError(f"cannot reach the Dask scheduler at {scheduler} "
                                   f"({type(exc).__name__}: {exc})") from None
    if workers is None or workers < 1:
        raise DistributedError(f"--workers must be >= 1, got {workers}")
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=40)
    client = Client(cluster, set_as_default=False)
    client._relight_cluster = cluster   # closed with the client
    return client


def local_threads(client) -> int:
    """Cycles threads per worker: on a local cluster the machine's cores shared out (at least
    1), so N workers do not each start a thread per core; 0 (all cores) on a remote cluster,
    whose machines this process cannot see."""
    cluster = getattr(client, "_relight_cluster", None)
    if cluster is None:
        return 0
    return max(1, (os.cpu_count() or 1) // max(1, len(cluster.workers)))


def close(client) -> None:
    cluster = getattr(client, "_relight_cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()


def _import_bpy():
    """``bpy`` in a worker process. A spawned worker inherits the coordinator's ``sys.path``,
    which after the coordinator imported bpy lists Blender's ``scripts/modules`` (holding
    Blender's own ``bpy`` package) before site-packages: those entries go until the wheel's
    ``bpy`` has loaded, which puts them back."""
    import sys

    if "bpy" not in sys.modules:
        marks = (os.sep + "scripts" + os.sep, os.sep + "addons_core")
        sys.path[:] = [p for p in sys.path if not any(m in p for m in marks)]
    import bpy

    return bpy


def _open_in_worker(blend_path: str, object_names: list):
    """The worker's scene and objects (the file opened only when not already open)."""
    bpy = _import_bpy()

    st = os.stat(blend_path)
    stamp = (blend_path, st.st_mtime_ns, st.st_size)
    if _OPENED.get("stamp") != stamp:
        from ..base.blend_files import blender_log_to_stderr

        with blender_log_to_stderr():
            bpy.ops.wm.open_mainfile(filepath=blend_path, load_ui=False)
        _OPENED["stamp"] = stamp
        _OPENED["loads"] = _OPENED.get("loads", 0) + 1
    objects = [bpy.data.objects[name] for name in object_names]
    from ..base.blend_files import activate_scene_of

    activate_scene_of(objects[0], blend_path)
    return bpy.context.scene, objects


def _worker_scene(blend_path: str, object_names: list, cache_key: dict):
    """The worker's scene and objects, checked against the coordinator's ``cache_key``."""
    _import_bpy()
    from ...lt_addon.io.chunk_cache import digest
    from ..base.bake_inputs import scene_key

    scene, objects = _open_in_worker(blend_path, object_names)
    if digest(scene_key(scene, objects)) != digest(cache_key["scene"]):
        raise DistributedError(f"the worker's {blend_path} is not the scene being baked (an "
                               "unsaved change, or another file at that path): save the .blend "
                               "where the workers read it")
    return scene, objects


def worker_device(cache_key: dict):
    """The device a worker bakes a chunk of ``cache_key`` on: the one the coordinator resolved
    for the bake (the key's ``device``: chunks of one bake come from one device, as their sample
    sets differ); a worker that cannot use it raises DistributedError in one line."""
    import socket

    from ..base import cycles_device

    want = cache_key.get("device", "CPU")
    if want == "CPU":
        return cycles_device.resolve("cpu")
    try:
        got = cycles_device.resolve("gpu")
    except cycles_device.DeviceError:
        got = None
    if got is None or got.id != want:
        raise DistributedError(f"the worker on {socket.gethostname()} cannot bake on {want} "
                               f"(it has {got.id if got else 'no GPU'}); run every worker on "
                               "that device, or bake with --device cpu")
    return got


def bake_chunk(blend_path: str, object_names: list, settings: dict, start: int, stop: int,
               cache_root: str, cache_key: dict, threads: int = 0, stage: str = "",
               part: tuple | None = None) -> dict:
    """Worker task: bake directions ``start:stop`` into the chunk cache with ``threads`` Cycles
    threads (0: Cycles' own choice, all cores); returns the chunk's figures. ``stage`` is the
    bake's own chunk function, ``stage(scene, objects, settings, start, stop, cache, threads,
    part) -> Cycles seconds`` with ``settings`` as the coordinator sent them (a dict) -- the
    texture bake's :func:`..bakes.texture_transport.direct_chunk`, the vertex bake's, the basis
    lights' or the material terms' (``part`` a material chunk's ``(kind, last, before)``), sent
    as its name ``"module:function"`` (:func:`stage_name`) and imported here once the worker has
    opened the file (a bake module imports bpy, which Dask must not do while it unpickles the
    task), so this module never imports a bake. Raises DistributedError when the worker's
    scene does not have ``cache_key``."""
    t0 = time.perf_counter()
    loads = _OPENED.get("loads", 0)
    scene, objects = _worker_scene(blend_path, object_names, cache_key)
    opened = time.perf_counter() - t0
    from ...lt_addon.io.chunk_cache import ChunkCache
    from ..base import cycles_device

    device = worker_device(cache_key)
    cache = ChunkCache(cache_root, cache_key)
    run_stage = _resolve(stage)
    with cycles_device.use(device):
        cycles = run_stage(scene, objects, settings, start, stop, cache, threads, part)
    return {"start": start, "pid": os.getpid(), "open_seconds": round(opened, 3),
            "opened_file": _OPENED.get("loads", 0) > loads, "cycles_seconds": round(cycles, 3),
            "seconds": round(time.perf_counter() - t0, 3), "device": device.describe()}


def _label(chunk) -> str:
    """A chunk's name: a material chunk's own, or the first direction of a range."""
    return getattr(chunk, "name", f"{chunk.start:05d}")


def stage_name(stage) -> str:
    """A chunk function as the name a worker imports it by (``"module:function"``)."""
    return f"{stage.__module__}:{stage.__qualname__}"


#: the only modules whose chunk functions a worker imports by name (this package's bakes)
_STAGE_MODULES = __name__.rsplit(".operators.farm.", 1)[0] + ".operators.bakes."


def _resolve(stage: str):
    """The chunk function a worker runs, imported by its name (:func:`stage_name`): a
    function of this package's ``operators.bakes`` modules, nothing else (a task names a
    module to import; the cluster is trusted, but a name costs nothing to check)."""
    import importlib

    module, _, name = str(stage).partition(":")
    if not module.startswith(_STAGE_MODULES) or not name.isidentifier():
        raise ValueError(f"not a chunk function of this package's bakes: {stage!r:.120}")
    return getattr(importlib.import_module(module), name)


def fill_chunks(client, blend_path: str, objects, settings, cache, chunks, step0: int,
                total: int, stage):
    """Generator (a job step source): bake the ``chunks`` (ranges of directions) the cache is
    missing on ``client``'s workers (``settings`` and ``stage`` as :func:`bake_chunk` takes
    them; a dataclass is sent as a dict); yields Progress as chunks finish; returns the figures
    (per-chunk seconds, file loads, wall time). Closing it cancels the outstanding tasks."""
    import dataclasses

    from distributed import as_completed

    t0 = time.perf_counter()
    names = [o.name for o in objects]
    threads = local_threads(client)
    if dataclasses.is_dataclass(settings):
        settings = dataclasses.asdict(settings)
    futures = {client.submit(bake_chunk, blend_path, names, settings, c.start, c.stop,
                             cache.root, cache.key, threads, stage_name(stage),
                             getattr(c, "part", None),
                             retries=1, pure=False,
                             key=f"relight-{stage.__name__}-{cache.digest[:12]}-{_label(c)}"): c
               for c in chunks}
    done, rows = 0, []
    try:
        for fut in as_completed(list(futures), loop=client.loop):
            c = futures[fut]
            try:
                rows.append(fut.result())
            except Exception as exc:   # KilledWorker after 3 deaths, or the chunk's own error
                raise DistributedError(f"chunk {_label(c)} (directions {c.start}-"
                                       f"{c.stop - 1}) failed: {type(exc).__name__}: "
                                       f"{exc}") from None
            done += len(c)
            yield Progress(step0 + done, total, f"chunk {_label(c)} baked by worker "
                                                f"{rows[-1]['pid']}")
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
    return {"chunks": len(rows), "wall_seconds": round(time.perf_counter() - t0, 3),
            "file_loads": sum(r["opened_file"] for r in rows),
            "chunk_seconds": [r["seconds"] for r in rows],
            "cycles_seconds": round(sum(r["cycles_seconds"] for r in rows), 3),
            "workers": sorted({r["pid"] for r in rows}), "cycles_threads_per_worker": threads,
            "worker_devices": {str(pid): dev for pid, dev in
                               sorted({(r["pid"], r.get("device", "CPU")) for r in rows})}}
