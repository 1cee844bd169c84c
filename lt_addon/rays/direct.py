"""Direct transport by rays: ``T[s, p] = cos(p, w_s) * V(p, w_s)`` for every direction of a set.

``T = cos * V / pi``: the same quantity as one 1-spp Cycles irradiance bake of the DIFFUSE direct pass under a hard Sun
of strength 1 from ``w_s`` (:mod:`..transport.texture`), at the texel-centre sample points of
:mod:`.texels`. Rays for all points and all directions are cast in batches (:mod:`.engine`).
"""

from __future__ import annotations

import time

import numpy as np

from .shading import ShadingPoints, cosine, shadow_origins


def direct_rows(occluder, points: ShadingPoints, directions) -> np.ndarray:
    """Direct transport (S, P) float32 for unit ``directions`` (S, 3): cosine x visibility / pi
    (Cycles' diffuse pass without its colour: a white Lambertian surface's ``E / pi`` under a
    sun of unit normal irradiance; checked against Cycles to float precision on the bumps).
    One engine call per direction (its threads share the rays)."""
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    out = np.zeros((len(D), points.size), np.float32)
    for s, L in enumerate(D):
        cos = cosine(points, L)
        lit = np.nonzero(cos > 0)[0]
        if not lit.size:
            continue
        out[s, lit] = cos[lit] / np.pi
        if lit.size > points.size // 4:   # every point's origin, then the lit ones': faster
            origins = np.take(shadow_origins(points, L), lit, axis=0)
        else:                             # (the same bits: shadow_origins is per point)
            origins = shadow_origins(points, L, lit)
        # one engine call per direction, its direction given once: no per-ray copy of it (the
        # rays of 64 directions in one call held ~400 MB at 512^2, faulted in afresh each call)
        blocked = occluder.occluded(origins, L.astype(np.float32))
        out[s, lit[blocked]] = 0.0
    return out


def direct_transport(occluder, points: ShadingPoints, directions, chunk: int = 64,
                     progress=None):
    """Generator over chunks of directions: yields ``(start, rows)`` with rows (n, P) float32;
    ``progress(done, total)`` is called after each chunk. Returns seconds and rays cast."""
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    t0 = time.perf_counter()
    rays0 = occluder.rays
    for a in range(0, len(D), chunk):
        yield a, direct_rows(occluder, points, D[a:a + chunk])
    return {"seconds": time.perf_counter() - t0, "rays": occluder.rays - rays0}
