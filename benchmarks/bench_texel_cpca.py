"""Mahajan et al. 2007's figures on texel transport (issue 33): the dimensionality of growing
texel blocks and its log-log slope, the optimal cluster size it predicts, and the measured cost
of fixed-count CPCA against global PCA, on a transport texture of at least 65k texels (the
paper's regime; the demo meshes of `bench_cpca.py` have 1.1k-4.4k vertices).

Bakes T of the bumps demo scene at 256^2 (65,536 texels; direct transport, the balanced
preset's directions, no model, no truths), then on T (texels x directions, float32):

* ``dimensionality.analyse`` over square texel blocks around ``--seeds`` random texels: the
  slope, mu, the global dimension N, the optimal patch size p* and the cluster count V / p*;
* ``cluster_analysis.cost_curve``: fixed-count CPCA at a per-cluster tolerance over counts
  around the prediction (1 = global PCA), each with its cost per texel (Mahajan's
  ``sum n_i (p_i + N) / V``) and its relative RMS error of T.

Prints Markdown; ``--out`` writes the JSON. Slow (minutes): in `make bench`, not in the tests.

Usage: python benchmarks/bench_texel_cpca.py [--resolution 256] [--directions hemi:1600:1.5]
    [--tol 0.01] [--seeds 4] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

BIN = os.path.dirname(sys.executable)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--directions", default="hemi:1600:1.5")
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--counts", default="")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    sys.path.insert(0, os.path.dirname(ROOT))
    from relightable_textures.lt_addon.transport import cluster_analysis as ca
    from relightable_textures.lt_addon.transport import dimensionality as dim
    from relightable_textures.lt_addon.transport.cpca import global_dimension

    work = tempfile.mkdtemp(prefix="bench-texel-cpca-")
    blend = os.path.join(work, "bumps.blend")
    subprocess.run([os.path.join(BIN, "relight"), "scene", "bumps", "--size", "demo", "--out",
                    blend], check=True, capture_output=True)
    t0 = time.perf_counter()
    p = subprocess.run([os.path.join(BIN, "relight"), "bake-textures", blend, "--object",
                        "Bumps", "--preset", "balanced", "--directions", args.directions,
                        "--resolution", str(args.resolution), "--bounces", "0", "--model",
                        "none", "--no-compare", "--out", os.path.join(work, "bk"),
                        "--device", "cpu"], capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(p.stderr[-3000:])
    bake_s = time.perf_counter() - t0
    R = args.resolution
    T = np.load(os.path.join(work, "bk", "Bumps_transport_texture.npy"))   # (S, R*R) half
    T = np.ascontiguousarray(T.T, dtype=np.float32)                          # (V texels, S)
    V, S = T.shape
    rng = np.random.default_rng(0)
    seeds = [tuple(int(v) for v in rng.integers(R // 8, R - R // 8, 2))
             for _ in range(args.seeds)]
    halves = [h for h in (1, 2, 4, 8, 16, 32, 64) if 2 * h + 1 <= R]
    t1 = time.perf_counter()
    N = global_dimension(T)
    rep = dim.analyse(T, seeds, grid_shape=(R, R), halves=halves, N=N, min_size=25,
                      max_dims=int(0.8 * S))
    dim_s = time.perf_counter() - t1
    pred = rep.get("recommended_clusters", 1)
    counts = ([int(c) for c in args.counts.split(",")] if args.counts else
              sorted({1, max(2, pred // 4), max(2, pred // 2), pred, pred * 2, pred * 4}))
    counts = [c for c in counts if 1 <= c <= V]
    rows = ca.cost_curve(T, counts, args.tol, N,
                         progress=lambda m: print(m, file=sys.stderr, flush=True))
    glob = next(r for r in rows if r["clusters_requested"] == 1)
    best = min(rows, key=lambda r: r["cost_per_vertex"])
    print(f"Measured {time.strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} cores: bumps demo "
          f"T at {R}^2 ({V} texels) x {S} directions ({args.directions}), direct transport; "
          f"bake {bake_s:.0f} s, dimensionality {dim_s:.0f} s\n")
    print(f"- dimensionality of texel blocks (99.95 % energy) around {len(seeds)} texels: "
          f"log-log slope {rep['slope']:.3f}, mu {rep.get('mu', float('nan')):.3f}, global "
          f"dimension N {N}, optimal cluster size p* {rep.get('p_star', float('nan')):.0f} "
          f"texels, predicted clusters V / p* = {pred}")
    for c in rep["curves"]:
        print(f"  - seed {c['seed']}: sizes {c['sizes']} -> dims {c['dims']} "
              f"(slope {c['slope']:.3f})")
    print(f"\n| clusters | cost per texel (multiply-adds) | relative RMS error of T | "
          f"seconds |\n|---|---|---|---|")
    for r in rows:
        print(f"| {r['clusters']} (asked {r['clusters_requested']}) | "
              f"{r['cost_per_vertex']:.1f} | {r['relative_rms_error']:.4f} | {r['seconds']:.0f} |")
    print(f"\nglobal PCA / cheapest CPCA at tolerance {args.tol}: "
          f"{glob['cost_per_vertex'] / best['cost_per_vertex']:.2f}x "
          f"({best['clusters']} clusters; errors {glob['relative_rms_error']:.4f} vs "
          f"{best['relative_rms_error']:.4f})")
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "texel_cpca.json"), "w") as fh:
            json.dump({"analysis": rep, "cost_curve": rows, "resolution": R,
                       "directions": args.directions, "tol": args.tol}, fh, indent=1,
                      default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
