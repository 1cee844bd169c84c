"""Benchmark (issue 13): can a per-texel horizon model relight low suns better than the linear
kernel over the same hard-sun bakes? Direct light only, so nothing but the shadow model differs.

Bakes the demo ``bumps`` patch's direct transport T (``--directions``, 1 spp, ``--resolution``)
and direct-only Cycles Sun truths (2 and 10 degrees, ``--spp``) at the four held-out lights, then
relights each light three ways and prints the relative RMSE ``||relit - truth|| / ||truth||``
(texels and RGB, albedo applied):

* kernel: :func:`lt_addon.transport.texture.sun_weights` (linear, averaged over the sun disc),
  the product's relight;
* factored: the kernel's interpolated visibility times the exact cosine term ``a . w``;
* horizon K: per texel, ``a`` fitted by least squares over the lit samples (T = a . w there),
  and per azimuth sector one horizon elevation (the split of lit and shadowed samples with the
  fewest misclassified), interpolated between sector centres; the sun's visibility is a linear
  step of the sun's width across that horizon.

Also, for the viewport preview, what the coefficient tables cost at low suns: a PCA of T (96
components, as the balanced preset) relit through tables of 32, 64 and 128 texels across the
hemisphere disk (bilinear, as the node tree samples them) against the same PCA relit directly.

Usage: python benchmarks/bench_horizon_model.py [--directions hemi:400:1.5] [--resolution 256]
           [--spp 64] [--sectors 16,32,64]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

LIGHTS = ((37.0, 10.0), (161.0, 30.0), (283.0, 55.0), (59.0, 80.0))


def fit_horizons(T: np.ndarray, D: np.ndarray, K: int):
    """``a`` (P, 3) and horizons (K, P) in radians from T (S, P) and directions D (S, 3)."""
    S, P = T.shape
    lit = T > 1e-6
    A = (lit.T.astype(np.float64) @ np.einsum("si,sj->sij", D, D).reshape(S, 9)).reshape(P, 3, 3)
    b = (T * lit).T.astype(np.float64) @ D
    a = np.linalg.solve(A + 1e-6 * np.eye(3), b[..., None])[..., 0]   # 3x3, regularised
    az = np.arctan2(D[:, 1], D[:, 0]) % (2 * np.pi)
    el = np.arcsin(np.clip(D[:, 2], -1.0, 1.0))
    facing = (D @ a.T) > 1e-6
    sector = np.floor(az / (2 * np.pi) * K).astype(int) % K
    H = np.zeros((K, P))
    for k in range(K):
        idx = np.nonzero(sector == k)[0]
        idx = idx[np.argsort(el[idx])]
        e, L, F = el[idx], lit[idx], facing[idx]
        lit_below = np.vstack([np.zeros((1, P)), np.cumsum(L, 0)])
        shadow_above = np.vstack([np.cumsum((F & ~L)[::-1], 0)[::-1], np.zeros((1, P))])
        j = np.argmin(lit_below + shadow_above, 0)
        edges = np.concatenate([[-0.05], 0.5 * (e[1:] + e[:-1]), [np.pi / 2 + 0.05]])
        H[k] = edges[j]
    return a, H


def horizon_relight(a, H, d, sun_angle_deg):
    K = H.shape[0]
    x = (np.arctan2(d[1], d[0]) % (2 * np.pi)) / (2 * np.pi) * K - 0.5
    k0, f = int(np.floor(x)) % K, x - np.floor(x)
    h = (1 - f) * H[k0] + f * H[(k0 + 1) % K]
    vis = np.clip((np.arcsin(d[2]) - h) / max(np.radians(sun_angle_deg), 1e-6) + 0.5, 0, 1)
    return vis * np.maximum(a @ d, 0.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--directions", default="hemi:400:1.5")
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--sectors", default="16,32,64")
    args = ap.parse_args(argv)

    from bench_transport_textures import build, truths as truth_bakes
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    assert LIGHTS == tx.TRUTH_LIGHTS
    scene, objs = build("bumps", "demo")
    R = args.resolution
    got = truth_bakes(scene, objs, R, args.spp, bounces=0)     # direct light only
    truths = {ang: [got[ang][light][0] for light in LIGHTS] for ang in (2.0, 10.0)}
    st = tx.TransportTextureSettings(directions=args.directions, resolution=R, bounces=0,
                                     model="none")
    t0 = time.perf_counter()
    res = run(tx.bake_transport_textures(scene, objs, st, tempfile.mkdtemp(), resume=False))
    b = res.objects[0]
    store = b.store or tt.TransportStore.open(b.store_path)
    print(f"T: {args.directions} at {R}^2 in {time.perf_counter() - t0:.1f} s", flush=True)
    T = np.asarray(store.array, np.float32)
    D = store.directions.directions
    lit = (T > 1e-6).astype(np.float32)
    models = {}
    for K in map(int, args.sectors.split(",")):
        t0 = time.perf_counter()
        a, H = fit_horizons(T, D, K)
        models[K] = (a, H)
        print(f"horizon fit, {K} sectors: {time.perf_counter() - t0:.1f} s")
    a = models[next(iter(models))][0]
    print("\nrelative RMSE against the direct-only Cycles Sun (albedo applied)")
    print("sun   el  | kernel  factored | " + "  ".join(f"horizon {K:2d}" for K in models))
    for ang in (2.0, 10.0):
        for i, (az, el) in enumerate(LIGHTS):
            d = direction_from_az_el(az, el)
            truth = truths[ang][i]
            n = np.linalg.norm(truth)
            idx, w = tt.sun_weights(store.directions, d, ang, "linear")
            err = lambda irr: np.linalg.norm(irr.reshape(R, R)[..., None] * b.albedo - truth) / n
            kernel = err(w @ T[idx])
            factored = err((w @ lit[idx]) * np.maximum(a @ d, 0.0))
            hor = [err(horizon_relight(*models[K], d, ang)) for K in models]
            print(f"{ang:4.0f} {el:4.0f}  | {kernel:.4f}  {factored:.4f}   | "
                  + "  ".join(f"{h:10.4f}" for h in hor), flush=True)

    pca = tt.fit_texture_pca(store, k=96)
    U = pca.U.astype(np.float64)
    print("\nthe preview's coefficient tables (PCA 96): relative RMSE, same truths")
    print("sun   el  | PCA direct | table 32  table 64  table 128")
    tables = {}
    for ang in (2.0, 10.0):
        for D in (32, 64, 128):
            t0 = time.perf_counter()
            tables[ang, D] = tt.coefficient_tables(pca.V, store.directions, D, ang, "linear")
            print(f"  tabulating {D}^2 for a {ang:g} deg sun: {time.perf_counter() - t0:.2f} s")
        for i, (az, el) in enumerate(LIGHTS):
            d = direction_from_az_el(az, el)
            truth = truths[ang][i]
            n = np.linalg.norm(truth)
            err = lambda c: np.linalg.norm((c @ U).reshape(R, R)[..., None] * b.albedo
                                           - truth) / n
            idx, w = tt.sun_weights(store.directions, d, ang, "linear")
            direct = err(w @ pca.V[idx].astype(np.float64))
            via = [err(tt.table_lookup(tables[ang, D], d)) for D in (32, 64, 128)]
            print(f"{ang:4.0f} {el:4.0f}  | {direct:.4f}     | "
                  + "  ".join(f"{x:.4f}" for x in via), flush=True)


if __name__ == "__main__":
    main()
