"""Benchmark of the steerable core (a script, not a test).

Prints two things:

1. **Steering time**: one relighting = ``steer_images`` over N = 49 basis images of
   ``size x size`` texels, 3 channels, float32 (default 1024^2), best of ``--repeats`` runs, in ms.
   Also the same through a PCA factorisation with k eigen-images.
2. **Codec error table** on a synthetic but physically shaped stack: a periodic bumpy height
   field (random Gaussian bumps and dents, like the paper's test textures) shaded with
   Lambert's cosine and **hard shadows** (height-field ray marching) under M quadrature
   directions of the upper hemisphere; the response to each 2D basis light ``b_ij`` is the
   quadrature ``sum_m w_m b_ij(d_m) T[p, m]`` (``w_m`` solid angle, ``T`` = visibility x cos),
   times an RGB albedo texture. Errors are reported both on the basis images themselves and on
   *steered* images for 24 light directions (what a user sees; relative to the float64 steered
   result).

Usage::

    python benchmarks/bench_steerable.py [--size 1024] [--stack-size 128] [--json out.json]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from relightable_textures.lt_addon.sphere import hemisphere as hs
from relightable_textures.lt_addon.steerable import basis as sb
from relightable_textures.lt_addon.io import storage as sto


def time_steering(size: int, repeats: int, n: int = 49, k_pca: int = 16) -> dict:
    rng = np.random.default_rng(0)
    imgs = rng.standard_normal((n, size, size, 3), dtype=np.float32)
    c = sb.steering_coefficients(sb.paper_basis(), [0.2, -0.3])
    sb.steer_images(imgs, c)  # warm-up
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        sb.steer_images(imgs, c)
        times.append(time.perf_counter() - t)
    eig = imgs[:k_pca]  # stand-in eigen-images: the cost only depends on k
    ck = rng.standard_normal(k_pca)
    sb.steer_images(eig, ck)
    times_k = []
    for _ in range(repeats):
        t = time.perf_counter()
        sb.steer_images(eig, ck)
        times_k.append(time.perf_counter() - t)
    return {"size": size, "n_images": n, "channels": 3, "dtype": "float32",
            "bytes": int(imgs.nbytes), "best_ms": 1e3 * min(times),
            "median_ms": 1e3 * float(np.median(times)), "repeats": repeats,
            "pca_k": k_pca, "pca_best_ms": 1e3 * min(times_k)}


def bumpy_height_field(size: int, n_bumps: int = 40, seed: int = 1) -> np.ndarray:
    """Periodic height field on [0, 1)^2: random Gaussian bumps (+) and dents (-)."""
    rng = np.random.default_rng(seed)
    u = (np.arange(size) + 0.5) / size
    U, V = np.meshgrid(u, u, indexing="ij")
    h = np.zeros((size, size))
    for _ in range(n_bumps):
        cx, cy = rng.uniform(0, 1, 2)
        r = rng.uniform(0.03, 0.08)
        amp = rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0) * r
        dx = (U - cx + 0.5) % 1.0 - 0.5
        dy = (V - cy + 0.5) % 1.0 - 0.5
        h += amp * np.exp(-(dx * dx + dy * dy) / (2 * r * r))
    return h


def transport(height: np.ndarray, dirs: np.ndarray, steps: int = 48, reach: float = 0.25):
    """T[p, m] = V(p, d_m) max(0, n(p) . d_m) on a periodic height field (hard shadows)."""
    size = height.shape[0]
    gx, gy = np.gradient(height, 1.0 / size, edge_order=2)
    nrm = np.stack([-gx, -gy, np.ones_like(height)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    ii, jj = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    T = np.empty((size * size, dirs.shape[0]), dtype=np.float64)
    ts = np.linspace(reach / steps, reach, steps)
    for m, d in enumerate(dirs):
        cosv = np.clip(nrm @ d, 0.0, None)
        horiz = np.hypot(d[0], d[1])
        lit = cosv > 0
        if horiz > 1e-9 and d[2] < 0.999:
            slope = d[2] / horiz
            ux, uy = d[0] / horiz, d[1] / horiz
            for t in ts:  # march along the light's horizontal direction, compare heights
                si = (ii + np.rint(t * ux * size).astype(int)) % size
                sj = (jj + np.rint(t * uy * size).astype(int)) % size
                lit &= height[si, sj] <= height + slope * t
        T[:, m] = np.where(lit, cosv, 0.0).ravel()
    return T


def synthetic_basis_stack(size: int, n_radial: int = 12, n_azimuth: int = 32) -> np.ndarray:
    """Basis images (49, size, size, 3) float64 of the bumpy field under the 2D basis lights."""
    basis = sb.paper_basis()
    # quadrature of the hemisphere on the disk: midpoint in r^2 (equal area), uniform in phi
    r = np.sqrt((np.arange(n_radial) + 0.5) / n_radial)
    phi = (np.arange(n_azimuth) + 0.5) * 2 * np.pi / n_azimuth
    R, P = np.meshgrid(r, phi, indexing="ij")
    xy = np.stack([R * np.cos(P), R * np.sin(P)], -1).reshape(-1, 2)
    w = np.full(xy.shape[0], 2.0 * np.pi / xy.shape[0])  # equal solid angle cells
    dirs = hs.disk_to_hemisphere(xy)
    T = transport(bumpy_height_field(size), dirs)
    Bw = sb.basis_2d(basis, xy) * w[:, None]  # (M, 49)
    grey = (T @ Bw).T.reshape(49, size, size)
    u = (np.arange(size) + 0.5) / size
    U, V = np.meshgrid(u, u, indexing="ij")
    albedo = np.stack([0.7 + 0.2 * np.sin(2 * np.pi * U), 0.6 + 0.0 * U,
                       0.5 + 0.2 * np.cos(2 * np.pi * V)], -1) / np.pi
    return grey[..., None] * albedo[None]


def relight_coefficients() -> np.ndarray:
    """Steering coefficients (24, 49): azimuths every 15 deg, elevations 15..75 deg."""
    az = np.arange(24) * 15.0
    el = 15.0 + 60.0 * (np.arange(24) % 4) / 3.0
    return sb.steering_coefficients_for_direction(sb.paper_basis(),
                                                  hs.direction_from_az_el(az, el))


def codec_rows(stack: np.ndarray) -> list[dict]:
    coeffs = relight_coefficients()
    ks = (4, 6, 9, 12, 16, 20, 25, 30, 36, 42, 49)
    rows = sto.codec_table(stack, pca_ks=ks, steering=coeffs)
    peak = float(np.max(np.abs(coeffs @ stack.reshape(stack.shape[0], -1))))
    for r in rows:
        r["steered_max_over_peak"] = r["steered_max_abs"] / peak
    return rows


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024, help="texels per side for the timing")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--stack-size", type=int, default=128,
                    help="texels per side of the synthetic stack for the codec table")
    ap.add_argument("--json", metavar="PATH", help="also write the figures as JSON")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    timing = time_steering(args.size, args.repeats)
    print(f"Steering {timing['n_images']} basis images of {args.size}^2 x 3 float32 "
          f"({timing['bytes'] / 2**20:.0f} MiB): best {timing['best_ms']:.1f} ms, "
          f"median {timing['median_ms']:.1f} ms over {args.repeats}; "
          f"PCA k={timing['pca_k']}: best {timing['pca_best_ms']:.1f} ms")

    t1 = time.perf_counter()
    stack = synthetic_basis_stack(args.stack_size)
    t_stack = time.perf_counter() - t1
    rows = codec_rows(stack)
    print(f"\nCodec errors: synthetic stack of 49 basis images {args.stack_size}^2 x 3 "
          f"(bumpy height field, cos shading, hard shadows; built in {t_stack:.1f} s).")
    print("basis = error on the 49 basis images; steered = on 24 relit images "
          "(relative Frobenius / max abs relative to the steered peak)")
    hdr = (f"{'codec':<18}{'B/texel':>9}{'vs f32':>8}{'basis rel':>11}{'basis PSNR':>11}"
           f"{'steer rel':>11}{'steer max/peak':>15}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r['codec']:<18}{r['bytes_per_texel']:>9.1f}{r['ratio_vs_float32']:>8.3f}"
              f"{r['rel_fro']:>11.2e}{r['psnr_db']:>11.1f}{r['steered_rel_fro']:>11.2e}"
              f"{r['steered_max_over_peak']:>15.2e}")
    out = {"steering": timing, "stack": {"size": args.stack_size, "shape": list(stack.shape),
                                         "description": "bumpy height field, Lambert cos, hard "
                                         "shadows, 384-direction quadrature, RGB albedo"},
           "codecs": rows, "total_s": time.perf_counter() - t0}
    if args.json:
        from relightable_textures.lt_addon.io import atomic

        atomic.write_json(args.json, out, indent=1)
        print(f"\nwrote {args.json}")
    return out


if __name__ == "__main__":
    main()
