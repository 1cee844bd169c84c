"""`relight bench`: sweep every knob that costs time or bytes and measure the trade (bpy).

For each sample scene a sweep bakes a grid of settings and measures, per point:

* ``bake_seconds`` (wall) split into ``cycles_seconds`` (Cycles bake calls) and our own work;
* ``peak_rss_mb``: the process's peak resident memory above its level before the point
  (sampled every 20 ms on Linux, so Cycles' memory counts);
* ``stored_bytes``: the file the bake writes (EXR per storage mode, ``.npz`` sidecar);
* preview cost: ``preview_ms`` (NumPy relight of the whole texture / shading + attribute write
  of every vertex, median of 5) and ``preview_madds`` (multiply-adds per texel or vertex per
  light update: ``3 N1^2`` for a steered texture; ``3 (d + 1) + 3 S (d + 1) / V`` for
  eigentransport; ``3 sum_i n_i (p_i + S) / V`` for CPCA, which projects the S-sample lighting
  onto each cluster's basis at run time);
* error vs a high-sample Cycles reference that no knob touches (``rel_rmse``, ``psnr_db``,
  ``max_abs_error``; :func:`.pareto.error_metrics`).

Texture scenes (bumps, noise): a grid over basis order N1, samples and resolution, each bake
stored at every storage precision. The reference is a Cycles Sun lamp (angle ``sun_angle_deg``,
high samples, the sweep's largest resolution, same bounces) for three light directions; lower
resolutions are compared after nearest-texel upsampling (what the preview's Closest lookup
shows). Transport scenes (statue, room): one bake per direction set (s), then eigentransport at
several d and CPCA (fixed clusters and adaptive) fitted from it; the reference is a Cycles vertex
bake under a sun-and-sky environment at 256 samples. For these per-vertex bakes the PCA is the
eigentransport, so "PCA k" and "d" are the same knob (eigentransports kept); this sweep fits no
texture PCA (the transport textures' is benchmarks/bench_transport_textures.py's).

Outputs per scene in ``--out``: ``<scene>.json`` (settings, points, Pareto masks, chosen presets
for texture scenes), ``<scene>.csv`` and three charts ``<scene>_error_vs_{time,bytes,preview}.png``
with the Pareto-optimal points ringed.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..lt_addon.io import atomic
from ..operators.base.jobs import Progress
from . import charts, pareto

TEXTURE_SCENES = ("bumps", "noise")
TRANSPORT_SCENES = ("statue", "room")
STORAGE = ("float", "half", "u8")

#: light directions (azimuth, elevation in degrees) of the texture reference
REFERENCE_LIGHTS = ((30.0, 25.0), (150.0, 50.0), (270.0, 75.0))


@dataclass(frozen=True)
class TextureSweep:
    size: str
    orders: tuple
    samples: tuple
    resolutions: tuple
    bounces: int
    reference_samples: int
    sun_angle_deg: float = 10.0


@dataclass(frozen=True)
class TransportSweep:
    size: str
    direction_sets: tuple
    ds: tuple
    clusters: tuple  # ("auto", tol) or (k, tol)
    reference_samples: int = 256


SWEEPS = {
    "quick": {"texture": TextureSweep("test", (3, 5, 7), (4, 16, 64), (32, 64, 128), 2, 1024),
              "transport": TransportSweep("test", ("cube:4", "cube:8", "cube:16"), (4, 8, 16, 32, 64, 0),
                                          ((8, 1e-3), ("auto", 1e-3), ("auto", 1e-4)))},
    "standard": {"texture": TextureSweep("demo", (3, 5, 7, 9), (16, 64), (128, 256), 2, 1024),
                 "transport": TransportSweep("demo", ("cube:4", "cube:8", "cube:16"),
                                             (4, 8, 16, 32, 64, 128, 0),
                                             ((8, 1e-3), (50, 1e-3), ("auto", 1e-3)))},
}


# ---------------------------------------------------------------------------------------------
# measuring helpers


def _rss_bytes() -> int:
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


@contextmanager
def peak_memory():
    """Context manager yielding a dict whose ``peak_rss_mb`` is set on exit: the peak resident
    set size above the level at entry, sampled every 20 ms by a thread."""
    out = {"peak_rss_mb": 0.0}
    base = _rss_bytes()
    peak = [base]
    stop = threading.Event()

    def sample():
        while not stop.wait(0.02):
            peak[0] = max(peak[0], _rss_bytes())

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    try:
        yield out
    finally:
        stop.set()
        t.join()
        peak[0] = max(peak[0], _rss_bytes())
        out["peak_rss_mb"] = round((peak[0] - base) / 2 ** 20, 2)


def _median_ms(fn, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(1e3 * (time.perf_counter() - t0))
    return round(float(np.median(times)), 3)


def _upsample(image: np.ndarray, size: int) -> np.ndarray:
    """Nearest-texel upsampling of an (R, R, C) image to (size, size, C); size % R == 0."""
    f = size // image.shape[0]
    if f * image.shape[0] != size:
        raise ValueError(f"reference resolution {size} is not a multiple of {image.shape[0]}")
    return np.repeat(np.repeat(image, f, axis=0), f, axis=1)


#: objects swept instead of the scene's default relight object: the room's floor receives the
#: colour bleeding and has 1089 vertices at demo size (the box has 98)
BENCH_OBJECTS = {"room": "Floor"}


def _fresh_scene(name: str, size: str):
    import bpy

    from .. import samples

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    info = samples.build(name, scene, size)
    return scene, bpy.data.objects[BENCH_OBJECTS.get(name, info["relight_object"])]


# ---------------------------------------------------------------------------------------------
# texture scenes


def texture_reference(scene, obj, sweep: TextureSweep, on_progress=None) -> dict:
    """Cycles Sun-lamp bakes at the sweep's largest resolution: {"images": [(R, R, 3)], ...}."""
    from ..lt_addon.sphere.hemisphere import direction_from_az_el
    from ..operators.base.cycles_bake import EnvironmentBake

    R = max(sweep.resolutions)
    t0 = time.perf_counter()
    images = []
    with EnvironmentBake(scene, obj, R, sweep.reference_samples, sweep.bounces, (8, 16),
                         seed=4242) as session:
        for i, (az, el) in enumerate(REFERENCE_LIGHTS):
            images.append(session.bake_sun(direction_from_az_el(az, el), 1.0,
                                           sweep.sun_angle_deg))
            if on_progress:
                on_progress(Progress(i + 1, len(REFERENCE_LIGHTS), "reference"))
    return {"images": images, "resolution": R, "samples": sweep.reference_samples,
            "seconds": round(time.perf_counter() - t0, 2), "sun_angle_deg": sweep.sun_angle_deg}


def texture_points(scene, obj, sweep: TextureSweep, reference: dict, tmp: str,
                   on_progress=None) -> list:
    """Bake every (order, samples, resolution) and measure it at every storage precision."""
    from ..lt_addon.sphere.hemisphere import direction_from_az_el
    from ..lt_addon.steerable.texture import SteerableTexture
    from ..operators.base.jobs import run
    from ..operators.bakes.steerable_bake import TextureBakeSettings, bake_steerable_texture

    lights = [direction_from_az_el(az, el) for az, el in REFERENCE_LIGHTS]
    R = reference["resolution"]
    grid = [(o, s, r) for o in sweep.orders for s in sweep.samples for r in sweep.resolutions]
    points = []
    for i, (order, spp, res) in enumerate(grid):
        settings = TextureBakeSettings(order=order, resolution=res, samples=spp,
                                       bounces=sweep.bounces, storage="half")
        settings.validate()
        with peak_memory() as mem:
            result = run(bake_steerable_texture(scene, obj, settings))
        for storage in STORAGE:
            path = os.path.join(tmp, f"p{i}-{storage}.exr")
            nbytes = result.texture.save(path, storage)
            tex = SteerableTexture.load(path)
            os.remove(path)
            metrics = [pareto.error_metrics(_upsample(tex.relight(d), R), ref)
                       for d, ref in zip(lights, reference["images"])]
            points.append({
                "order": order, "samples": spp, "resolution": res, "storage": storage,
                "bounces": sweep.bounces, "bake_seconds": round(result.total_seconds, 3),
                "cycles_seconds": round(result.cycles_seconds, 3),
                "own_seconds": round(result.total_seconds - result.cycles_seconds, 3),
                "bake_calls": result.bake_calls, "peak_rss_mb": mem["peak_rss_mb"],
                "stored_bytes": nbytes,
                "preview_ms": _median_ms(lambda: tex.relight(lights[1])),
                "preview_madds": 3 * order * order,
                "rel_rmse": float(np.sqrt(np.mean([m["rel_rmse"] ** 2 for m in metrics]))),
                "psnr_db": float(np.mean([m["psnr_db"] for m in metrics])),
                "max_abs_error": float(max(m["max_abs_error"] for m in metrics))})
        if on_progress:
            p = points[-3]
            on_progress(Progress(i + 1, len(grid), f"N1 {order}, {spp} spp, {res}^2: "
                                 f"{p['bake_seconds']:.1f} s, rel. RMSE {p['rel_rmse']:.4f}"))
    return points


# ---------------------------------------------------------------------------------------------
# transport scenes


def _model_madds(model, S: int) -> float:
    from ..lt_addon.transport.cpca import CPCA

    if isinstance(model, CPCA):
        n = model.dims()
        return float(3 * np.sum(n * (model.sizes() + S)) / model.n_vertices)
    V, d = model.n_vertices, model.d
    return float(3 * (d + 1) + 3 * S * (d + 1) / V)


def transport_points(scene, obj, sweep: TransportSweep, tmp: str, on_progress=None) -> tuple:
    """Bake per direction set, fit every d / clustering, compare with a Cycles reference."""
    from ..lt_addon.transport import cpca
    from ..lt_addon.transport.cluster_analysis import auto_cpca
    from ..lt_addon.sphere.directions import parse_direction_spec
    from ..lt_addon.transport.eigentransport import fit_eigentransport, project_environment
    from ..lt_addon.transport.error import sun_sky_environment
    from ..operators.base.jobs import run
    from ..operators.bakes.transport_bake import bake_environment_truth, bake_transport
    from ..operators.base.meshes import mesh_edges
    from ..operators.preview.vertex_relight import write_shading

    edges = mesh_edges(obj)
    env = sun_sky_environment(64, [0.4, -0.3, 0.8], row_order="bottom_first",
                              sun_radius_deg=8.0, sun_radiance=500.0)
    t0 = time.perf_counter()
    truth = bake_environment_truth(scene, obj, env, 0, sweep.reference_samples, seed=4242)
    reference = {"samples": sweep.reference_samples, "seconds": round(time.perf_counter() - t0, 2),
                 "environment": "sun and sky, 8 deg sun at (0.4, -0.3, 0.8)"}
    points = []
    for spec in sweep.direction_sets:
        ds = parse_direction_spec(spec)
        with peak_memory() as mem:
            res = run(bake_transport(scene, obj, ds.directions))
        T = res.transport.astype(np.float64)
        V, S = T.shape
        Lw = project_environment(env, ds.directions, ds.solid_angles, row_order="bottom_first")
        N = cpca.global_dimension(T)
        t1 = time.perf_counter()
        full = fit_eigentransport(T, d=min(V, S))
        svd_seconds = time.perf_counter() - t1  # one decomposition serves every d: charged to each
        fits = [("eigentransport", {"d": d or full.d}, lambda d=d: full.truncate(d or full.d))
                for d in sweep.ds if d <= full.d]
        fits += [("cpca", {"clusters": k, "tol": tol},
                  lambda k=k, tol=tol: (auto_cpca(T, edges, tol=tol, N=N) if k == "auto"
                                        else cpca.fit_cpca(T, min(k, V), tol=tol, N=N)))
                 for k, tol in sweep.clusters]
        for kind, knobs, fit in fits:
            t1 = time.perf_counter()
            model = fit()
            fit_seconds = time.perf_counter() - t1 + (svd_seconds if kind == "eigentransport"
                                                      else 0.0)
            path = os.path.join(tmp, "model.npz")
            np.savez(path, **model.to_arrays())
            nbytes = os.path.getsize(path)
            shade = model.shade(Lw)
            m = pareto.error_metrics(shade, truth)
            points.append({
                "direction_set": spec, "directions": S, "model": kind, **knobs,
                "clusters_fitted": getattr(model, "n_clusters", 1),
                "bake_seconds": round(res.total_seconds + fit_seconds, 3),
                "cycles_seconds": round(res.cycles_seconds, 3),
                "own_seconds": round(res.total_seconds - res.cycles_seconds + fit_seconds, 3),
                "peak_rss_mb": mem["peak_rss_mb"], "stored_bytes": nbytes,
                "preview_ms": _median_ms(lambda: write_shading(obj, model.shade(Lw))),
                "preview_madds": _model_madds(model, S),
                "rel_rmse": m["rel_rmse"], "psnr_db": m["psnr_db"],
                "max_abs_error": m["max_abs_error"]})
        if on_progress:
            best = min(p["rel_rmse"] for p in points if p["direction_set"] == spec)
            on_progress(Progress(len(points), len(points), f"{spec}: {S} directions in "
                                 f"{res.total_seconds:.1f} s, best rel. RMSE {best:.4f}"))
    return points, reference


# ---------------------------------------------------------------------------------------------
# reporting


AXES = {"time": ("bake_seconds", "bake time (s)"), "bytes": ("stored_bytes", "stored bytes"),
        "preview": ("preview_madds", "preview multiply-adds per texel/vertex")}


def add_pareto(points: list) -> None:
    """Mark each point Pareto-optimal (True/False) for error vs each cost axis, in place."""
    err = np.array([p["rel_rmse"] for p in points], float)
    for name, (key, _) in AXES.items():
        mask = pareto.pareto_mask(np.array([p[key] for p in points], float), err)
        for p, m in zip(points, mask):
            p[f"pareto_{name}"] = bool(m)


def _group(p: dict) -> str:
    if "order" in p:
        return f"N1 = {p['order']}"
    return f"{p['model']} {p['direction_set']}"


def write_charts(scene_name: str, points: list, out_dir: str) -> dict:
    """Three log-log charts, one series per group (order / model + directions), Pareto ringed."""
    paths = {}
    groups = sorted({_group(p) for p in points}, key=lambda g: (len(g), g))
    for name, (key, label) in AXES.items():
        series = []
        for g in groups:
            pts = sorted((p for p in points if _group(p) == g), key=lambda p: p[key])
            series.append(charts.Series(np.array([p[key] for p in pts], float),
                                      np.array([p["rel_rmse"] for p in pts], float), g,
                                      line=False,
                                      highlight=np.array([p[f"pareto_{name}"] for p in pts])))
        paths[name] = os.path.join(out_dir, f"{scene_name}_error_vs_{name}.png")
        charts.write_chart(paths[name], series, title=f"{scene_name}: error vs {label} "
                         "(ringed: Pareto-optimal)", xlabel=label,
                         ylabel="rel. RMSE vs Cycles reference", logx=True, logy=True)
    return paths


def choose_texture_presets(points: list, storage_tolerance: float = 0.01) -> dict:
    """Draft / balanced / production from the (bake seconds, rel. RMSE) Pareto front.

    The storage precisions of one bake share its bake time, so the front picks among them by
    error differences that are mostly noise; each chosen bake then takes the precision with the
    fewest bytes whose error is within ``storage_tolerance`` (relative) of the chosen one."""
    chosen = pareto.choose_presets(points, cost_key="bake_seconds", error_key="rel_rmse")
    keys = ("order", "samples", "resolution", "storage", "bounces")
    out = {}
    for name, p in chosen.items():
        same_bake = [q for q in points if all(q[k] == p[k] for k in keys if k != "storage")
                     and q["rel_rmse"] <= p["rel_rmse"] * (1 + storage_tolerance)]
        q = min(same_bake, key=lambda q: q["stored_bytes"])
        why = p["why"] + (f"; stored as {q['storage']} ({q['stored_bytes']} bytes, rel_rmse "
                          f"{q['rel_rmse']:.4f}): the smallest precision within "
                          f"{100 * storage_tolerance:g}% of its error"
                          if q["storage"] != p["storage"] else "")
        out[name] = {"settings": {k: q[k] for k in keys},
                     "figures": {k: q[k] for k in ("bake_seconds", "rel_rmse", "psnr_db",
                                                   "stored_bytes", "preview_madds",
                                                   "peak_rss_mb")},
                     "why": why}
    return out


def bench_scene(name: str, mode: str, out_dir: str, on_progress=None) -> dict:
    """Run one scene's sweep; writes ``<name>.json``, ``<name>.csv`` and the charts."""
    sweeps = SWEEPS[mode]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="relight-bench-") as tmp:
        if name in TEXTURE_SCENES:
            sweep = sweeps["texture"]
            scene, obj = _fresh_scene(name, sweep.size)
            reference = texture_reference(scene, obj, sweep, on_progress)
            points = texture_points(scene, obj, sweep, reference, tmp, on_progress)
            reference.pop("images")
        elif name in TRANSPORT_SCENES:
            sweep = sweeps["transport"]
            scene, obj = _fresh_scene(name, sweep.size)
            points, reference = transport_points(scene, obj, sweep, tmp, on_progress)
        else:
            raise ValueError(f"unknown bench scene {name!r}")
    add_pareto(points)
    report = {"scene": name, "mode": mode, "size": sweep.size, "object": obj.name,
              "sweep": {k: v for k, v in sweep.__dict__.items()}, "reference": reference,
              "machine": f"{os.cpu_count()} cores", "seconds": round(time.perf_counter() - t0, 1),
              "date": time.strftime("%Y-%m-%d"), "points": points}
    if name in TEXTURE_SCENES:
        report["presets"] = choose_texture_presets(points)
    os.makedirs(out_dir, exist_ok=True)
    report["charts"] = write_charts(name, points, out_dir)
    pareto.write_csv(os.path.join(out_dir, f"{name}.csv"), points)
    path = os.path.join(out_dir, f"{name}.json")
    atomic.write_json(path, report, default=str)
    report["json"] = path
    return report


def pareto_table(points: list, axis: str = "time") -> list:
    """The Pareto-optimal points of one axis, cheapest first."""
    key = AXES[axis][0]
    return sorted((p for p in points if p[f"pareto_{axis}"]), key=lambda p: p[key])


def format_report(report: dict) -> str:
    """Console summary: the Pareto front of error vs bake time, and the presets if chosen."""
    pts = report["points"]
    lines = [f"== {report['scene']} ({report['size']}, {report['object']}): {len(pts)} points in "
             f"{report['seconds']:.0f} s -> {report['json']}",
             "   Pareto front, error vs bake time:"]
    for p in pareto_table(pts, "time"):
        what = (f"N1 {p['order']:2d} {p['samples']:4d} spp {p['resolution']:4d}^2 "
                f"{p['storage']:5s}" if "order" in p else
                f"{p['direction_set']:8s} {p['model']:14s} "
                + (f"d {p['d']:4d}" if p["model"] == "eigentransport"
                   else f"k {p['clusters']} tol {p['tol']:g}"))
        lines.append(f"     {what}: {p['bake_seconds']:8.2f} s, {p['stored_bytes']:>10d} B, "
                     f"{p['preview_madds']:8.1f} madds, rel. RMSE {p['rel_rmse']:.4f}, "
                     f"PSNR {p['psnr_db']:.1f} dB")
    for name, pr in report.get("presets", {}).items():
        lines.append(f"   preset {name}: {pr['settings']} -- {pr['why']}")
    return "\n".join(lines)
