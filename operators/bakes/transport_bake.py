"""Per-vertex light transport baked with Cycles (bpy), Nowrouzezahrai et al. 2008.

``T[v, s]`` is the response of vertex ``v`` to a distant light of unit normal irradiance from
sample direction ``s``: ``V(x, w_s) max(0, n . w_s)`` with ``bounces = 0`` (visibility times
cosine), plus the interreflected light with ``bounces > 0``. One Cycles vertex bake per
direction under a hard Sun lamp (angle 0, strength 1): direct light from a hard Sun is
noise-free at 1 sample (one shadow ray), so ``bounces = 0`` needs 1 sample; interreflection is
Monte Carlo and needs more. Not used: packing three directions into one bake as red, green and
blue suns -- Cycles picks one light per path, so the channels get noisy (DESIGN.md sec. 4).

The DIFFUSE bake without the colour pass gives ``E / pi`` (irradiance over pi) per vertex with
smooth shading; we store ``T = pi * value``, so ``E = sum_s L_s T[:, s] dw_s`` and the shading of
an albedo-``rho`` diffuse surface is ``rho / pi * E``.

Like the texture bake this is a generator yielding progress and returning the result, so the
operator, CLI and tests drive the same code, and stopping it restores the scene.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

import numpy as np

from ...lt_addon.io.transaction import after_commit
from ...lt_addon.io.versions import REPORT_VERSION
from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem
from ...lt_addon.caveats import report_warnings
from ...lt_addon.settings import check_ranges, setting
from ..base import cycles_device
from ..base.cycles_bake import BakeInputError, EnvironmentBake, check_bakeable, check_memory
from ..base.jobs import Progress


#: Directions per chunk: the unit a cancelled bake resumes from and a Dask worker bakes.
CHUNK_DIRECTIONS = 16


@dataclass
class TransportBakeResult:
    transport: np.ndarray  # (V, S) float32
    directions: np.ndarray  # (S, 3) float64, world frame
    cycles_seconds: float
    total_seconds: float
    bake_calls: int
    chunks: dict = None     # chunks_total, chunks_reused (, distributed) with a chunk cache
    direct: dict = None     # how T was made: engine, why (, library, vs_cycles) -- rays or Cycles


def _default_samples(samples, bounces: int) -> int:
    return samples if samples is not None else (1 if bounces == 0 else 64)


def bake_vertex_directions(scene, obj, spec: dict, start: int, stop: int, cache,
                           threads: int = 0) -> float:
    """Bake directions ``start:stop`` of ``spec`` (``directions`` (S, 3), ``bounces``,
    ``samples``, ``seed``) for ``obj``'s vertices exactly as :func:`bake_transport` does, into
    ``cache`` as the chunk ``vertex_<start>`` ((V, n) float32); returns Cycles' seconds. The
    Dask task of a distributed bake (:mod:`.distributed`)."""
    dirs = np.asarray(spec["directions"], dtype=np.float64)
    if threads:
        scene.render.threads_mode, scene.render.threads = "FIXED", int(threads)
    out = np.empty((len(obj.data.vertices), stop - start), dtype=np.float32)
    with EnvironmentBake(scene, obj, None, _default_samples(spec["samples"], spec["bounces"]),
                         spec["bounces"], (8, 16), mode="irradiance", seed=spec["seed"],
                         world_sampling="none") as session:
        for j, s in enumerate(range(start, stop)):
            out[:, j] = np.pi * session.bake_sun(dirs[s], 1.0, 0.0)[:, 0]
        seconds = session.bake_seconds
    cache.put(f"vertex_{start:05d}", out)
    return seconds


def vertex_stage(scene, objects, spec: dict, start: int, stop: int, cache, threads: int = 0,
                 part=None) -> float:
    """The per-vertex bake's chunk function for :func:`..farm.distributed.fill_chunks`:
    directions ``start:stop`` of ``spec`` (``directions`` (S, 3), ``bounces``, ``samples``,
    ``seed``) for ``objects[0]`` into ``cache`` (:func:`bake_vertex_directions`)."""
    return bake_vertex_directions(scene, objects[0], spec, start, stop, cache, threads)


def vertex_chunk_cache(scene, obj, directions, bounces: int, samples, seed: int,
                       out_dir: str):
    """The chunk cache of a per-vertex bake of ``obj`` into ``out_dir``, keyed by the scene
    content (:func:`.bake_inputs.scene_key`), the directions' bytes, bounces, samples and
    seed; stale keys are removed."""
    import hashlib
    import os

    from ...lt_addon.io.chunk_cache import ChunkCache
    from ..base.bake_inputs import cache_root, scene_key
    from ..base.cycles_device import current

    dirs = np.ascontiguousarray(directions, dtype=np.float64)
    key = {"stage": "vertex", "scene": scene_key(scene, [obj]), "device": current().id,
           "directions": hashlib.sha256(dirs.tobytes()).hexdigest(), "count": len(dirs),
           "bounces": int(bounces), "samples": _default_samples(samples, bounces),
           "seed": int(seed), "chunk_directions": CHUNK_DIRECTIONS}
    safe = object_stem(obj.name)
    cache = ChunkCache(os.path.join(cache_root(out_dir), safe + "_vertex"), key)
    cache.prune_others(adopt_devices=current().mix_devices)   # --mix-devices
    return cache


def bake_transport(scene, obj, directions, bounces: int = 0, samples: int | None = None,
                   seed: int = 0, cache=None, client=None, blend_path: str | None = None,
                   direct: str = "cycles"):
    """Generator: bake ``T`` of ``obj`` for every direction; returns a TransportBakeResult.

    Without bounces ``T`` is visibility x cosine, which shadow rays give exactly: ``direct``
    "auto" or "rays" (:func:`..base.direct_rays.bake_rays`) casts a ray per vertex corner and
    direction through the ray engine and Cycles bakes only :data:`..base.direct_rays.
    DIRECT_CHECKS` of the directions, the report's check (``direct.vs_cycles``); "cycles", or
    bounces, bakes every direction with Cycles.

    With a chunk ``cache`` (:func:`vertex_chunk_cache`) every finished chunk of
    :data:`CHUNK_DIRECTIONS` directions is kept and a rerun reuses it (bit for bit); with a Dask
    ``client`` too, the missing chunks are baked on its workers from the saved ``blend_path``.

    Parameters
    ----------
    directions : ndarray, shape (S, 3)
        Unit vectors towards the light, world frame (z up).
    bounces : int
        Diffuse bounces; 0 = visibility x cosine only.
    samples : int, optional
        Cycles samples per vertex; default 1 without bounces (exact), 64 with bounces.

    Yields
    ------
    Progress after every direction.
    """
    check_bakeable(obj, need_uv=False)
    dirs = np.asarray(directions, dtype=np.float64)
    if dirs.ndim != 2 or dirs.shape[1] != 3 or len(dirs) == 0:
        raise BakeInputError(f"directions must have shape (S, 3), got {dirs.shape}")
    if not np.all(np.isfinite(dirs)):
        raise BakeInputError("directions contain NaN or inf")
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    samples = _default_samples(samples, bounces)
    n_vertices = len(obj.data.vertices)
    if client is not None and (cache is None or not blend_path):
        raise BakeInputError("a distributed bake needs the chunk cache and a saved .blend the "
                             "workers can open")
    # T (float32) plus the float64 copy the fit makes
    check_memory(n_vertices * len(dirs) * 12, f"{n_vertices} vertices x {len(dirs)} directions",
                 "use fewer directions")
    start = time.perf_counter()
    S = len(dirs)
    T = np.empty((n_vertices, S), dtype=np.float32)
    if bounces == 0 and direct != "cycles":
        from ..base.direct_rays import bake_rays

        choice, rays = bake_rays(scene, [(obj.name, n_vertices)], "POINT", direct,
                                 instances=True)
        if rays is not None:
            if client is not None:   # nothing is left to share out: say so, do not ignore it
                choice["workers_unused"] = (
                    "the Dask workers were not used: shadow rays baked every direction in this "
                    "process (use --direct cycles to bake the directions on the workers)")
            return (yield from _bake_by_rays(scene, obj, dirs, rays, choice, T, seed, start))
    elif direct == "rays":
        raise BakeInputError("--direct rays bakes visibility x cosine only: with --bounces the "
                             "indirect light needs Cycles (use --direct auto or cycles)")
    chunks = [range(a, min(a + CHUNK_DIRECTIONS, S)) for a in range(0, S, CHUNK_DIRECTIONS)]
    kept = [cache.get(f"vertex_{c.start:05d}") if cache else None for c in chunks]
    kept = [k if k is None or k.shape == (n_vertices, len(c)) else None
            for k, c in zip(kept, chunks)]
    reused = sum(k is not None for k in kept)
    distributed = None
    if client is not None and reused < len(chunks):
        from ..farm.distributed import fill_chunks

        distributed = yield from fill_chunks(
            client, blend_path, [obj], {"directions": dirs.tolist(), "bounces": bounces,
                                        "samples": samples, "seed": seed},
            cache, [c for c, k in zip(chunks, kept) if k is None], 0, S, vertex_stage)
        kept = [k if k is not None else cache.get(f"vertex_{c.start:05d}")
                for c, k in zip(chunks, kept)]
    cycles, calls = 0.0, 0
    missing = any(k is None for k in kept)
    with (EnvironmentBake(scene, obj, None, samples, bounces, (8, 16), mode="irradiance",
                          seed=seed, world_sampling="none")
          if missing else contextlib.nullcontext()) as session:
        for chunk, k in zip(chunks, kept):
            if k is not None:
                T[:, chunk.start:chunk.stop] = k
                yield Progress(chunk.stop, S, f"directions {chunk.start + 1}-{chunk.stop}/{S} "
                                              "(reused)")
                continue
            for s in chunk:
                T[:, s] = np.pi * session.bake_sun(dirs[s], 1.0, 0.0)[:, 0]
                yield Progress(s + 1, S, f"direction {s + 1}/{S}")
            if cache is not None:
                cache.put(f"vertex_{chunk.start:05d}", T[:, chunk.start:chunk.stop])
        if session is not None:
            cycles, calls = session.bake_seconds, session.bake_calls
    figures = None
    if cache is not None:
        figures = {"chunks_total": len(chunks), "chunks_reused": reused,
                   "chunk_directions": CHUNK_DIRECTIONS, "chunks_rejected": cache.rejected,
                   **({"other_device_chunks": cache.other_devices} if cache.other_devices
                      else {}),
                   **({"mixed_device_chunks": cache.mixed_devices} if cache.mixed_devices
                      else {})}
        if distributed is not None:
            figures["distributed"] = distributed
    return TransportBakeResult(T, dirs, cycles, time.perf_counter() - start, calls, figures,
                               {"engine": "cycles", "why": "asked for (--direct cycles)"
                                if direct == "cycles" else
                                "the bounces need Cycles" if bounces else choice["why"]})


def _bake_by_rays(scene, obj, dirs, rays, choice: dict, T, seed: int, start: float):
    """Generator: ``T`` (V, S) by ``rays`` (:class:`..base.direct_rays.ReceiverRays`), then
    Cycles' bake of the checked directions; returns the TransportBakeResult."""
    from ..base.direct_rays import check_indices, direct_agreement

    S = len(dirs)
    checks = check_indices(S)
    total = S + len(checks)
    for a in range(0, S, CHUNK_DIRECTIONS):
        b = min(a + CHUNK_DIRECTIONS, S)
        T[:, a:b] = rays.bake_rows(dirs[a:b]).T
        yield Progress(b, total, f"direct by rays, directions {a + 1}-{b}/{S}")
    ray_seconds = time.perf_counter() - start
    with EnvironmentBake(scene, obj, None, 1, 0, (8, 16), mode="irradiance", seed=seed,
                         world_sampling="none") as session:
        cycles_rows = []
        for i, s in enumerate(checks):
            cycles_rows.append(np.pi * session.bake_sun(dirs[s], 1.0, 0.0)[:, 0])
            yield Progress(S + i + 1, total, f"Cycles' check of the rays, direction {s + 1}")
        cycles, calls = session.bake_seconds, session.bake_calls
    cast = (rays.bake_engine or rays.engine).rays
    choice.update(checked_directions=len(checks), rays=int(cast),
                  # corners touching another object's surface (lt_addon/rays/contact.py)
                  contact_points=int(getattr(rays, "touching", 0)),
                  ray_seconds=round(ray_seconds, 3),
                  vs_cycles=direct_agreement(np.stack(cycles_rows), T[:, checks].T))
    return TransportBakeResult(T, dirs, cycles, time.perf_counter() - start, calls, None, choice)


def bake_environment_truth(scene, obj, environment, bounces: int, samples: int,
                           seed: int = 1) -> np.ndarray:
    """Cycles ground truth: ``E / pi`` per vertex under an equirect environment (bottom row first).

    Returns
    -------
    values : ndarray, shape (V, 3), float32
        Irradiance over pi per vertex (a white Lambertian surface's outgoing radiance).
    """
    env = np.asarray(environment)
    with EnvironmentBake(scene, obj, None, samples, bounces, env.shape[:2], mode="irradiance",
                         seed=seed, world_sampling="importance") as session:
        return session.bake(env)


@dataclass
class TransportSettings:
    """What to bake and how many eigentransports to keep (exactly one of energy / coeffs).

    ``clusters``: None = one global eigentransport (Nowrouzezahrai 2008); an int k = CPCA with k
    clusters; "auto" = Mahajan 2007's adaptive subdivision, started from the count predicted by
    the dimensionality analysis (:func:`..lt_addon.transport.cluster_analysis.auto_cpca`), keeping a
    split only when the cost falls. With clusters, ``energy`` E is a per-cluster tolerance: each
    cluster keeps the fewest vectors leaving at most 1 - E of its energy (``coeffs`` = a fixed
    count per cluster; "auto" needs ``energy``)."""

    directions: str = setting(
        "cube:8", metavar="SPEC",
        help="Hard-sun directions of the per-vertex bake: halton:N | latlong:RxC | "
             "cube:N (6 N^2) | cubegauss:N (cube:8 = 384)")
    bounces: int = setting(0, lo=0, hi=64,
                           help="Diffuse bounces of the per-vertex bake (0 = visibility x cosine, "
                                "exact at 1 sample)")
    direct: str = setting("auto", label="Direct By", choices=(
        ("auto", "Auto", "without bounces, shadow rays where they reproduce the scene (no "
                         "see-through or displaced shadow casters, hair or volumes), else "
                         "Cycles; the report says which and why"),
        ("rays", "Rays", "shadow rays per vertex and direction (Embree); refuse a scene rays "
                         "cannot reproduce, or bounces"),
        ("cycles", "Cycles", "a Cycles vertex bake per direction: the reference path")),
        help="How the per-vertex transport is baked")
    samples: int | None = setting(None, lo=1, panel=False,
                                  help="Cycles samples per vertex (default 1 without bounces: "
                                       "exact for a hard Sun; 64 with bounces)")
    energy: float | None = setting(
        0.99, lo=0.0, hi=1.0, soft=(0.5, 1.0), label="Energy Kept",
        help="Fraction of the centred transport energy the eigentransports keep (default 0.99)")
    coeffs: int | None = setting(None, lo=1, panel=False,
                                 help="keep exactly d eigentransports")
    seed: int = 0
    clusters: int | str | None = None

    def validate(self):
        from ...lt_addon.sphere.directions import parse_direction_spec

        try:
            ds = parse_direction_spec(self.directions)
        except ValueError as exc:
            raise BakeInputError(str(exc)) from None
        from ..base.direct_rays import DIRECT_BAKES

        if self.direct not in DIRECT_BAKES:
            raise BakeInputError(f"direct must be one of {', '.join(DIRECT_BAKES)}, got "
                                 f"{self.direct!r}")
        if self.bounces < 0 or self.bounces > 64:
            raise BakeInputError(f"bounces must be in 0..64, got {self.bounces}")
        if (self.energy is None) == (self.coeffs is None):
            raise BakeInputError("give exactly one of --energy and --coeffs")
        if self.energy is not None and not 0.0 < self.energy <= 1.0:
            raise BakeInputError(f"--energy must be in (0, 1], got {self.energy}")
        if self.coeffs is not None and self.coeffs < 1:
            raise BakeInputError(f"--coeffs must be >= 1, got {self.coeffs}")
        self.clusters = parse_clusters(self.clusters)
        if self.clusters == "auto" and self.energy is None:
            raise BakeInputError("--clusters auto chooses the clusters by cost at a tolerance; "
                                 "use --energy instead of --coeffs")
        check_ranges(self)
        return ds


def parse_clusters(value):
    """None, "auto" or a positive int from a CLI / settings value; BakeInputError otherwise."""
    if value is None or value == "auto":
        return value
    text = str(value).strip()
    if isinstance(value, bool) or not text.isdigit() or int(text) < 1:
        raise BakeInputError(f"--clusters takes 'auto' or a positive integer, got {value!r}")
    return int(text)


def fit_model(T: np.ndarray, settings: TransportSettings, metadata: dict, edges=None):
    """Eigentransport (no clusters) or CPCA (``settings.clusters``) of a (V, S) bake.

    ``edges`` (E, 2): the mesh edges, needed by ``clusters="auto"`` (the dimensionality
    analysis that picks the starting count grows patches along them).
    Raises BakeInputError when a fixed cluster count exceeds the vertex count."""
    from ...lt_addon.transport import cluster_analysis
    from ...lt_addon.transport import cpca
    from ...lt_addon.transport.eigentransport import fit_eigentransport

    T = np.asarray(T, dtype=np.float64)
    if settings.clusters is None:
        return fit_eigentransport(T, d=settings.coeffs, energy=settings.energy,
                                  metadata=metadata)
    tol = None if settings.energy is None else 1.0 - settings.energy
    if settings.clusters == "auto":
        if edges is None:
            raise BakeInputError("--clusters auto needs the mesh edges")
        return cluster_analysis.auto_cpca(T, edges, tol=tol, seed=settings.seed)
    if settings.clusters > T.shape[0]:
        raise BakeInputError(f"--clusters {settings.clusters} exceeds the object's "
                             f"{T.shape[0]} vertices; use at most {T.shape[0]} or 'auto'")
    return cpca.fit_cpca(T, settings.clusters, tol=tol, dims=settings.coeffs, seed=settings.seed)


def cluster_summary(model) -> dict:
    """JSON-safe CPCA figures for reports: counts, sizes, dims, N and Mahajan's cost."""
    p, n = model.sizes(), model.dims()
    info = {k: v for k, v in model.info.items() if k != "tree"}
    return {"clusters": model.n_clusters, "N": model.N, "cost": model.cost(),
            "cost_per_vertex": model.cost_per_vertex(),
            "size_min": int(p.min()), "size_median": float(np.median(p)), "size_max": int(p.max()),
            "dims_min": int(n.min()), "dims_mean": float(n.mean()), "dims_max": int(n.max()),
            "fit": info}


@dataclass
class TransportBakeOutput:
    """What a per-vertex transport bake produced: the JSON-safe report (as written next to the
    sidecar) and the fitted model (an Eigentransport or a CPCA) -- an object, not a report
    entry."""
    report: dict
    model: object


def write_transport(result: TransportBakeResult, model, fit_seconds: float, obj, direction_set,
                    settings: TransportSettings, out_dir: str, figures: dict | None = None
                    ) -> dict:
    """Write the sidecar and the samples file, record the bake on ``obj``; returns the report
    (the caller writes it, once, when everything it reports is known)."""
    import os

    from ...lt_addon.transport.cpca import CPCA
    from ...lt_addon.transport.sidecar import samples_path, save_sidecar
    from ..base.blend_files import record_kind
    from ..preview.vertex_relight import KIND, mesh_positions_normals

    clustered = isinstance(model, CPCA)
    os.makedirs(out_dir, exist_ok=True)
    path = _stem(out_dir, obj) + "_transport.npz"
    pos, nrm = mesh_positions_normals(obj)
    meta = {"object": obj.name, "directions": direction_set.spec, "bounces": settings.bounces,
            "samples": settings.samples or (1 if settings.bounces == 0 else 64),
            "seed": settings.seed}
    nbytes = save_sidecar(path, model, direction_set, pos, nrm, meta)
    # The samples themselves, kept so `relight analyze` / Analyze Clusters need not bake them
    # again. Half floats: T <= ~1 (visibility x cosine plus bounces), and fp16's 2^-11 relative
    # rounding is ~1e-7 of the energy, far below the analysis' 1e-3 tolerance.
    with atomic.atomic_path(samples_path(path)) as tmp:
        np.save(tmp, np.asarray(result.transport, np.float16))
    samples_bytes = os.path.getsize(samples_path(path))
    V, S = result.transport.shape
    report = {
        "kind": KIND, "object": obj.name, "sidecar": os.path.abspath(path),
        "samples": os.path.abspath(samples_path(path)),   # (V, S) float, read by analyze
        "vertices": V, "directions": S, "direction_set": direction_set.spec,
        "settings": {"bounces": settings.bounces, "samples": meta["samples"],
                     "energy": settings.energy, "coeffs": settings.coeffs, "seed": settings.seed,
                     "clusters": settings.clusters},
        "model": "cpca" if clustered else "eigentransport", "d": model.d,
        **({"cpca": cluster_summary(model),
            "relative_rms_error": model.info["relative_rms_error"]} if clustered else
           {"captured_energy": model.captured_energy, "selection": model.selection}),
        "device": cycles_device.current().report(),
        "direct": result.direct, "bake_calls": result.bake_calls,
        "timings": {"cycles_bake_seconds": round(result.cycles_seconds, 4),
                    "total_bake_seconds": round(result.total_seconds, 4),
                    "fit_seconds": round(fit_seconds, 4),
                    "seconds_per_direction": round(result.cycles_seconds / max(S, 1), 5),
                    "directions_per_second": round(S / max(result.total_seconds, 1e-9), 2)},
        "bytes": {"sidecar_file": nbytes, "samples_file": samples_bytes,
                  **model.storage_bytes()},
        **(figures or {}),
    }
    record_kind(obj, KIND, path, {"d": model.d, "directions": direction_set.spec,
                                  "model": report["model"],
                                  "clusters": model.n_clusters if clustered else 1,
                                  "bounces": settings.bounces, "vertices": V,
                                  "bytes": nbytes,
                                  "bake_seconds": round(result.total_seconds, 2)})
    return report


def _stem(out_dir: str, obj) -> str:
    """``<out_dir>/<object>``, the object name made file-safe: every file of the bake starts so."""
    import os

    safe = object_stem(obj.name)
    return os.path.join(out_dir, safe)


def report_path(out_dir: str, obj) -> str:
    """``<out_dir>/<object>_transport.json``."""
    return _stem(out_dir, obj) + "_transport.json"


def fit(result: TransportBakeResult, obj, direction_set, settings: TransportSettings):
    """(model, seconds): eigentransport or CPCA of a bake (:func:`fit_model`)."""
    from ..base.meshes import mesh_edges

    t0 = time.perf_counter()
    model = fit_model(result.transport, settings, {"directions": direction_set.spec,
                                                    "bounces": settings.bounces},
                      edges=mesh_edges(obj))
    return model, time.perf_counter() - t0


def fit_and_write(result: TransportBakeResult, obj, direction_set, settings: TransportSettings,
                  out_dir: str, figures: dict | None = None) -> TransportBakeOutput:
    """Fit a finished bake and write everything (sidecar, samples, record, JSON report)."""
    model, seconds = fit(result, obj, direction_set, settings)
    report = write_transport(result, model, seconds, obj, direction_set, settings, out_dir,
                             figures)
    atomic.write_json(report_path(out_dir, obj), {**report, "format_version": REPORT_VERSION})
    return TransportBakeOutput(report, model)


def truth_environment(scene) -> np.ndarray:
    """The light a transport bake's ``--truth`` is checked under: the scene world's
    environment when it varies, else a sun-and-sky (a constant sky hides direction errors)."""
    from ...lt_addon.transport.error import sun_sky_environment
    from ..preview.vertex_relight import world_environment

    env = world_environment(scene)
    if env is None or np.ptp(env) == 0:
        env = sun_sky_environment(64, [0.4, -0.3, 0.8], row_order="bottom_first")
    return env


def transport_job(scene, obj, settings: TransportSettings, out_dir: str, *,
                  truth_samples: int = 0, preview: bool = True, resume: bool = True,
                  client=None, blend_path: str | None = None):
    """The whole ``bake-transport`` verb as one job (a generator of :class:`.jobs.Progress`):
    bake, fit, optional Cycles truth (``truth_samples`` > 0), files, and the vertex preview.
    Nothing is written before the bake, fit and truth are done, so cancelling leaves the
    previous bake as it was; the JSON report is written once, at the end, with
    ``timings.wall_total`` covering all of it. With ``resume`` the bake's finished chunks
    are kept in ``<out_dir>/.relight_cache`` until the files are written, so a rerun after a
    cancel or crash redoes only the missing ones; a Dask ``client`` bakes them on its workers
    from ``blend_path``. Returns a :class:`TransportBakeOutput`."""
    started = time.perf_counter()
    direction_set = settings.validate()
    cache = (vertex_chunk_cache(scene, obj, direction_set.directions, settings.bounces,
                                settings.samples, settings.seed, out_dir) if resume else None)
    result = yield from bake_transport(scene, obj, direction_set.directions, settings.bounces,
                                       settings.samples, settings.seed, cache, client,
                                       blend_path, settings.direct)
    yield Progress(0, 1, "fitting")
    model, fit_seconds = fit(result, obj, direction_set, settings)
    figures = {}
    if truth_samples:
        yield Progress(0, 1, f"Cycles truth ({truth_samples} spp)")
        figures["ground_truth"] = truth_errors(scene, obj, model, direction_set,
                                               truth_environment(scene), settings.bounces,
                                               samples=truth_samples,
                                               transport=result.transport)
    report = write_transport(result, model, fit_seconds, obj, direction_set, settings, out_dir,
                             figures)
    if result.chunks:
        report.update(result.chunks)
    if cache is not None:   # once the bake is committed the chunks have served
        after_commit(out_dir, cache.clear)
    if preview:
        from ..preview import preview_nodes, vertex_relight

        timings = vertex_relight.update_preview(scene)
        preview_nodes.install_attribute_preview(obj, vertex_relight.SHADING_ATTRIBUTE)
        report["preview"] = {"shade_ms": round(timings.get(obj.name, {}).get("shade_ms", 0), 3),
                             "warnings": timings.get("warnings", [])}
    report["timings"]["wall_total"] = round(time.perf_counter() - started, 4)
    report["warnings"] = report_warnings(report)   # said by the CLI and the panel
    atomic.write_json(report_path(out_dir, obj), {**report, "format_version": REPORT_VERSION})
    return TransportBakeOutput(report, model)


def truth_errors(scene, obj, model, direction_set, environment, bounces: int, samples: int,
                 ds_for=(1, 2, 4, 8, 16, 32, 64, 128), transport=None) -> dict:
    """Relative RMS error per d of eigentransport shading vs a Cycles vertex bake of the same
    environment (white Lambertian, same bounces). ``environment``: (H, W, 3) bottom row first.

    With ``transport`` (the full (V, S) bake) the error of shading with *all* S directions is
    reported too: the floor that the direction sampling alone leaves, whatever d is."""
    from ...lt_addon.transport.cpca import CPCA
    from ...lt_addon.transport.eigentransport import project_environment, relative_rms_error

    t0 = time.perf_counter()
    truth = bake_environment_truth(scene, obj, environment, bounces, samples)
    truth_seconds = time.perf_counter() - t0
    Lw = project_environment(environment, direction_set.directions, direction_set.solid_angles,
                             row_order="bottom_first")
    # albedo 1: E / pi, as the DIFFUSE bake; a CPCA model has no single d to truncate
    models = ([(model.d, model)] if isinstance(model, CPCA) else
              [(d, model.truncate(d)) for d in sorted({min(d, model.d) for d in ds_for}
                                                        | {model.d})])
    rows = [{"d": d, "rel_rms_error": relative_rms_error(truth, m.shade(Lw))} for d, m in models]
    out = {"truth_samples": samples, "truth_seconds": round(truth_seconds, 3), "per_d": rows}
    if transport is not None:
        full = np.asarray(transport, np.float64) @ Lw / np.pi
        out["all_directions_rel_rms_error"] = relative_rms_error(truth, full)
    return out
