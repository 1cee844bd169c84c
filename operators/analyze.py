"""`relight analyze`: how many CPCA clusters an object's transport needs (Mahajan 2007), on data.

Bakes the object's per-vertex transport (one exact 1-sample hard-Sun bake per direction without
bounces, as :mod:`.transport_bake`), runs :func:`..lt_addon.transport.cluster_analysis.analyse_clusters`
on it and writes ``<object>_analysis.json``. From a source checkout with matplotlib (the
development tools, not part of the extension zip) it also draws the two charts of
:func:`..devtools.charts.analysis_charts`: patch dimensionality vs patch size and cost per vertex
vs cluster count.

Nothing in the .blend changes; every output is written under a temporary name and renamed.
"""

from __future__ import annotations

import os
import time

from ..lt_addon.io import atomic
from ..lt_addon.transport import cluster_analysis
from .meshes import mesh_edges


def analyse_object(scene, obj, direction_set, bounces: int = 0, samples: int | None = None,
                   tol: float = 1e-3, n_seeds: int = 8, seed: int = 0, on_progress=None) -> dict:
    """Bake ``obj``'s transport for ``direction_set`` and analyse it; returns the JSON report
    (with ``timings``: Cycles bake seconds and analysis seconds)."""
    from .steerable_bake import run
    from .transport_bake import bake_transport

    result = run(bake_transport(scene, obj, direction_set.directions, bounces, samples, seed),
                 on_progress=on_progress)
    if result is None:
        return None
    t0 = time.perf_counter()
    report = cluster_analysis.analyse_clusters(result.transport, mesh_edges(obj), tol=tol,
                                               n_seeds=n_seeds, seed=seed, progress=on_progress)
    report.update(object=obj.name, direction_set=direction_set.spec, bounces=bounces,
                  timings={"bake_seconds": round(result.total_seconds, 3),
                           "cycles_seconds": round(result.cycles_seconds, 3),
                           "analysis_seconds": round(time.perf_counter() - t0, 3)})
    return report


def write_analysis(report: dict, out_dir: str) -> dict:
    """Write the JSON report (and, where the development tools are present, the two charts)
    into ``out_dir``; returns the paths written."""
    os.makedirs(out_dir, exist_ok=True)
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in report["object"])
    paths = {"json": os.path.join(out_dir, f"{safe}_analysis.json")}
    try:   # charts need matplotlib, a development extra: the installed extension has neither
        from ..devtools import charts
    except ImportError:
        charts = None
    if charts is not None and charts.available():
        paths.update(charts.analysis_charts(report, out_dir, safe))
    atomic.write_json(paths["json"], dict(report, outputs=paths))
    return paths
