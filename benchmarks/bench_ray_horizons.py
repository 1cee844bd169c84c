"""Benchmark (issue 32): per-texel horizons found by rays against T's interpolated directions at
low suns. Direct light only, so nothing but the shadow model differs.

On a demo scene at ``--resolution``, against direct-only Cycles Sun truths (2 and 10 degrees,
``--spp``) at the four held-out lights, relative RMSE over the covered texels (albedo applied):

* *T*: the ray-traced transport at ``--counts`` directions relit by the product's linear kernel;
* *horizon A*: the horizon map at ``A`` azimuths (:mod:`lt_addon.transport.horizon_map`: the
  blocked interval per azimuth by rays, 8-bit, the sun's disc cut by its edges), as the
  horizon viewport shows it;
* *disc 64*: 64 hard suns over the disc by rays, averaged -- no table at all, the floor of any
  representation of hard-sun rays.

Per object too, where the scene has several (the statue and its ground).

Usage: python benchmarks/bench_ray_horizons.py [--scene bumps] [--resolution 256] [--spp 256]
           [--counts 1600] [--azimuths 32,64,128]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

LIGHTS = ((37.0, 10.0), (161.0, 30.0), (283.0, 55.0), (59.0, 80.0))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="bumps")
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--counts", default="1600")
    ap.add_argument("--azimuths", default="32,64,128")
    args = ap.parse_args(argv)

    from bench_transport_textures import build, truths as truth_bakes
    from relightable_textures.lt_addon.rays import engine as ray_engine, horizon
    from relightable_textures.lt_addon.transport import horizon_map as hmap
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.operators.bakes import ray_direct, texture_transport as tx
    from relightable_textures.operators.base import ray_scene
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.base.jobs import run

    assert LIGHTS == tx.TRUTH_LIGHTS
    scene, objs = build(args.scene, "demo")
    R = args.resolution
    t0 = time.perf_counter()
    got = truth_bakes(scene, objs, R, args.spp, bounces=0)
    truths = {ang: [got[ang][light] for light in LIGHTS] for ang in (2.0, 10.0)}
    print(f"truths: {time.perf_counter() - t0:.1f} s", flush=True)

    mapped = ray_direct.needs_normals(objs)
    with EnvironmentBake(scene, objs, R, 1, 0, (8, 16), mode="irradiance", seed=0,
                         world_sampling="none", passes="color") as s:
        albedos = s.bake_all(np.zeros((8, 16), np.float32))
        baked = s.bake_normals() if any(mapped) else [None] * len(objs)
    normals = [ray_direct.world_normals(o, n) if m else None
               for o, n, m in zip(objs, baked, mapped)]
    with ray_scene.RenderGeometry(scene) as dg:
        V, Tri, _ = ray_scene.casters(dg)
        occ = ray_engine.Occluder(V, Tri)
        recv = [ray_scene.receiver_points(o, dg, R, n) for o, n in zip(objs, normals)]
    P = sum(p.size for _, p in recv)
    print(f"{len(objs)} objects, {P} shading points, {len(Tri)} caster triangles", flush=True)

    def err(rows_of, ang, i, only=None):
        """Relative RMSE over all objects' (or object ``only``'s) covered texels for light i;
        rows_of(oi) -> (P,)."""
        num = den = 0.0
        for oi, (smp, _) in enumerate(recv):
            if only is not None and oi != only:
                continue
            truth = truths[ang][i][oi].reshape(R * R, -1)[smp.texel]
            alb = albedos[oi].reshape(R * R, -1)[smp.texel]
            got_ = rows_of(oi)[:, None] * alb
            num += float(np.sum((got_ - truth) ** 2))
            den += float(np.sum(truth ** 2))
        return np.sqrt(num / den)

    methods = {}
    for count in map(int, args.counts.split(",")):
        dset = tx.resolve_directions(scene, tx.TransportTextureSettings(
            directions=f"hemi:{count}:1.5", resolution=R))[0]
        t0 = time.perf_counter()
        Ts = [np.concatenate([direct_rows(occ, p, dset.directions[a:a + 64])
                              for a in range(0, dset.size, 64)]) for _, p in recv]
        secs = time.perf_counter() - t0
        print(f"T at hemi:{count}:1.5: {secs:.1f} s, {count * P / 1e6:.1f} M rays", flush=True)

        def t_relight(oi, d, ang, Ts=Ts, dset=dset):
            idx, w = tt.sun_weights(dset, d, ang, "linear")
            return w @ Ts[oi][idx].astype(np.float64)
        methods[f"T {count} directions"] = t_relight
    for A in map(int, args.azimuths.split(",")):
        t0 = time.perf_counter()
        r0 = occ.rays
        Hs = [hmap.from_points(horizon.horizons(occ, p, azimuths=A), smp.texel, R, p.Ns)
              for smp, p in recv]
        print(f"horizons, {A} azimuths: {time.perf_counter() - t0:.1f} s, "
              f"{(occ.rays - r0) / 1e6:.1f} M rays ({(occ.rays - r0) / P:.0f} per point)",
              flush=True)
        methods[f"horizon map, {A} azimuths"] = (
            lambda oi, d, ang, Hs=Hs: Hs[oi].direct(d, ang).reshape(-1)[recv[oi][0].texel])

    def disc_rays(oi, d, ang):
        pts = tt._disc_points(d, np.radians(ang) / 2, 64)
        return direct_rows(occ, recv[oi][1], pts).astype(np.float64).mean(0)
    methods["64 hard suns by rays (no table)"] = disc_rays

    print("\nrelative RMSE against direct-only Cycles Sun truths, covered texels; elevation "
          "10 / 30 / 55 / 80 deg")
    for ang in (2.0, 10.0):
        for name, fn in methods.items():
            for only in [None] + (list(range(len(objs))) if len(objs) > 1 else []):
                errs = [err(lambda oi: fn(oi, direction_from_az_el(az, el), ang), ang, i, only)
                        for i, (az, el) in enumerate(LIGHTS)]
                who = "" if only is None else f" [{objs[only].name}]"
                print(f"{ang:4g} deg  {name + who:44s} " + " / ".join(f"{e:.4f}" for e in errs),
                      flush=True)


if __name__ == "__main__":
    main()
