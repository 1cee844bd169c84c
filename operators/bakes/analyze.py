"""`relight analyze` / *Analyze Clusters*: how many CPCA clusters an object's transport needs
(Mahajan 2007), measured on the object's own transport.

The job (:func:`analysis_job`) takes the transport samples of the object's existing vertex
transport bake when it was made with the same direction set and bounces (``bake-transport``
keeps them next to its sidecar as ``<object>_transport_samples.npy``, half floats), and bakes
them otherwise (one exact 1-sample hard-Sun bake per direction without bounces, as
:mod:`.transport_bake`). It runs
:func:`..lt_addon.transport.cluster_analysis.analyse_clusters` on them and the report says which
source it used. :func:`write_analysis` writes ``<object>_analysis.json``; from a source checkout
with matplotlib (the development tools, not part of the extension zip) it also draws the two
charts of :func:`..devtools.charts.analysis_charts`: patch dimensionality vs patch size and cost
per vertex vs cluster count.

Nothing in the .blend changes; every output is written under a temporary name and renamed.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from ...lt_addon import plugins
from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem
from ...lt_addon.transport import cluster_analysis
from ...lt_addon.transport.sidecar import samples_path
from ..base.jobs import Progress
from ..base.meshes import mesh_edges

#: scene property with the one-line summary of the last analysis (shown in the panel)
SUMMARY_KEY = "relight_analysis"


def reusable_samples(obj, direction_set, bounces: int) -> tuple[str | None, str]:
    """(path, why): the samples file of ``obj``'s vertex transport bake if it was made with
    this direction set and bounces for the mesh as it is now, else (None, the reason)."""
    import bpy

    from ..base.blend_files import object_bakes
    from ..preview.vertex_relight import KIND

    records = [b for b in object_bakes(obj) if b.get("kind") == KIND]
    if not records:
        return None, "no vertex transport bake"
    rec = records[-1]
    if rec.get("directions") != direction_set.spec or rec.get("bounces") != bounces:
        return None, (f"the bake used {rec.get('directions')}, {rec.get('bounces')} bounces, "
                      f"not {direction_set.spec}, {bounces} bounces")
    if rec.get("vertices") != len(obj.data.vertices):
        return None, "the mesh changed since the bake"
    path = os.path.normpath(samples_path(bpy.path.abspath(rec["path"])))
    if not os.path.isfile(path):
        return None, f"the bake kept no samples ({os.path.basename(path)} is missing)"
    return path, "same directions and bounces"


@dataclass
class AnalysisOutput:
    """What :func:`analysis_job` produced: the JSON-safe report (as written) and the paths of
    the files it wrote (``json``; the two charts too where the development tools are)."""
    report: dict
    paths: dict


def analysis_job(scene, obj, direction_set, out_dir: str, bounces: int = 0,
                 samples: int | None = None, tol: float = 1e-3, n_seeds: int = 8,
                 seed: int = 0, reuse: bool = True):
    """Job (a generator yielding :class:`.jobs.Progress`): the object's transport -- reused from
    its bake where possible (``reuse``), baked otherwise -- its cluster analysis, and the report
    written into ``out_dir`` (:func:`write_analysis`); returns an :class:`AnalysisOutput`. The
    report's ``transport_source`` says where the transport came from and why, its ``timings``
    hold the bake, the analysis and the whole job's wall seconds."""
    from .transport_bake import bake_transport

    started = time.perf_counter()
    path, why = reusable_samples(obj, direction_set, bounces) if reuse else (None, "--rebake")
    T = None
    if path is not None:
        from ...lt_addon.io import untrusted

        yield Progress(0, 1, f"reusing {os.path.basename(path)}")
        want = (len(obj.data.vertices), direction_set.directions.shape[0])
        shape = untrusted.npy_header(path)[0]   # (its header only: the file may be anyone's)
        if shape != want:
            T, path, why = None, None, f"the samples file holds {shape}, not this mesh's"
        else:
            T = untrusted.load_npy(path, shape=want, dtype="f")
            untrusted.check_values(path, T, what="transport values")
    if T is None:
        # as the vertex bake makes it (rays where they reproduce the scene): a reused bake
        # and a fresh one are the same transport
        result = yield from bake_transport(scene, obj, direction_set.directions, bounces,
                                           samples, seed, direct="auto")
        T = result.transport
        bake = {"bake_seconds": round(result.total_seconds, 3),
                "cycles_seconds": round(result.cycles_seconds, 3)}
        source = {"kind": "baked", "why": why, "direct": result.direct["engine"]}
    else:
        bake = {"bake_seconds": 0.0, "cycles_seconds": 0.0}
        source = {"kind": "reused", "file": path, "why": why}
    yield Progress(1, 1, f"analysing {T.shape[0]} vertices x {T.shape[1]} directions")
    t0 = time.perf_counter()
    report = cluster_analysis.analyse_clusters(np.asarray(T, np.float64), mesh_edges(obj),
                                               tol=tol, n_seeds=n_seeds, seed=seed)
    now = time.perf_counter()
    report.update(object=obj.name, direction_set=direction_set.spec, bounces=bounces,
                  transport_source=source,
                  timings={**bake, "analysis_seconds": round(now - t0, 3),
                           "wall_total": round(now - started, 3)})
    return AnalysisOutput(report, write_analysis(report, out_dir))


def summary(report: dict) -> str:
    """One line for the panel and the operator report."""
    best, one = report["optimum"], report["global_pca"]
    src = "reused bake" if report["transport_source"]["kind"] == "reused" else "baked"
    return (f"{report['object']}: best {best['clusters']} clusters, "
            f"{best['cost_per_vertex']:.1f} vs {one['cost_per_vertex']:.1f} multiply-adds per "
            f"vertex for one PCA; predicted {report['predicted_clusters'] or '-'} "
            f"({src}, {report['timings']['wall_total']:.1f} s)")


def write_analysis(report: dict, out_dir: str) -> dict:
    """Write the JSON report (and, where the development tools are present, the two charts)
    into ``out_dir``; returns the paths written."""
    os.makedirs(out_dir, exist_ok=True)
    safe = object_stem(report["object"])
    paths = {"json": os.path.join(out_dir, f"{safe}_analysis.json")}
    draw = plugins.get("analysis-charts")   # the development tools' (matplotlib), if installed
    if draw is not None:
        paths.update(draw(report, out_dir, safe))
    atomic.write_json(paths["json"], dict(report, outputs=paths))
    return paths
