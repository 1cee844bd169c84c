"""`relight analyze`: how many CPCA clusters an object's transport needs (Mahajan 2007), on data.

Bakes the object's per-vertex transport (one exact 1-sample hard-Sun bake per direction without
bounces, as :mod:`.transport_bake`), runs :func:`..lt_addon.cluster_analysis.analyse_clusters`
on it and writes ``<object>_analysis.json`` plus two PNG charts:

* ``<object>_dimensionality.png``: patch dimensionality vs patch size, log-log, one curve per
  seed vertex, with the fitted slope in the legend;
* ``<object>_cost.png``: cost per vertex vs cluster count (log x), the measured optimum, the
  count predicted from the slope (``V / p*``) and the two adaptive results (the paper's, and
  ``--clusters auto``) marked.

Nothing in the .blend changes; every output is written under a temporary name and renamed.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from ..lt_addon import cluster_analysis, plot
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


def dimensionality_chart(report: dict) -> list:
    """Chart series: one log-log dimensionality curve per seed vertex."""
    dim = report["dimensionality"]
    out = []
    for c in dim["curves"]:
        label = f"vertex {c['seed']}: slope {c['slope']:.2f}"
        out.append(plot.Series(np.array(c["sizes"], float), np.array(c["dims"], float), label))
    return out


def cost_chart(report: dict) -> tuple[list, list]:
    """Chart series and vertical markers: measured cost per vertex vs cluster count."""
    curve = report["cost_curve"]
    k = np.array([r["clusters"] for r in curve], float)
    c = np.array([r["cost_per_vertex"] for r in curve], float)
    best = k == report["optimum"]["clusters"]
    series = [plot.Series(k, c, "fixed CPCA (measured)", highlight=best),
              plot.Series(np.array([report["adaptive"]["clusters"]], float),
                          np.array([report["adaptive"]["cost_per_vertex"]], float),
                          "adaptive (paper: from 8, halving)", line=False, marker="x"),
              plot.Series(np.array([report["auto"]["clusters"]], float),
                          np.array([report["auto"]["cost_per_vertex"]], float),
                          "auto (from predicted, halving/quartering)", line=False, marker="x")]
    marks = [(float(report["optimum"]["clusters"]), "optimum")]
    if report["predicted_clusters"]:
        marks.append((float(report["predicted_clusters"]), "predicted V/p*"))
    return series, marks


def write_analysis(report: dict, out_dir: str) -> dict:
    """Write the JSON report and the two charts into ``out_dir``; returns their paths."""
    os.makedirs(out_dir, exist_ok=True)
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in report["object"])
    paths = {"json": os.path.join(out_dir, f"{safe}_analysis.json"),
             "dimensionality_png": os.path.join(out_dir, f"{safe}_dimensionality.png"),
             "cost_png": os.path.join(out_dir, f"{safe}_cost.png")}
    dim = report["dimensionality"]
    plot.write_chart(paths["dimensionality_png"], dimensionality_chart(report),
                     title=f"{report['object']}: patch dimensionality (99.95% energy), mean "
                           f"slope {dim['slope']:.2f}",
                     xlabel="patch size (vertices)", ylabel="dimensionality", logx=True,
                     logy=True)
    series, marks = cost_chart(report)
    plot.write_chart(paths["cost_png"], series,
                     title=f"{report['object']}: CPCA cost, N = {report['N']}, tol "
                           f"{report['tol']:g}",
                     xlabel="clusters", ylabel="multiply-adds per vertex", logx=True,
                     vlines=marks)
    report = dict(report, outputs=paths)
    tmp = paths["json"] + f".{os.getpid()}.tmp"
    with open(tmp, "w") as fh:
        json.dump(report, fh, indent=2)
    os.replace(tmp, paths["json"])
    return paths
