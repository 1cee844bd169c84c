"""Benchmark: what one sun direction costs by rays against one Cycles bake call, in the same run
(issue 32), and how far the ray bake is from Cycles' bake of the same hard sun.

Per scene (bumps: a smooth height field; statue: Suzanne and its ground, baked together) at
``--resolution``: the same ``--directions`` are baked by Cycles calls (1-spp hard suns, one call
per direction: what ``--direct cycles`` does) and by rays (``--direct rays``: the scene read once,
then batched occlusion rays). Prints milliseconds per direction for both, their ratio, rays per
second, and the relative difference of the two T over the covered texels (direction by
direction: median and worst).

Usage: python benchmarks/bench_ray_direct.py [--resolution 256] [--directions 64]
           [--scenes bumps,statue] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

SCENES = {"bumps": ["Bumps"], "statue": ["Statue", "Ground"]}


def measure(name, R, n_dirs):
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.lt_addon.transport.texture import parse_directions
    from relightable_textures.operators.base import ray_scene
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build(name, scene, "demo")
    objects = [bpy.data.objects[o] for o in SCENES[name]]
    D = parse_directions(f"hemi:{n_dirs}:1.5").directions
    with EnvironmentBake(scene, objects, R, 1, 0, (8, 16), mode="irradiance", seed=0,
                         world_sampling="none", passes="direct") as s:
        s.bake_sun_all(D[0], 1.0, 0.0)                     # warm-up: kernels, first sync
        t0 = time.perf_counter()
        cyc = [s.bake_sun_all(d, 1.0, 0.0) for d in D]
        cycles_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    with ray_scene.RenderGeometry(scene) as depsgraph:
        V, T, _ = ray_scene.casters(depsgraph)
        occ = Occluder(V, T)
        pts = [ray_scene.receiver_points(o, depsgraph, R) for o in objects]
    scene_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    rows = [direct_rows(occ, p, D) for _, p in pts]
    rays_s = time.perf_counter() - t0
    diffs = []
    for oi, (smp, _) in enumerate(pts):
        for j in range(len(D)):
            c = cyc[j][oi][..., 0].reshape(-1)[smp.texel]
            n = np.linalg.norm(c)
            if n > 0:
                diffs.append(float(np.linalg.norm(rows[oi][j] - c) / n))
    return {"scene": name, "objects": SCENES[name], "resolution": R, "directions": len(D),
            "texels": int(sum(smp.size for smp, _ in pts)), "triangles": int(len(T)),
            "cycles_ms_per_direction": round(1000 * cycles_s / len(D), 2),
            "rays_ms_per_direction": round(1000 * rays_s / len(D), 2),
            "rays_scene_read_s": round(scene_s, 3),
            "speedup": round(cycles_s / (rays_s + scene_s), 2),
            "rays_per_second": round(occ.rays / rays_s),
            "rel_diff_median": round(float(np.median(diffs)), 5),
            "rel_diff_max": round(float(np.max(diffs)), 5)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--directions", type=int, default=64)
    ap.add_argument("--scenes", default="bumps,statue")
    ap.add_argument("--out", default="out/bench")
    args = ap.parse_args(argv)
    rows = [measure(s, args.resolution, args.directions) for s in args.scenes.split(",")]
    print("| scene | texels | triangles | Cycles call, ms/direction | rays, ms/direction | "
          "scene read (rays) | speed-up | rays/s | T rays vs Cycles (median / worst) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} {r['resolution']}² | {r['texels']} | {r['triangles']} | "
              f"{r['cycles_ms_per_direction']} | {r['rays_ms_per_direction']} | "
              f"{r['rays_scene_read_s']} s | {r['speedup']}× | {r['rays_per_second']:,} | "
              f"{r['rel_diff_median']} / {r['rel_diff_max']} |")
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "ray_direct.json")
    with open(path, "w") as fh:
        json.dump({"date": time.strftime("%Y-%m-%d"), "rows": rows}, fh, indent=1)
    print(f"written: {path}")


if __name__ == "__main__":
    main()
