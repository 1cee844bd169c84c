"""Per-texel horizons by rays: where along each azimuth the sky opens for good.

For a shading point and an azimuth ``phi``, the *horizon* ``h(phi)`` is the elevation above which
every direction of that azimuth reaches the sky: the top end of the occluded elevations. A sun
at elevation ``e`` is then visible where ``e > h(phi)``, exactly for a point whose occluded
elevations along ``phi`` form one interval from below (heightfields, a ground under an object),
and the sun's disc is partly visible across the line -- a soft shadow whose edge *moves* with the
sun, where interpolating visibility between two baked directions draws two faint copies of
the shadow (the ghosting of a low sun).

Found by the ray engine, not fitted from sampled directions: a coarse scan of ``coarse + 1``
elevations 0..90 degrees per azimuth finds the highest blocked one, then ``refine`` bisection
steps place the transition within ``90 / coarse / 2**refine`` degrees. Every ray leaves its
point by Cycles' rules (:func:`.shading.shadow_origins`).

Shapes: ``H`` is (A, P) radians in [0, pi/2] for ``A`` azimuths ``2 pi a / A`` (from +x toward
+y, as :func:`...sphere.hemisphere.direction_from_az_el`) and ``P`` shading points.
"""

from __future__ import annotations

import time

import numpy as np

from .shading import ShadingPoints, cosine, shadow_origins


#: Coarse elevations per azimuth (0..90 degrees, 90 / COARSE apart) and bisection steps after
#: them: the transition is placed within 90 / COARSE / 2**REFINE degrees (0.09 for 8 and 7).
COARSE, REFINE = 8, 7


def _dirs(az, el):
    """Unit directions (..., 3) from azimuth and elevation in radians."""
    ce = np.cos(el)
    return np.stack(np.broadcast_arrays(ce * np.cos(az), ce * np.sin(az), np.sin(el)), -1)


def horizons(occluder, points: ShadingPoints, azimuths: int = 128, coarse: int = COARSE,
             refine: int = REFINE, progress=None) -> np.ndarray:
    """Horizon elevations (A, P) float32 radians (module docstring).

    ``progress(done, total)`` is called after each azimuth. A point open at every coarse
    elevation gets 0; one blocked at the zenith gets pi/2 (never lit).
    """
    gen = iter_horizons(occluder, points, azimuths, coarse, refine)
    while True:
        try:
            done = next(gen)
        except StopIteration as stop:
            return stop.value
        if progress is not None:
            progress(done, azimuths)


def iter_horizons(occluder, points: ShadingPoints, azimuths: int = 128, coarse: int = COARSE,
                  refine: int = REFINE):
    """Generator form of :func:`horizons`: yields the azimuths done after each one (a caller
    may stop between them) and returns H (A, P)."""
    if azimuths < 3 or coarse < 2 or refine < 0:
        raise ValueError(f"need azimuths >= 3, coarse >= 2, refine >= 0; got "
                         f"{azimuths}, {coarse}, {refine}")
    P = points.size
    H = np.zeros((azimuths, P), np.float32)
    els = np.linspace(0.0, np.pi / 2, coarse + 1)
    step = els[1] - els[0]
    for a in range(azimuths):
        phi = 2 * np.pi * a / azimuths
        L = _dirs(phi, els)                                           # (J, 3)
        origins = np.concatenate([shadow_origins(points, L[j]) for j in range(len(els))])
        blocked = occluder.occluded(origins, np.repeat(L.astype(np.float32), P, 0))
        blocked = blocked.reshape(len(els), P)
        any_ = blocked.any(0)
        top = np.where(any_, len(els) - 1 - np.argmax(blocked[::-1], 0), -1)   # highest blocked
        h = np.where(top < 0, 0.0, np.pi / 2)
        todo = np.nonzero((top >= 0) & (top < len(els) - 1))[0]
        lo = els[top[todo]]
        hi = lo + step
        for _ in range(refine):
            mid = 0.5 * (lo + hi)
            Lm = _dirs(phi, mid)
            b = occluder.occluded(shadow_origins(points, Lm, todo), Lm.astype(np.float32))
            lo = np.where(b, mid, lo)
            hi = np.where(b, hi, mid)
        h[todo] = 0.5 * (lo + hi)
        H[a] = h
        yield a + 1
    return H


def horizon_at(H: np.ndarray, azimuth) -> np.ndarray:
    """Horizons (P,) (or (n, P) for n azimuths) at ``azimuth`` radians, linear between the
    table's azimuths (periodic)."""
    A = H.shape[0]
    x = (np.asarray(azimuth, np.float64) % (2 * np.pi)) / (2 * np.pi) * A
    k0 = np.floor(x).astype(int) % A
    f = x - np.floor(x)
    k1 = (k0 + 1) % A
    f = np.asarray(f)[..., None]
    return (1 - f) * H[k0] + f * H[k1]


def disc_fraction(t) -> np.ndarray:
    """Fraction of a disc of radius 1 on the far side of a line at signed distance ``t`` from
    its centre (1 for t >= 1, 0 for t <= -1): the visible part of a sun whose centre is ``t``
    sun radii above the horizon."""
    t = np.clip(np.asarray(t, np.float64), -1.0, 1.0)
    return 0.5 + (t * np.sqrt(1.0 - t * t) + np.arcsin(t)) / np.pi


def direct(points: ShadingPoints, H: np.ndarray, d, sun_angle_deg: float = 0.0,
           disc: int = 0) -> np.ndarray:
    """Direct transport (P,) float64 for a sun towards unit ``d`` of angular diameter
    ``sun_angle_deg``: ``cos * V / pi`` as :func:`.direct.direct_rows` gives it for a hard sun.

    ``disc = 0``: the cosine at the centre times the part of the disc above the horizon line
    (:func:`disc_fraction`, the line taken straight across the disc). ``disc = n``: the mean of
    ``n`` hard suns spread over the disc, each lit where it is above the horizon.
    """
    d = np.asarray(d, np.float64)
    r = np.radians(sun_angle_deg) / 2
    if disc and r > 0:
        from ..transport.texture import _disc_points

        acc = np.zeros(points.size)
        pts = _disc_points(d / np.linalg.norm(d), r, disc)
        for p in pts:
            acc += direct(points, H, p, 0.0)
        return acc / len(pts)
    az = np.arctan2(d[1], d[0])
    el = np.arcsin(np.clip(d[2], -1.0, 1.0))
    h = horizon_at(H, az)
    vis = disc_fraction((el - h) / r) if r > 0 else (el > h).astype(np.float64)
    return cosine(points, d) * vis / np.pi


def cost(P: int, azimuths: int, coarse: int, refine: int) -> int:
    """Rays at most for :func:`horizons` on ``P`` points (the refinement only runs where a
    transition lies between two coarse elevations)."""
    return int(P) * int(azimuths) * (int(coarse) + 1 + int(refine))


def timed_horizons(occluder, points, **kw):
    """(H, figures): :func:`horizons` with its seconds and rays."""
    t0 = time.perf_counter()
    r0 = occluder.rays
    H = horizons(occluder, points, **kw)
    return H, {"seconds": time.perf_counter() - t0, "rays": occluder.rays - r0}
