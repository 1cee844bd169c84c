"""Direct transport by rays: ``T[s, p] = cos(p, w_s) * V(p, w_s)`` for every direction of a set.

``T = cos * V / pi``: the same quantity as one 1-spp Cycles irradiance bake of the DIFFUSE direct pass under a hard Sun
of strength 1 from ``w_s`` (:mod:`..transport.texture`), at the texel-centre sample points of
:mod:`.texels`. Rays for all points and all directions are cast in batches (:mod:`.engine`).
"""

from __future__ import annotations

import time

import numpy as np

from . import contact
from .shading import ShadingPoints, cosine, shadow_origins


#: Points per block of :func:`direct_rows`. A direction's arrays over all points (cosines, lit
#: indices, origins, hits: ~40 bytes a point) were fresh pages every direction: at 4096^2 about
#: 690 MB a direction, and the kernel's page faults took a third of the direct stage's time.
#: Blocks of this many reuse the allocator's memory. A multiple of every vector width, so the
#: cosines' matrix-vector products round each point as over all points.
POINT_BLOCK = 1 << 18


def direct_rows(occluder, points: ShadingPoints, directions, out=None) -> np.ndarray:
    """Direct transport (S, P) float32 for unit ``directions`` (S, 3): cosine x visibility / pi
    (Cycles' diffuse pass without its colour: a white Lambertian surface's ``E / pi`` under a
    sun of unit normal irradiance; checked against Cycles to float precision on the bumps).
    One engine call per direction and block of :data:`POINT_BLOCK` points (its threads share
    the rays). ``out``: an (at least S, P) float32 array to fill (its first S rows; reused
    by the caller across chunks of directions)."""
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    n = points.size
    if out is None:
        out = np.zeros((len(D), n), np.float32)
    else:
        out = out[:len(D)]
        out[...] = 0.0
    cast = getattr(occluder, "occluded_async", None)
    touching = None if points.contact is None else points.contact.touching
    pending = None        # the rays in flight: (row, their points, Future of what is blocked)

    def land(row, lit, future):
        out[row, lit[future.result()]] = 0.0
    try:
        for s, L in enumerate(D):
            Lf = L.astype(np.float32)
            for a in range(0, n, POINT_BLOCK):
                b = min(a + POINT_BLOCK, n)
                cos = cosine(points, L, slice(a, b))
                lit = np.nonzero(cos > 0)[0]
                if not lit.size:
                    continue
                if lit.size > (b - a) // 4:   # every point's origin, then the lit ones': faster
                    origins = np.take(shadow_origins(points, L, slice(a, b)), lit, axis=0)
                else:                         # (the same bits: shadow_origins is per point)
                    origins = shadow_origins(points, L, lit + a)
                if touching is not None:    # another object's surface at t ~ 0 (.contact)
                    near = np.nonzero(touching[a + lit])[0]
                    if near.size:
                        dark = contact.blocked(points, a + lit[near], L, origins[near])
                        if dark.any():
                            keep = np.ones(lit.size, bool)
                            keep[near[dark]] = False
                            lit, origins = lit[keep], origins[keep]
                            if not lit.size:
                                continue
                out[s, a + lit] = cos[lit] / np.pi
                # one engine call per direction and block, its direction given once: no per-ray
                # copy of it (the rays of 64 directions in one call held ~400 MB at 512^2).
                # Cast while the next direction's origins are made (they took as long as the
                # rays on the bumps, the engine's threads idle meanwhile)
                if cast is None:
                    out[s, a + lit[occluder.occluded(origins, Lf)]] = 0.0
                    continue
                future = cast(origins, Lf)
                if pending is not None:
                    land(*pending)
                pending = (s, a + lit, future)
        if pending is not None:
            land(*pending)
            pending = None
        footprint = getattr(points, "footprint", None)
        if footprint is not None:    # each texel's footprint where a shadow edge passes
            refine = [footprint.edges(out[s], points) for s in range(len(D))]
            footprint.prepare(points, np.unique(np.concatenate(refine)) if refine else [])
            for s, L in enumerate(D):
                idx = refine[s]
                row = out[s]
                footprint.linear_means(points, row, L, idx)   # thin smooth texels, no rays
                if len(idx):
                    out[s, idx] = footprint.refine(points, idx, L, row[idx], occluder,
                                                   cosine, shadow_origins)
    finally:
        if pending is not None:     # (an error or a cancel: no rays left in flight)
            pending[2].cancel() or pending[2].exception()
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
