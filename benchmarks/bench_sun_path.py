"""Benchmark: an animated Sun over a day, with and without directions along its path (issue 32).

The bumps demo at ``--resolution`` with a Sun keyframed over a day (azimuth 80 -> 280 degrees,
elevation -3 -> 50 -> -3 over 49 frames). The balanced preset's bake, with ``--sun-path auto``
(directions every ``--step`` degrees along the path on top of the preset's set) and ``off``, is
relit for a 2-degree Sun at points of the path at 5-10 degrees of elevation and compared with
Cycles' radiance bakes of those Suns (the scene's 2 bounces, ``--truth-samples``). Prints the
relative RMSE per light and combined (``sqrt(mean(rel^2))``), bake time and direction counts.

Usage: python benchmarks/bench_sun_path.py [--resolution 256] [--step 0.5] [--out out/bench]
           [--preset balanced] [--set '{"horizon_resolution": 256}'] [--modes off,auto]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--step", type=float, default=0.5)
    ap.add_argument("--truth-samples", type=int, default=256)
    ap.add_argument("--out", default="out/bench")
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--set", default="{}", help="settings over the preset's, as JSON")
    ap.add_argument("--modes", default="off,auto",
                    help="which bakes: off (the preset's set alone), auto (with the path)")
    args = ap.parse_args(argv)
    overrides = json.loads(args.set)

    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport.bundle import relight, rel_rmse, viewport_direct
    from relightable_textures.lt_addon.transport.gathered_texture import indirect_images
    from relightable_textures.lt_addon.transport import sparse_tables as sp
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "tests", "blender"))
    from test_sun_path import _animate_sun

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("bumps", scene, "demo")
    obj = bpy.data.objects["Bumps"]
    _animate_sun(scene)
    R = args.resolution
    # lights on the path at elevations 5..10 degrees, morning and evening
    lights = []
    for el in (5.0, 7.5, 10.0):
        t = math.asin((el + 3) / 53) / math.pi
        lights += [(80 + 200 * t, el), (80 + 200 * (1 - t), el)]
    t0 = time.perf_counter()
    truths = run(tx.truth_bakes(scene, [obj], lights, 2.0, 2, args.truth_samples, R))
    print(f"truths: {len(lights)} lights, {args.truth_samples} spp, "
          f"{time.perf_counter() - t0:.1f} s", flush=True)
    rows = []
    import tempfile
    with tempfile.TemporaryDirectory() as folder:
        for mode in args.modes.split(","):
            # the preset as a user bakes it: PCA model, viewport auto (so the bake also finds
            # the per-texel horizons its horizon viewport shows)
            s = tx.settings_from_preset(args.preset, resolution=R, sun_path=mode,
                                        sun_path_step=args.step, **overrides)
            t0 = time.perf_counter()
            res = run(tx.bake_transport_textures(scene, [obj], s, os.path.join(folder, mode),
                                                 resume=False))
            bake_s = time.perf_counter() - t0
            b = res.objects[0]
            tables = sp.cached_tables(b.store.directions, sp.TABLE_SIZE, 2.0, "linear")
            per, per_view, per_hor = [], [], []
            for az, el in lights:
                d = direction_from_az_el(az, el)
                truth = truths[(az, el)][0]
                per.append(rel_rmse(relight(b, b.store, d, 2.0, source="transport"), truth))
                ind = (0.0 if b.indirect is None else
                       tx._upsample(indirect_images(b.indirect, d, 2.0), R))
                view = viewport_direct(b.store, tables, d)[..., None] * b.albedo
                per_view.append(rel_rmse(view + ind, truth))
                if b.found_horizon is not None:   # the horizon viewport's direct light
                    hor = b.found_horizon.direct(d, 2.0)[..., None] * b.albedo
                    per_hor.append(rel_rmse(hor + ind, truth))
            row = {"sun_path": mode, "directions": b.store.directions.size,
                   "path": (res.direct or {}).get("direction_set", {}).get("sun_path"),
                   "bake_seconds": round(bake_s, 2),
                   "viewport_fits": sp.choose_viewport("auto", b.store.directions.size, R)[0],
                   "rel_rmse_T": [round(e, 4) for e in per],
                   "rel_rmse_viewport": [round(e, 4) for e in per_view],
                   "combined_T": round(float(np.sqrt(np.mean(np.square(per)))), 4),
                   "combined_viewport": round(float(np.sqrt(np.mean(np.square(per_view)))), 4),
                   "viewport_chosen": (b.viewport or {}).get("shows"),
                   "rel_rmse_horizons": [round(e, 4) for e in per_hor],
                   "combined_horizons": (round(float(np.sqrt(np.mean(np.square(per_hor)))), 4)
                                         if per_hor else None),
                   "indirect": (b.indirect.settings.get("method", "steerable")
                                if b.indirect is not None else None)}
            rows.append(row)
            print(json.dumps(row), flush=True)
            b.store.abort()
    print("| sun path | directions | bake | 2° Sun at 5-10° on the path: from T | T through "
          "sparse tables | per-texel horizons | the viewport auto chose |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        hor = "–" if r["combined_horizons"] is None else f"{r['combined_horizons']:.3f}"
        print(f"| {r['sun_path']} | {r['directions']} | {r['bake_seconds']:.1f} s | "
              f"{r['combined_T']:.3f} | {r['combined_viewport']:.3f} | {hor} | "
              f"{r['viewport_chosen']} |")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "sun_path.json"), "w") as fh:
        json.dump({"date": time.strftime("%Y-%m-%d"), "preset": args.preset,
                   "settings": overrides, "lights": lights, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
