"""Benchmark (issue 13): what limits the transport bake at a low sun -- the directions, or the
1-spp hard-sun bakes themselves? Direct light only, so nothing but the sampling differs.

On the demo ``bumps`` patch at ``--resolution``, against direct-only Cycles Sun truths (2 and 10
degrees, ``--spp``, two seeds for the truths' own noise) at the four held-out lights:

* *disc*: N hard suns spread evenly over the sun's disc (1 spp each, sunflower), averaged --
  no interpolation at all, the best any set of hard-sun bakes can do there (N = 1, 16, 64);
* *soft 1 spp*: one bake under the soft Sun itself at 1 spp (Cycles samples the disc once per
  texel: the same count as one hard sun, spent on noise instead);
* *T*: the transport store at ``--counts`` directions relit by the product's kernel.

Usage: python benchmarks/bench_low_sun_floor.py [--resolution 256] [--spp 256]
           [--counts 400,1600]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

LIGHTS = ((37.0, 10.0), (161.0, 30.0), (283.0, 55.0), (59.0, 80.0))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--counts", default="400,1600")
    args = ap.parse_args(argv)

    from bench_transport_textures import build, truths as truth_bakes
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.base.jobs import run

    assert LIGHTS == tx.TRUTH_LIGHTS
    scene, objs = build("bumps", "demo")
    R = args.resolution
    truths = {}
    for seed in (1, 2):     # direct light only; two seeds for the truths' own noise
        got = truth_bakes(scene, objs, R, args.spp, bounces=0, seed=seed)
        for ang in (2.0, 10.0):
            truths[ang, seed] = [got[ang][light][0] for light in LIGHTS]
    rel = tx.rel_rmse

    def line(label, errs):
        comb = float(np.sqrt(np.mean(np.square(errs))))
        print(f"{label:44s} " + " ".join(f"{e:.4f}" for e in errs) + f" | {comb:.4f}",
              flush=True)

    print("\nrelative RMSE against the direct-only Cycles Sun (albedo applied), lights at "
          "elevation 10 / 30 / 55 / 80 deg | combined")
    for ang in (2.0, 10.0):
        line(f"{ang:g} deg: one truth's own noise", [
            rel(truths[ang, 1][i], truths[ang, 2][i]) / np.sqrt(2) for i in range(4)])
    results = {}
    for spec in [f"hemi:{c}:1.5" for c in args.counts.split(",")]:
        st = tx.TransportTextureSettings(directions=spec, resolution=R, bounces=0, model="none")
        t0 = time.perf_counter()
        res = run(tx.bake_transport_textures(scene, objs, st, tempfile.mkdtemp(),
                                             resume=False))
        b = res.objects[0]
        secs = time.perf_counter() - t0
        for ang in (2.0, 10.0):
            results[spec, ang] = [
                rel(tx.relight(b, b.store, direction_from_az_el(az, el), ang), truths[ang, 1][i])
                for i, (az, el) in enumerate(LIGHTS)]
        albedo = b.albedo
        b.store.abort()
        print(f"T at {spec}: {secs:.1f} s", flush=True)
    with EnvironmentBake(scene, objs, R, 1, 0, (8, 16), mode="irradiance", seed=0,
                         world_sampling="none", passes="direct") as s:
        for ang in (2.0, 10.0):
            for n in (1, 16, 64):
                errs = []
                for i, (az, el) in enumerate(LIGHTS):
                    pts = tt._disc_points(direction_from_az_el(az, el), np.radians(ang) / 2, n)
                    acc = sum(s.bake_sun(p, 1.0, 0.0) for p in pts if p[2] > 0) / n
                    errs.append(rel(acc * albedo, truths[ang, 1][i]))
                line(f"{ang:g} deg: disc of {n} hard suns, 1 spp each", errs)
            line(f"{ang:g} deg: the soft Sun itself at 1 spp", [
                rel(s.bake_sun(direction_from_az_el(az, el), 1.0, ang) * albedo,
                    truths[ang, 1][i]) for i, (az, el) in enumerate(LIGHTS)])
            for spec in [f"hemi:{c}:1.5" for c in args.counts.split(",")]:
                line(f"{ang:g} deg: T at {spec}, linear kernel", results[spec, ang])


if __name__ == "__main__":
    main()
