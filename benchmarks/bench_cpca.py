"""Benchmark: Mahajan 2007's comparison on our scenes -- the per-vertex cost of global PCA,
fixed CPCA at 10 / 50 / 5000 clusters, the Mahajan-chosen count and adaptive subdivision (the
paper's: from 8 clusters, binary splits; and ``--clusters auto``: from the predicted count,
binary or 4-way splits), all at equal *shading* error.

Every method is fitted over a sweep of per-cluster tolerances; each fit gives one (shading
error, cost per vertex) point, the shading error being the relative RMS difference from the
full transport's shading under four sun-and-sky environments. A method's cost at the target
error is interpolated log-log along its points (``cluster_analysis.cost_at_error``). Costs are
Mahajan's ``sum_i n_i (p_i + N) / V`` with each non-zero cluster mean counted as a vector.

Prints a table and writes JSON, CSV and a PNG chart per scene. Usage:
    python benchmarks/bench_cpca.py [--scenes statue,room] [--size demo|test]
        [--directions cube:8] [--targets 0.01,0.003] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OBJECTS = {"statue": "Statue", "room": "Floor"}
PAPER = "adaptive, paper (8 clusters, halving)"
AUTO = "adaptive, auto (predicted count, halving or quartering)"
SUNS = ([0.4, -0.3, 0.8], [-0.7, 0.2, 0.4], [0.1, 0.8, 0.3], [0.0, 0.0, 1.0])
FLOOR = 1e-4  # charts show shading errors from here up (smaller ones are drawn at it)
TOLS = 10.0 ** -np.arange(1.5, 4.51, 0.5)          # ~3e-2 .. ~3e-5 per-cluster tolerance


def bake(name: str, size: str, spec: str):
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
    from relightable_textures.operators.bakes import transport_bake as tb
    from relightable_textures.operators.base.meshes import mesh_edges
    from relightable_textures.operators.base.jobs import run

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build(name, scene, size)
    obj = bpy.data.objects[OBJECTS[name]]
    ds = parse_direction_spec(spec)
    res = run(tb.bake_transport(scene, obj, ds.directions))
    return res, ds, mesh_edges(obj)


def lightings(ds) -> np.ndarray:
    """(4, S, 3) weighted sun-and-sky lightings (8 degree suns)."""
    from relightable_textures.lt_addon.transport.eigentransport import project_environment
    from relightable_textures.lt_addon.transport.error import sun_sky_environment

    return np.stack([project_environment(
        sun_sky_environment(64, d, row_order="bottom_first", sun_radius_deg=8.0,
                            sun_radiance=500.0), ds.directions, ds.solid_angles,
        row_order="bottom_first") for d in SUNS])


def bench_scene(name: str, size: str, spec: str, targets) -> dict:
    from relightable_textures.lt_addon.transport import cluster_analysis as CA
    from relightable_textures.lt_addon.transport import cpca as cp

    res, ds, edges = bake(name, size, spec)
    T = res.transport.astype(np.float64)
    V, S = T.shape
    L = lightings(ds)
    N = cp.global_dimension(T)
    t0 = time.perf_counter()
    analysis = CA.analyse_clusters(T, edges, counts=[1])
    predicted = analysis["predicted_clusters"] or 1
    methods = {"global PCA": CA.global_pca_curve(T, L, N)}
    fixed = {f"fixed {k}" + (f" (= V)" if k >= V else ""): min(k, V) for k in CA.PAPER_COUNTS}
    fixed[f"Mahajan-chosen {predicted}"] = predicted
    for label, k in fixed.items():
        tols = TOLS if k < V else TOLS[:1]           # one cluster per vertex is exact at any tol
        methods[label] = CA.method_curve(
            T, L, lambda tol, k=k: cp.fit_cpca(T, k, tol=tol, N=N), tols)
        print(f"   {name}: {label} done", flush=True)
    methods[PAPER] = CA.method_curve(
        T, L, lambda tol: cp.adaptive_cpca(T, 8, tol=tol, N=N), TOLS)
    print(f"   {name}: {PAPER} done", flush=True)
    methods[AUTO] = CA.method_curve(
        T, L, lambda tol: CA.auto_cpca(T, edges, tol=tol, N=N, predicted=predicted), TOLS)
    fit_seconds = time.perf_counter() - t0
    at = {}
    for target in targets:
        costs = {m: CA.cost_at_error([r["shading_error"] for r in rows],
                                     [r["cost_per_vertex"] for r in rows], target)
                 for m, rows in methods.items()}
        fixed_costs = [c for m, c in costs.items()
                       if (m.startswith("fixed") or m.startswith("Mahajan")) and c is not None]
        best_fixed = min(fixed_costs) if fixed_costs else None
        gp = costs["global PCA"]
        at[str(target)] = {"cost_per_vertex": costs, "best_fixed": best_fixed}
        for key, m in (("paper", PAPER), ("auto", AUTO)):
            ad = costs[m]
            at[str(target)][f"{key}_vs_global_pca"] = gp / ad if ad and gp else None
            at[str(target)][f"{key}_saving_vs_best_fixed"] = \
                1 - ad / best_fixed if ad and best_fixed else None
    return {"scene": f"{name}-{size}", "object": OBJECTS[name], "vertices": V, "directions": S,
            "direction_set": spec, "N": N, "bake_seconds": round(res.total_seconds, 3),
            "fit_seconds": round(fit_seconds, 3), "analysis": {
                k: analysis[k] for k in ("predicted_clusters", "N")} | {
                "slope": analysis["dimensionality"]["slope"],
                "p_star": analysis["dimensionality"]["p_star"]},
            "methods": methods, "at_target": at}


def chart(row: dict, path: str, targets) -> None:
    from relightable_textures.devtools import charts as plot

    series = []
    for label, rows in row["methods"].items():
        e = np.array([r["shading_error"] for r in rows], float)
        c = np.array([r["cost_per_vertex"] for r in rows], float)
        order = np.argsort(c)
        e = np.maximum(e, FLOOR)                      # near-exact fits at the left edge
        series.append(plot.Series(e[order], c[order], label, line=len(rows) > 1))
    plot.write_chart(path, series, title=f"{row['scene']}: cost at equal shading error "
                     f"(N = {row['N']}, {row['directions']} directions)",
                     xlabel="shading error (rel. RMS vs full transport)",
                     ylabel="multiply-adds per vertex", logx=True, logy=True,
                     vlines=[(float(t), "targets" if i == 0 else "")
                             for i, t in enumerate(targets)])


def main() -> None:
    from relightable_textures.devtools.pareto import write_csv

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="statue,room")
    parser.add_argument("--size", default="demo", choices=["test", "demo"])
    parser.add_argument("--directions", default="cube:8")
    parser.add_argument("--targets", default="0.01,0.003")
    parser.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    parser.add_argument("--replot", action="store_true",
                        help="only redraw the charts from <out>/cpca.json")
    args = parser.parse_args()
    if args.replot:
        with open(os.path.join(args.out, "cpca.json")) as fh:
            for row in json.load(fh):
                chart(row, os.path.join(args.out, f"cpca_{row['scene'].split('-')[0]}.png"),
                      [float(t) for t in row["at_target"]])
        return
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="relight-bench-"))
    os.makedirs(args.out, exist_ok=True)
    targets = [float(t) for t in args.targets.split(",")]
    out, csv_rows = [], []
    for name in args.scenes.split(","):
        row = bench_scene(name, args.size, args.directions, targets)
        out.append(row)
        chart(row, os.path.join(args.out, f"cpca_{name}.png"), targets)
        a = row["analysis"]
        print(f"\n== {row['scene']} ({row['object']}): {row['vertices']} vertices x "
              f"{row['directions']} directions, N = {row['N']}; bake {row['bake_seconds']:.1f} s,"
              f" fits {row['fit_seconds']:.1f} s; slope {a['slope']:.3f}, p* {a['p_star']:.1f}")
        for target, r in row["at_target"].items():
            print(f"   cost per vertex at shading error {target}:")
            for m, c in r["cost_per_vertex"].items():
                print(f"     {m:28s} {'not reached' if c is None else f'{c:8.1f}'}")
                csv_rows.append({"scene": row["scene"], "target_error": float(target),
                                 "method": m, "cost_per_vertex": c})
            for key, m in (("paper", PAPER), ("auto", AUTO)):
                g, s = r[f"{key}_vs_global_pca"], r[f"{key}_saving_vs_best_fixed"]
                print(f"     {m}: {g:.2f}x cheaper than global PCA (goal >= 8x), "
                      f"{100 * s:+.1f}% vs the best fixed count (goal >= +15%)"
                      if g and s is not None else f"     {m}: a method missed the target")
    with open(os.path.join(args.out, "cpca.json"), "w") as fh:
        json.dump(out, fh, indent=2)
    write_csv(os.path.join(args.out, "cpca.csv"), csv_rows)
    print(f"\nwrote {args.out}/cpca.json, cpca.csv, cpca_<scene>.png")


if __name__ == "__main__":
    main()
