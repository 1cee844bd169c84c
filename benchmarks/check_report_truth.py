"""Does the bake's report say what an independent Cycles bake of the scene says? (issue 55)

For two gallery scenes whose Light Paths differ from the bake's old fixed 2 bounces (the low-poly
sphere at 1 diffuse bounce, the mutual shadows at 3), bake with the balanced preset and its
default -1 bounces and Sun size (the scene's), with the report's truths at two held-out lights;
then, independently of the bake's settings and code path, read the bounces from the scene's own
``cycles.diffuse_bounces`` / ``max_bounces``, bake Cycles' DIFFUSE radiance of a Sun lamp at the
same lights with another seed, relight the bake with what the viewport shows
(``bundle.relight(source="viewport")``) and compute the relative RMSE over the texels Cycles
covers. Prints the report's figure next to the independent one, per object and light, and the
truths' own noise (the two seeds' distance / sqrt 2).

Usage: python benchmarks/check_report_truth.py [--resolution 96] [--samples 128]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--resolution", type=int, default=96)
    p.add_argument("--samples", type=int, default=128)
    args = p.parse_args(argv)

    import bpy

    import gallery_scenes as gs
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import bundle
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.base.jobs import run

    R = args.resolution
    for key, diffuse in (("lowpoly", 1), ("shadows", 3)):
        scene = gs.new_scene()
        objs = gs.SCENES[key].build(scene)
        scene.cycles.diffuse_bounces = diffuse
        s = tx.settings_from_preset("balanced", resolution=R)
        out = run(tx.bake_job(scene, objs, s, tempfile.mkdtemp(prefix="relight-chk-"), truth=2,
                              truth_samples=args.samples, compare=False, preview=False))
        reps = out.reports
        gt = reps[0]["ground_truth"]
        bounces = min(scene.cycles.diffuse_bounces, scene.cycles.max_bounces)
        print(f"== {key}: scene diffuse {scene.cycles.diffuse_bounces}, total "
              f"{scene.cycles.max_bounces}; the report: bounces {reps[0]['settings']['bounces']}"
              f" (from_scene {reps[0]['from_scene']}), headline {gt['headline_rel_rmse']:.4f} "
              f"of {gt['headline_of']}")
        loaded = [tx.load_bake(r["report"]) for r in reps]
        angle = reps[0]["settings"]["sun_angle"]
        for row_light in sorted({(r["azimuth"], r["elevation"]) for r in gt["lights"]}):
            az, el = row_light
            d = direction_from_az_el(az, el)
            mine = {}
            for seed in (7, 8):
                with EnvironmentBake(scene, objs, R, args.samples, bounces, (8, 16),
                                     mode="radiance", seed=seed,
                                     world_sampling="none") as session:
                    mine[seed] = session.bake_sun_all(d, 1.0, angle)
            for oi, (b, store, _) in enumerate(loaded):
                truth = mine[7][oi]
                m = truth.sum(-1) > 0
                got = np.asarray(bundle.relight(b, store, d, angle, 1.0, source="viewport"))
                indep = float(np.linalg.norm((got - truth)[m]) / np.linalg.norm(truth[m]))
                noise = float(np.linalg.norm((mine[8][oi] - truth)[m])
                              / np.linalg.norm(truth[m]) / np.sqrt(2))
                rep = next(r for r in gt["lights"] if r["object"] == b.name
                           and (r["azimuth"], r["elevation"]) == row_light)
                fig = rep.get(gt["headline_of"], rep["transport"])
                print(f"  {b.name:12s} az {az:5.0f} el {el:4.0f}: report {fig:.4f}, "
                      f"independent {indep:.4f} (truth noise {noise:.4f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
