"""Per-texel horizons by rays: the elevations between which the sky is blocked along each azimuth.

For a shading point and an azimuth ``phi`` the occluded elevations are summed up as one interval
``[lo(phi), hi(phi)]``: ``hi`` is where the sky opens for good above, ``lo`` where it is blocked
from (``-pi/2`` when it is blocked from the horizon up: heightfields, an object standing on the
ground; above ``0`` under an object that floats or overhangs, where a low sun shines under it).
A sun at elevation ``e`` is visible outside the interval, and a sun's disc by the part of it
outside (:func:`visible_fraction`) -- a soft shadow whose edges *move* with the sun, where
interpolating visibility between two baked directions draws two faint copies of the shadow
(the ghosting of a low sun). Two blocked intervals along one azimuth (sky between them) are
taken as their hull; :func:`iter_horizons` counts them. Directions behind the surface (a zero
cosine) do not count: whatever blocks them, the interval is the simplest one that agrees with
the rays in front.

Found by the ray engine, not fitted from sampled directions: a scan of :data:`ELEVATIONS`
(denser near the horizon, where a far object subtends a few degrees) finds the lowest and the
highest blocked ones, then ``refine`` bisection steps place each edge within its bracket
(0.1 degrees at the horizon, 0.1 degrees higher up with 7 steps). Every ray leaves its point by
Cycles' rules (:func:`.shading.shadow_origins`).

Shapes: ``H`` is (2, A, P) radians -- ``H[0]`` the lower edges, ``H[1]`` the upper ones -- for
``A`` azimuths ``2 pi a / A`` (from +x toward +y, as
:func:`...sphere.hemisphere.direction_from_az_el`) and ``P`` shading points. An open sky is an
empty interval (:func:`place_open`).
"""

from __future__ import annotations

import numpy as np

from . import reach as reach_mod
from .shading import ShadingPoints, cosine, shadow_origins

#: The scanned elevations (degrees): 1-2.5 degrees apart below 10, wider above (an object
#: subtending less than its gap can be missed: 1 m seen from 25 m at the horizon is 2.3 degrees).
ELEVATIONS = (0.0, 1.0, 2.0, 3.5, 5.0, 7.0, 9.5, 12.5, 16.0, 20.0, 25.0, 31.0, 38.0, 46.0,
              55.0, 65.0, 77.0, 90.0)
#: Bisection steps for each edge: the widest bracket (13 degrees) / 2^7 = 0.1 degrees.
REFINE = 7
#: The lower edge of an interval blocked from the horizon up.
FROM_BELOW = -np.pi / 2


def _dirs(az, el):
    """Unit directions (..., 3) from azimuth and elevation in radians."""
    ce = np.cos(el)
    return np.stack(np.broadcast_arrays(ce * np.cos(az), ce * np.sin(az), np.sin(el)), -1)


def horizons(occluder, points: ShadingPoints, azimuths: int = 128, refine: int = REFINE,
             progress=None) -> np.ndarray:
    """Horizon intervals (2, A, P) float32 radians (module docstring); ``progress(done,
    total)`` after each azimuth."""
    gen = iter_horizons(occluder, points, azimuths, refine)
    while True:
        try:
            done = next(gen)
        except StopIteration as stop:
            return stop.value[0]
        if progress is not None:
            progress(done, azimuths)


def _bisect(occluder, points, phi, idx, lo, hi, blocked_at_lo, refine: int):
    """Move ``lo``/``hi`` (elevations, radians, (M,)) of points ``idx`` together: the ray at
    ``lo`` is blocked and at ``hi`` open (``blocked_at_lo``, a bool or (M,) bools) or the
    reverse. Returns the midpoints."""
    for _ in range(refine):
        mid = 0.5 * (lo + hi)
        L = _dirs(phi, mid)
        b = occluder.occluded(shadow_origins(points, L, idx), L.astype(np.float32))
        move_lo = b == blocked_at_lo
        lo = np.where(move_lo, mid, lo)
        hi = np.where(move_lo, hi, mid)
    return 0.5 * (lo + hi)


#: A scan ray is "upward" of its point's plane (and may be skipped where no caster can be met,
#: :mod:`.reach`) when cos(Ng, L) exceeds this: clear of rounding, 0.06 degrees above the plane.
UPWARD = 1e-3
#: Rays per engine call at most in the scan (points are taken in chunks of it / 18 elevations).
RAY_BUDGET = 4 << 20


def iter_horizons(occluder, points: ShadingPoints, azimuths: int = 128, refine: int = REFINE):
    """Generator form of :func:`horizons`: yields the azimuths done after each one (a caller
    may stop between them) and returns ``(H, figures)``; H (2, A, P) float16 (0.03 degrees
    at the zenith, against the map's 0.35-degree codes); figures: ``skipped``, the scan's
    rays no caster could meet (not cast), ``castable``, the others, and ``searched``, those
    of them :func:`_search` cast. At most
    :data:`RAY_BUDGET` rays per engine call, whatever the number of points."""
    if azimuths < 3 or refine < 0:
        raise ValueError(f"need azimuths >= 3 and refine >= 0; got {azimuths}, {refine}")
    P = points.size
    H = np.empty((2, azimuths, P), np.float16)
    els = np.radians(np.asarray(ELEVATIONS))
    J = len(els)
    chunk = max(1, RAY_BUDGET // J)
    open_ = np.zeros((azimuths, P), bool)
    bounds = _bounds(occluder, points, azimuths, chunk)
    JJ = np.arange(J, dtype=np.int16)[:, None]
    skipped = searched = castable = 0
    for a in range(azimuths):
        phi = 2 * np.pi * a / azimuths
        L = _dirs(phi, els)                                           # (J, 3)
        L32 = L.astype(np.float32)
        # only directions in front of the closure count: behind it the cosine is 0 whatever
        # the ray meets (often the object itself), and along one azimuth the directions in
        # front form one range of elevations
        care_all = np.stack([cosine(points, L[j]) > 0 for j in range(J)])
        # the terminator along phi: cos(N, L(e)) ~ cos(e - e0)
        e0_all = np.arctan2(points.Ns[:, 2], points.Ns[:, 0] * np.cos(phi)
                            + points.Ns[:, 1] * np.sin(phi))
        for c0 in range(0, P, chunk):
            part = slice(c0, min(c0 + chunk, P))
            idx = np.arange(part.start, part.stop)
            n = len(idx)
            care = care_all[:, part]
            # rays only where the direction is in front (behind it a blocked ray is not used)
            # and, leaving the point upwards of its plane, where some caster can be met
            if bounds is not None:
                covered, e_lo, e_hi = bounds[c0 // chunk]
                Ng = points.Ng[part]
                upward = (L[:, 0, None] * Ng[:, 0] + L[:, 1, None] * Ng[:, 1]
                          + L[:, 2, None] * Ng[:, 2]) > UPWARD             # (J, n)
                reachable = covered[a][None] & (els[:, None] >= e_lo) & (els[:, None] <= e_hi)
                cast = care & ~(upward & ~reachable)
                skipped += int(care.sum() - cast.sum())
            else:
                cast = care
            top, bottom, rays = _search(occluder, points, L, L32, part, idx, cast)
            searched += rays
            castable += int(cast.sum())
            any_ = top >= 0
            e0 = e0_all[idx]
            care_top = np.where(care, JJ, -1).max(0)
            care_bottom = np.where(care, JJ, J).min(0)
            # blocked up to (or from) the end of the range in front: the edge is the
            # terminator itself -- continuous from one azimuth to the next, unlike "blocked to
            # the zenith"
            hi = np.where(any_, np.clip(e0 + np.pi / 2, 0.0, np.pi / 2), 0.0)
            start = e0 - np.pi / 2
            lo = np.where(any_, np.where(start > 0, start, FROM_BELOW), 0.0)   # open: [0, 0]
            # both edges bisected together: one engine call per step
            up = np.nonzero(any_ & (top < care_top))[0]
            down = np.nonzero(any_ & (bottom > care_bottom))[0]
            if up.size or down.size:
                edge = _bisect(occluder, points, phi, idx[np.concatenate([up, down])],
                               np.concatenate([els[top[up]], els[bottom[down] - 1]]),
                               np.concatenate([els[top[up] + 1], els[bottom[down]]]),
                               np.arange(up.size + down.size) < up.size, refine)
                hi[up], lo[down] = edge[:up.size], edge[up.size:]
            H[0, a, idx], H[1, a, idx] = lo, hi
            open_[a, idx] = ~any_
        yield a + 1
    place_open(H, open_)
    return H, {"skipped": skipped, "searched": searched, "castable": castable}


def _search(occluder, points, L, L32, part: slice, idx, cast):
    """The highest and the lowest blocked elevation (indices into ``L``, (J, 3)) of the points
    ``part`` (``idx`` the same as indices), rays only where ``cast`` (J, n): down from the top
    until a point's first blocked ray, then up from the bottom until its first one below that.
    The scan it replaces cast every elevation; the elevations between the two are never
    needed (only the hull is kept): 17 % fewer scan rays on the bumps demo, 22-23 % on the
    statue demo's objects (balanced preset, 256^2, the same intervals bit for bit). Returns
    ``(top, bottom, rays)``: top -1 and bottom J where nothing is blocked; rays cast. One
    engine call per elevation and direction of search, the direction given once."""
    J, n = cast.shape
    rays = 0

    def blocked(j, pick):
        nonlocal rays
        rays += pick.size
        if pick.size > n // 4:          # (the same bits either way: per point)
            origins = np.take(shadow_origins(points, L[j], part), pick, axis=0)
        else:
            origins = shadow_origins(points, L[j], idx[pick])
        return occluder.occluded(origins, L32[j])

    top = np.full(n, -1, np.int64)
    for j in range(J - 1, -1, -1):
        pick = np.flatnonzero(cast[j] & (top < 0))
        if pick.size:
            top[pick[blocked(j, pick)]] = j
    bottom = np.where(top >= 0, top, -1)      # searched below the top only; -1: done
    for j in range(J):
        pick = np.flatnonzero(cast[j] & (bottom > j))
        if pick.size:
            bottom[pick[blocked(j, pick)]] = j
    bottom[top < 0] = J
    return top, bottom, rays


def _bounds(occluder, points: ShadingPoints, azimuths: int, chunk: int):
    """Per chunk of points, where their upward rays can meet a caster (:func:`.reach.reach`),
    or None when the engine does not expose its triangles."""
    V, T = getattr(occluder, "vertices", None), getattr(occluder, "triangles", None)
    if V is None or T is None or not len(T):
        return None
    boxes = reach_mod.clusters(V, T)
    out = []
    for c0 in range(0, points.size, chunk):
        # in pieces of REACH_POINTS: the arcs' counts take (A + 1) x 8 bytes per point
        parts = [_reach(boxes, points, slice(s0, min(s0 + REACH_POINTS, c0 + chunk,
                                                      points.size)), azimuths)
                 for s0 in range(c0, min(c0 + chunk, points.size), REACH_POINTS)]
        out.append((np.concatenate([p[0] for p in parts], axis=1),
                    np.concatenate([p[1] for p in parts]),
                    np.concatenate([p[2] for p in parts])))
    return out


#: Points per :func:`.reach.reach` call (its transient memory: ~2 KB per point at 128 azimuths).
REACH_POINTS = 1 << 15


def _reach(boxes, points: ShadingPoints, part: slice, azimuths: int):
    """:func:`.reach.reach` for the points ``part``: their upward rays' origins (the pushed
    point, lifted by up to Cycles' terminator offset) and how far above the plane they start."""
    c = points.compact()
    up = c["P_up"][part].astype(np.float64)
    tip = up + c["lift"][part] * c["lifting"][part, None]      # the most lifted origin
    lo, hi = np.minimum(up, tip), np.maximum(up, tip)
    scale = np.maximum(1.0, np.abs(hi).max(1, keepdims=True))
    apex, spread = 0.5 * (lo + hi), 0.5 * (hi - lo) + 1e-6 * scale
    Ng, P = points.Ng[part], points.P[part]
    push = np.einsum("pj,pj->p", Ng, up - P)                   # the push, float32 P's
    lift_ng = np.einsum("pj,pj->p", Ng, tip - up)
    above = 0.5 * (push + np.minimum(lift_ng, 0.0))
    return reach_mod.reach(boxes, apex, spread, Ng, P, above, azimuths)


def place_open(H, open_) -> None:
    """An open sky (no blocked direction along its azimuth) is an empty interval ``[m, m]``:
    ``m`` the middle of a neighbouring azimuth's floating interval (both neighbours': the
    mean), else 0. Between two azimuths the edges are interpolated, so the interval then
    shrinks to nothing where it is, instead of spreading towards the horizon (an open
    ``[-pi/2, 0]`` against ``[a, b]`` blends to an interval over low elevations: a shadow where
    the sun shines under the object). In place."""
    mids, weight = np.zeros(H.shape[1:], np.float32), np.zeros(H.shape[1:], np.float32)
    floating = ~open_ & (H[0] >= 0)          # (from below is -pi/2, in float16 -1.5703)
    mid = 0.5 * (H[0].astype(np.float32) + H[1])
    for shift in (1, -1):
        f = np.roll(floating, shift, axis=0)
        mids += np.where(f, np.roll(mid, shift, axis=0), 0.0)
        weight += f
    take = open_ & (weight > 0)
    m = mids[take] / weight[take]
    H[0][take] = m
    H[1][take] = m


def visible_fraction(el, lo, hi, radius: float) -> np.ndarray:
    """The part of a sun's disc (angular ``radius`` > 0, centre at elevation ``el``) outside
    the blocked elevations ``[lo, hi]``, each edge taken as a straight line across the disc
    (an empty interval, ``lo >= hi``, blocks nothing)."""
    return 1.0 - np.maximum(disc_fraction((el - lo) / radius)
                            - disc_fraction((el - hi) / radius), 0.0)


def disc_fraction(t) -> np.ndarray:
    """Fraction of a disc of radius 1 on the far side of a line at signed distance ``t`` from
    its centre (1 for t >= 1, 0 for t <= -1): the visible part of a sun whose centre is ``t``
    sun radii above the horizon."""
    t = np.clip(np.asarray(t, np.float64), -1.0, 1.0)
    return 0.5 + (t * np.sqrt(1.0 - t * t) + np.arcsin(t)) / np.pi


def cost(P: int, azimuths: int, refine: int = REFINE) -> int:
    """Rays at most for :func:`horizons` on ``P`` points (the bisections only run where an
    edge lies between two scanned elevations)."""
    return int(P) * int(azimuths) * (len(ELEVATIONS) + 2 * int(refine))
