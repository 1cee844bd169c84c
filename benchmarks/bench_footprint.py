"""Benchmark: each texel's footprint (lt_addon/rays/footprint.py) against Cycles' converged bake.

The brick relief of tests/blender/test_footprint.py at ``--resolution`` (128^2 by default), 12
hard suns (azimuths 0-330 degrees in steps of 30, elevations alternating 2, 5 and 20 degrees),
the DIFFUSE direct pass in irradiance. Per sun the relative L2 distance from Cycles'
``--reference``-spp bake (1024 by default) of: the centre ray alone (a 1-spp bake), the
footprint with one lattice for every texel (before 2026-12-06), the footprint with each texel's
own shift of it (now), and Cycles' own 16-spp bake; then the worst and mean ratio to the 16-spp
distance over the suns where the bakes differ at all, and the rays. The jitter box is this Blender's
(``footprint.jitter_box(bpy.app.version)``): run it with each release's Python to compare.

Usage: python benchmarks/bench_footprint.py [--resolution 128] [--reference 1024] [--json FILE]
(any Python with bpy and this package importable, e.g. the matrix's suite venvs).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                "tests", "blender"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--reference", type=int, default=1024)
    ap.add_argument("--json", default=None)
    ap.add_argument("--cycles-cache", default=None,
                    help="an .npz to keep Cycles' two bakes in (read when it exists: for "
                         "sweeps of the pattern; it must be this Blender's)")
    args = ap.parse_args(argv)

    import bpy

    from relightable_textures.lt_addon.rays import footprint as F
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.operators.base import ray_scene
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from test_footprint import relief

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    obj = relief(scene)
    R = args.resolution
    suns = [(30.0 * i, (2.0, 5.0, 20.0)[i % 3]) for i in range(12)]
    dirs = np.array([direction_from_az_el(a, e) for a, e in suns])
    t0 = time.perf_counter()
    cyc = {}
    key = f"{bpy.app.version_string}/{R}/{args.reference}"
    if args.cycles_cache and os.path.exists(args.cycles_cache):
        with np.load(args.cycles_cache) as z:
            if str(z["key"]) == key:
                cyc = {16: z["c16"], args.reference: z["ref"]}
    for spp in (16, args.reference):
        if spp in cyc:
            continue
        with EnvironmentBake(scene, obj, R, spp, 0, (8, 16), mode="irradiance", seed=1,
                             world_sampling="none", passes="direct") as session:
            cyc[spp] = np.array([session.bake_sun(d, 1.0, 0.0)[..., 0].reshape(-1)
                                 for d in dirs])
    if args.cycles_cache:
        np.savez(args.cycles_cache, key=key, c16=cyc[16], ref=cyc[args.reference])
    t_cycles = time.perf_counter() - t0
    shift = F.texel_shift
    rows, rays, secs = {}, {}, {}
    for name in ("centre", "one lattice", "shifted"):
        F.texel_shift = ((lambda t: np.full((len(t), 2), 0.5 / F.SAMPLES))
                         if name == "one lattice" else shift)
        with ray_scene.RenderGeometry(scene) as depsgraph:
            V, T, _ = ray_scene.casters(depsgraph)
            occluder = Occluder(V, T)
            smp, pts = ray_scene.receiver_points(obj, depsgraph, R,
                                                 footprint=name != "centre")
        t1 = time.perf_counter()
        rows[name] = direct_rows(occluder, pts, dirs)
        secs[name] = time.perf_counter() - t1
        rays[name] = len(smp.texel) * len(dirs) + (pts.footprint.rays if pts.footprint else 0)
    F.texel_shift = shift
    ref = cyc[args.reference][:, smp.texel]

    def dist(x, s):
        return float(np.linalg.norm(x - ref[s]) / np.linalg.norm(ref[s]))

    table = []
    print(f"bpy {bpy.app.version_string}: jitter box "
          f"{F.jitter_box(bpy.app.version)} texels, relief {R}^2, {args.reference}-spp reference")
    print(f"{'sun':>12} {'centre':>8} {'one lattice':>12} {'shifted':>8} {'Cycles 16':>10}")
    for s, sun in enumerate(suns):
        row = {"sun": sun, **{k: dist(v[s], s) for k, v in rows.items()},
               "cycles16": dist(cyc[16][s, smp.texel], s)}
        table.append(row)
        print(f"{str(sun):>12} {row['centre']:8.4f} {row['one lattice']:12.4f} "
              f"{row['shifted']:8.4f} {row['cycles16']:10.4f}")
    summary = {}
    # a sun whose every bake agrees (no jitter-dependent texel: 16 spp within 1e-3) has no
    # ratio to speak of
    judged = [row for row in table if row["cycles16"] > 1e-3]
    for k in ("centre", "one lattice", "shifted"):
        r = np.array([row[k] / row["cycles16"] for row in judged])
        summary[k] = {"worst_ratio": float(r.max()), "mean_ratio": float(r.mean()),
                      "rays": int(rays[k]), "seconds": secs[k]}
        print(f"{k:>12}: worst {r.max():.2f}x, mean {r.mean():.2f}x Cycles' 16-spp distance "
              f"({len(judged)} suns); "
              f"{rays[k]:,} rays, {secs[k]:.2f} s")
    print(f"Cycles' two bakes: {t_cycles:.1f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"bpy": bpy.app.version_string, "resolution": R,
                       "reference_spp": args.reference, "suns": table, "summary": summary,
                       "cycles_seconds": t_cycles}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
