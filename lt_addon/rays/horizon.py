"""Per-texel horizons by rays: the elevations between which the sky is blocked along each azimuth.

For a shading point and an azimuth ``phi`` the occluded elevations are summed up as one interval
``[lo(phi), hi(phi)]``: ``hi`` is where the sky opens for good above, ``lo`` where it is blocked
from (``-pi/2`` when it is blocked from the horizon up: heightfields, an object standing on the
ground; above ``0`` under an object that floats or overhangs, where a low sun shines under it).
Where nothing is blocked from the horizon up but the ground is below it (a wall, a slope facing
away from the ground), the interval is ``[-pi/2, hi]`` with ``hi < 0`` (down to :data:`BELOW`):
the part of a large sun's disc under the horizon is lit only where its rays pass the ground's
edge, as Cycles finds them. Under a floating interval the ground below is not kept (the hull of
the two would block the sky between them, where a low sun shines under the object).
A sun at elevation ``e`` is visible outside the interval, and a sun's disc by the part of it
outside (:func:`visible_fraction`) -- a soft shadow whose edges *move* with the sun, where
interpolating visibility between two baked directions draws two faint copies of the shadow
(the ghosting of a low sun). Two blocked intervals along one azimuth (sky between them) are
taken as their hull; :func:`iter_horizons` counts them. Directions behind the surface (a zero
cosine) do not count: whatever blocks them, the interval is the simplest one that agrees with
the rays in front.

Found by the ray engine, not fitted from sampled directions: a scan of :data:`ELEVATIONS`
(denser near the horizon, where a far object subtends a few degrees) finds the lowest and the
highest blocked ones, then bisection steps place each edge within its bracket to 0.1 degrees
(up to ``refine`` = 7 steps for the widest gap, 13 degrees; 4 for the 1-degree gaps:
:func:`steps`). Every ray leaves its point by
Cycles' rules (:func:`.shading.shadow_origins`).

Shapes: ``H`` is (2, A, P) radians -- ``H[0]`` the lower edges, ``H[1]`` the upper ones -- for
``A`` azimuths ``2 pi a / A`` (from +x toward +y, as
:func:`...sphere.hemisphere.direction_from_az_el`) and ``P`` shading points. An open sky is an
empty interval (:func:`place_open`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import reach as reach_mod
from .shading import ShadingPoints, facing, facing_at, shadow_origins

#: The scanned elevations (degrees): 1-2.5 degrees apart below 10, wider above (an object
#: subtending less than its gap can be missed: 1 m seen from 25 m at the horizon is 2.3 degrees).
#: Below the horizon down to :data:`BELOW` (where the directions are in front of the point: a
#: wall, a slope): a large sun near the horizon reaches there (a 10-degree Sun 3 degrees high
#: down to -2), and whether those rays meet the ground or pass its edge is the scene's.
ELEVATIONS = (-10.0, -7.0, -5.0, -3.5, -2.0, -1.0, 0.0, 1.0, 2.0, 3.5, 5.0, 7.0, 9.5, 12.5,
              16.0, 20.0, 25.0, 31.0, 38.0, 46.0, 55.0, 65.0, 77.0, 90.0)
#: The lowest elevation the horizons hold (radians): an upper edge under it is there (a sun
#: reaches below it only when it is over 20 degrees wide at the horizon).
BELOW = np.radians(ELEVATIONS[0])
#: The index of the horizontal in :data:`ELEVATIONS`.
J0 = ELEVATIONS.index(0.0)
#: Bisection steps for each edge: the widest bracket (13 degrees) / 2^7 = 0.1 degrees.
REFINE = 7
#: ... for an upper edge below the horizon, which only a sun over a few degrees wide reaches:
#: 13 / 2^5 = 0.41 degrees, about the map's code step.
REFINE_BELOW = 5
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


def _bisect(occluder, points, ca, sa, idx, lo, hi, blocked_at_lo, refine: int):
    """Move ``lo``/``hi`` (elevations, radians, (M,)) of points ``idx`` together along the
    azimuths whose cosines and sines are ``ca``/``sa`` ((M,)): the ray at ``lo`` is blocked
    and at ``hi`` open (``blocked_at_lo``, a bool or (M,) bools) or the reverse. Each bracket
    is halved until it is as narrow as the widest scan gap after ``refine`` steps
    (:func:`steps`). Returns the midpoints."""
    lo, hi = np.array(lo, np.float64), np.array(hi, np.float64)
    at_lo = np.broadcast_to(blocked_at_lo, lo.shape)
    n = steps(np.abs(hi - lo), refine)          # (refine: an int, or one per bracket)
    for k in range(int(n.max(initial=0))):
        act = np.flatnonzero(n > k)
        mid = 0.5 * (lo[act] + hi[act])
        ce = np.cos(mid)
        L = np.stack([ce * ca[act], ce * sa[act], np.sin(mid)], -1)
        b = occluder.occluded(shadow_origins(points, L, idx[act]), L.astype(np.float32))
        move_lo = b == at_lo[act]
        lo[act] = np.where(move_lo, mid, lo[act])
        hi[act] = np.where(move_lo, hi[act], mid)
    return 0.5 * (lo + hi)


def steps(width, refine: int = REFINE) -> np.ndarray:
    """Bisection steps (int, like ``width``) that narrow brackets ``width`` (radians) to the
    widest scan gap's after ``refine`` steps (13 / 2^7 = 0.10 degrees): 4 for the 1-degree
    gaps near the horizon, where all 7 made them 0.008 degrees wide -- finer than the map's
    0.25-0.49-degree codes by 30x or more, for 3 more rays each (the bisections' rays are the scan's
    costliest: they graze the casters' edges)."""
    refine = np.asarray(refine, np.float64)
    tol = np.radians(np.max(np.diff(ELEVATIONS))) / 2.0 ** refine
    w = np.maximum(np.asarray(width, np.float64), tol)
    return np.clip(np.ceil(np.log2(w / tol) - 1e-9), 0, refine).astype(np.int64)


#: A scan ray is "upward" of its point's plane (and may be skipped where no caster can be met,
#: :mod:`.reach`) when cos(Ng, L) exceeds this: clear of rounding, 0.06 degrees above the plane.
UPWARD = 1e-3
#: Rays per engine call at most in the scan (points are taken in chunks of it / 18 elevations).
RAY_BUDGET = 4 << 20


def iter_horizons(occluder, points: ShadingPoints, azimuths: int = 128, refine: int = REFINE,
                  gaps: bool = False):
    """Generator form of :func:`horizons`: yields the azimuths done (whole-map equivalents:
    the (azimuth, point) pairs done / P) after each block of pairs (a caller may stop between
    them) and returns ``(H, figures)``; H (2, A, P) float16 (``gaps``: (4, A, P), below)
    (0.03 degrees at the zenith,
    against the map's 0.25-0.49-degree codes); figures: ``skipped``, the scan's rays no caster
    could meet (not cast), ``castable``, the others, and ``searched``, those of them
    :func:`_search` cast.

    The pairs are taken in blocks of azimuths over a chunk of points (:func:`_blocks`), and
    every engine call casts one elevation (or one bisection step) for a whole block: ~600
    calls of up to 233k rays on the bumps demo at 256^2 (128 azimuths, 16k points), where one
    azimuth at a time made 10,560 calls of ~2,600 rays (and the calls' set-up cost more than
    their rays). Each scan ray is the one a scan of one azimuth at a time casts, bit for bit
    (tests), and so is each bisection step's.

    ``gaps``: H is (4, A, P), ``H[2:]`` the widest open band inside each interval (the sky
    through a window, between two casters: :func:`_gaps`), an empty one ``[0, 0]``; figures
    add ``gap_rays``, the rays that sought them."""
    if azimuths < 3 or refine < 0:
        raise ValueError(f"need azimuths >= 3 and refine >= 0; got {azimuths}, {refine}")
    A, P = int(azimuths), points.size
    H = np.empty((4 if gaps else 2, A, P), np.float16)
    open_ = np.zeros((A, P), bool)
    scan = _Scan(occluder, points, A, refine, gaps)
    figures = {"skipped": 0, "searched": 0, "castable": 0}
    if gaps:
        figures["gap_rays"] = 0
    done, bounds = 0, (None, None)        # (the chunk's first point, its bounds)
    for part, az in _blocks(P, A, len(ELEVATIONS)):
        if bounds[0] != part.start:              # once per chunk of points, before its blocks
            bounds = (part.start, _bounds(occluder, points, A, part))
        ai, pi, lo, hi, any_, figs = scan.block(part, az, bounds[1])
        H[0, ai, pi], H[1, ai, pi] = lo, hi
        if gaps:
            H[2, ai, pi], H[3, ai, pi] = scan.gap
        open_[ai, pi] = ~any_
        for k in figures:
            figures[k] += figs[k]
        done += len(ai)
        yield done // P
    place_open(H, open_)
    return H, figures


#: A chunk of points is split into at least this many blocks of azimuths (the bake's progress
#: and cancel come between blocks), where there are enough azimuths.
MIN_BLOCKS = 8


def _blocks(P: int, A: int, J: int) -> list:
    """The scan's blocks ``(points slice, azimuth indices)``: chunks of points of at most
    :data:`RAY_BUDGET` / J, and in each groups of azimuths of at most that many pairs (and
    at least :data:`MIN_BLOCKS` groups when there are enough azimuths)."""
    pairs = max(1, RAY_BUDGET // J)
    chunk = max(1, min(P, pairs))
    group = max(1, min(pairs // chunk, -(-A // MIN_BLOCKS)))
    return [(slice(c0, min(c0 + chunk, P)), np.arange(a0, min(a0 + group, A)))
            for c0 in range(0, P, chunk) for a0 in range(0, A, group)]


def _spread(points) -> np.ndarray:
    """(P,) radians: how far past its mean normal's terminator a point's closure normals reach
    -- 0 but for sampled normals (:meth:`.normal_samples.NormalSet.reach`); made once."""
    got = getattr(points, "_horizon_spread", None)
    if got is None or len(got) != points.size:
        got = np.zeros(points.size)
        ns = points.normal_set
        if ns is not None:
            below = ns.shared.reach_below[ns.pick]
            got[ns.rows] = np.arcsin(np.clip(-below, 0.0, 1.0))
        points._horizon_spread = got
    return got


class _Scan:
    """The scan's per-call constants, and :meth:`block`: one block's intervals."""

    def __init__(self, occluder, points, A: int, refine: int, gaps: bool = False):
        self.occluder, self.points, self.refine, self.gaps = occluder, points, refine, gaps
        self.gap = None     # the last block's gaps (g_lo, g_hi) (m,), where ``gaps``
        self.els = np.radians(np.asarray(ELEVATIONS))
        J = len(self.els)
        phis = 2 * np.pi * np.arange(A) / A
        # cos / sin of each azimuth as a scan of one azimuth at a time takes them (a
        # scalar's; the same bits for every pair of the azimuth)
        self.ca = np.array([np.cos(p) for p in phis])
        self.sa = np.array([np.sin(p) for p in phis])
        ce, se = np.cos(self.els), np.sin(self.els)
        self.L = np.stack([np.stack(np.broadcast_arrays(ce * c, ce * s, se), -1)
                           for c, s in zip(self.ca, self.sa)])           # (A, J, 3)
        self.L32 = self.L.astype(np.float32)
        self.JJ = np.arange(J, dtype=np.int16)[:, None]

    def block(self, part: slice, az, bounds):
        """The pairs of the points ``part`` and azimuths ``az`` ((g,) indices), azimuth-major:
        ``(ai, pi, lo, hi, any_, figures)``, their azimuths and points (m,), the interval's
        edges (m,) and whether anything is blocked (m,)."""
        points, els = self.points, self.els
        J, n, g = len(els), part.stop - part.start, len(az)
        m = g * n
        ai = np.repeat(az, n)                                    # (m,) pair -> azimuth
        pi = np.tile(np.arange(part.start, part.stop), g)        # (m,) pair -> point
        # only directions in front of the closure count: behind it the cosine is 0 whatever
        # the ray meets (often the object itself), and along one azimuth the directions in
        # front form one range of elevations
        if points.mapped() is None and points.normal_set is None:   # one product for all
            care = (points.Ns[part] @ self.L[az].reshape(-1, 3).T > 0).reshape(n, g, J)
            care = care.transpose(2, 1, 0).reshape(J, m)                        # (J, m)
        else:                           # closure normals: their bump terms, direction by one
            care = np.concatenate([np.stack([facing(points, self.L[a, j], part)
                                             for j in range(J)]) for a in az], 1)
        # the terminator along phi: cos(N, L(e)) ~ cos(e - e0)
        Ns = points.Ns[part]
        e0 = np.concatenate([np.arctan2(Ns[:, 2], Ns[:, 0] * self.ca[a] + Ns[:, 1] * self.sa[a])
                             for a in az])
        # rays only where the direction is in front (behind it a blocked ray is not used) and,
        # leaving the point upwards of its plane, where some caster can be met
        skipped = 0
        if bounds is not None:
            covered, e_lo, e_hi = bounds
            Ng = points.Ng[part]
            upward = np.concatenate(
                [(self.L[a, :, 0, None] * Ng[:, 0] + self.L[a, :, 1, None] * Ng[:, 1]
                  + self.L[a, :, 2, None] * Ng[:, 2]) > UPWARD for a in az], 1)     # (J, m)
            reachable = (covered[az].reshape(1, m)
                         & np.tile((els[:, None] >= e_lo) & (els[:, None] <= e_hi), g))
            cast = care & ~(upward & ~reachable)
            skipped = int(care.sum() - cast.sum())
        else:
            cast = care
        top, bottom, rays = _search(self.occluder, points, self.L[az].transpose(1, 0, 2),
                                    self.L32[az].transpose(1, 0, 2), None, pi, cast,
                                    which=ai - az[0])
        lo, hi, any_ = self._edges(ai, pi, care, e0, top, bottom)
        figures = {"skipped": skipped, "searched": rays, "castable": int(cast.sum())}
        if self.gaps:
            self.gap, figures["gap_rays"] = self._gap_edges(
                ai, pi, self.L[az].transpose(1, 0, 2), self.L32[az].transpose(1, 0, 2),
                care, cast, top, bottom, ai - az[0])
        return ai, pi, lo, hi, any_, figures

    def _gap_edges(self, ai, pi, L, L32, care, cast, top, bottom, which):
        """The widest open band inside each pair's interval (:func:`_gaps`, on the scan's
        elevations and the midpoints of its steps wider than :data:`GAP_STEP`:
        :func:`gap_grid`), its edges bisected as the interval's are: ``((g_lo, g_hi) (m,)
        radians, rays)``; no band: ``[0, 0]``."""
        els, L, L32, care, cast, top, bottom = gap_grid(self.els, L, care, cast, top, bottom)
        ga, gb, rays = _gaps(self.occluder, self.points, L, L32, pi, care, cast, top, bottom,
                             which, els)
        m = len(ai)
        g_lo, g_hi = np.zeros(m), np.zeros(m)
        has = np.nonzero(ga >= 0)[0]
        if has.size:
            # the band's lower edge: blocked under it, open over; its upper: the reverse
            edge = _bisect(self.occluder, self.points, np.tile(self.ca[ai[has]], 2),
                           np.tile(self.sa[ai[has]], 2), np.tile(pi[has], 2),
                           np.concatenate([els[ga[has] - 1], els[gb[has]]]),
                           np.concatenate([els[ga[has]], els[gb[has] + 1]]),
                           np.arange(2 * has.size) < has.size, self.refine)
            g_lo[has], g_hi[has] = edge[:has.size], edge[has.size:]
            rays += int(steps(np.concatenate([els[ga[has]] - els[ga[has] - 1],
                                              els[gb[has] + 1] - els[gb[has]]]),
                              self.refine).sum())
        return (g_lo, g_hi), rays

    def _edges(self, ai, pi, care, e0, top, bottom):
        """The intervals' edges ``(lo, hi, any_)`` (m,) of pairs (azimuths ``ai``, points
        ``pi``) from the search's highest and lowest blocked elevations ``top``, ``bottom``
        (:func:`_search`), the directions in front ``care`` (J, m) and the terminators ``e0``
        (m,): an edge between two scanned elevations bisected, one at the end of the range in
        front the terminator itself."""
        els, JJ, J = self.els, self.JJ, len(self.els)
        any_ = top >= 0
        below = any_ & (top < J0)          # blocked only under the horizon: the ground
        care_top = np.where(care, JJ, -1).max(0)
        care_bottom = np.where(care[J0:], JJ[J0:], J).min(0)
        # blocked up to (or from) the end of the range in front: the edge is the terminator
        # itself -- continuous from one azimuth to the next, unlike "blocked to the zenith"
        # (sampled normals: their terminators reach past the mean's by the samples' spread)
        half = np.pi / 2 + _spread(self.points)[pi]
        hi = np.where(any_, np.clip(e0 + half, BELOW, np.pi / 2), 0.0)
        start = e0 - half
        lo = np.where(any_ & ~below, np.where(start > 0, start, FROM_BELOW), 0.0)  # open: [0, 0]
        lo[below] = FROM_BELOW
        # both edges bisected together: one engine call per step (an edge under the horizon
        # to the coarser REFINE_BELOW)
        up = np.nonzero(any_ & (top < care_top))[0]
        down = np.nonzero(any_ & ~below & (bottom > care_bottom))[0]
        if up.size or down.size:
            both = np.concatenate([up, down])
            refine = np.where(np.concatenate([below[up], np.zeros(down.size, bool)]),
                              min(self.refine, REFINE_BELOW), self.refine)
            edge = _bisect(self.occluder, self.points, self.ca[ai[both]], self.sa[ai[both]],
                           pi[both], np.concatenate([els[top[up]], els[bottom[down] - 1]]),
                           np.concatenate([els[top[up] + 1], els[bottom[down]]]),
                           np.arange(up.size + down.size) < up.size, refine)
            hi[up], lo[down] = edge[:up.size], edge[up.size:]
        return lo, hi, any_

    def pairs(self, ai, pi, bounds):
        """:meth:`block` for explicit pairs: azimuths ``ai`` and points ``pi`` (m,) -> their
        intervals' edges ``(lo, hi)`` (m,) (open: ``[0, 0]``); ``bounds`` of all the points
        (:func:`_bounds`) or None."""
        points, els = self.points, self.els
        J, m = len(els), len(ai)
        L = self.L[ai]                                               # (m, J, 3)
        if points.mapped() is None and points.normal_set is None:
            care = np.einsum("mk,mjk->jm", points.Ns[pi], L) > 0                  # (J, m)
        else:
            care = np.zeros((J, m), bool)
            for a in np.unique(ai):
                at = np.nonzero(ai == a)[0]
                for j in range(J):
                    care[j, at] = facing_at(points, self.L[a, j], pi[at])
        Ns = points.Ns[pi]
        e0 = np.arctan2(Ns[:, 2], Ns[:, 0] * self.ca[ai] + Ns[:, 1] * self.sa[ai])
        if bounds is not None:
            covered, e_lo, e_hi = bounds
            upward = np.einsum("mk,mjk->jm", points.Ng[pi], L) > UPWARD
            reachable = (covered[ai, pi][None, :] & (els[:, None] >= e_lo[pi][None, :])
                         & (els[:, None] <= e_hi[pi][None, :]))
            cast = care & ~(upward & ~reachable)
        else:
            cast = care
        Lt = L.transpose(1, 0, 2)
        top, bottom, _ = _search(self.occluder, points, Lt, Lt.astype(np.float32), None, pi,
                                 cast, which=np.arange(m))
        lo, hi, _ = self._edges(ai, pi, care, e0, top, bottom)
        return lo, hi


def iter_pair_horizons(occluder, points: ShadingPoints, azimuths: int, ai, pi,
                       refine: int = REFINE):
    """Generator: the intervals of chosen (azimuth, point) pairs only -- ``ai`` (m,) azimuth
    indices of ``azimuths``, ``pi`` (m,) points -- as :func:`iter_horizons` finds them for
    whole maps (the same scan, search and bisection; open pairs are ``[0, 0]``, not placed by
    :func:`place_open`). Yields the pairs done after each block; returns ``(lo, hi)`` (m,)
    float16 radians. The footprints of the horizon map (:func:`...transport.horizon_map.
    varying_pairs`) want a texel's sub-samples only along the azimuths where its edges move."""
    if azimuths < 3 or refine < 0:
        raise ValueError(f"need azimuths >= 3 and refine >= 0; got {azimuths}, {refine}")
    ai = np.asarray(ai, np.int64)
    pi = np.asarray(pi, np.int64)
    m = len(ai)
    lo = np.zeros(m, np.float16)
    hi = np.zeros(m, np.float16)
    if not m:
        return lo, hi
    scan = _Scan(occluder, points, int(azimuths), refine)
    bounds = _bounds(occluder, points, int(azimuths))
    step = max(1, RAY_BUDGET // len(ELEVATIONS))
    for a0 in range(0, m, step):
        sel = slice(a0, min(a0 + step, m))
        lo[sel], hi[sel] = scan.pairs(ai[sel], pi[sel], bounds)
        yield sel.stop
    return lo, hi


def iter_pair_edges(occluder, points: ShadingPoints, azimuths: int, ai, pi, lo_b, hi_b,
                    refine: int = REFINE):
    """Generator: the upper edges of chosen (azimuth, point) pairs expected within brackets
    ``[lo_b, hi_b]`` (m,) radians -- a footprint's sub-sample's edge lies between its texel's
    neighbours' --, the brackets kept within the directions in front of the point (the
    terminator's elevations along the azimuth). A ray at each end; where the lower end is
    blocked and the upper open, bisection narrows the bracket as the scan's does (3 steps for a
    half-degree bracket: 5 rays where the scan casts about 25). Where both ends are blocked, a
    ray under the upper terminator says whether the edge is the terminator itself (as the scan
    finds it) or lies between (bisected); where both are open, a ray over the lower terminator
    whether the edge lies below the bracket (bisected). Elsewhere (a floating interval, an open
    sky, a normal-mapped point) the pair's whole scan (:meth:`_Scan.pairs`). Yields the pairs
    done after each block; returns ``(lo, hi)`` (m,) float16: a searched pair's lower edge is
    "from below" (only its upper edge is sought). (Bisecting the bracket without the end
    rays, an edge outside it clamped to it, made the relief's footprints 0.13 from Cycles at
    3 degrees against 0.07: measured 2026-12-06, not kept.)"""
    A = int(azimuths)
    ai = np.asarray(ai, np.int64)
    pi = np.asarray(pi, np.int64)
    m = len(ai)
    lo = np.full(m, FROM_BELOW, np.float16)
    hi = np.zeros(m, np.float16)
    if not m:
        return lo, hi
    scan = _Scan(occluder, points, A, refine)
    mapped = points.mapped()
    mapped_mask = np.zeros(points.size, bool)
    if mapped is not None:
        mapped_mask[mapped] = True
    step = max(1, RAY_BUDGET // len(ELEVATIONS))
    gap = 1e-4                            # inside the range in front, clear of rounding
    for a0 in range(0, m, step):
        sel = np.arange(a0, min(a0 + step, m))
        a, p = ai[sel], pi[sel]
        ca, sa = scan.ca[a], scan.sa[a]
        Ns = points.Ns[p]
        e0 = np.arctan2(Ns[:, 2], Ns[:, 0] * ca + Ns[:, 1] * sa)
        top = np.clip(e0 + np.pi / 2, BELOW, np.pi / 2)             # the scan's "to the top"
        # the bracket from the horizon up (the lower terminator's, if higher), or under the
        # horizon for an edge of the ground's (a bracket wholly under it)
        e_up = np.maximum(e0 - np.pi / 2, 0.0) + gap
        ground = np.asarray(hi_b, np.float64)[sel] < 0
        e_top = np.where(ground, np.minimum(top, 0.0), top) - gap
        e_bot = np.where(ground, np.maximum(e0 - np.pi / 2, BELOW) + gap, e_up)
        lb = np.clip(np.asarray(lo_b, np.float64)[sel], e_bot, e_top)
        hb = np.clip(np.asarray(hi_b, np.float64)[sel], e_bot, e_top)

        def blocked_at(e, k):
            """Whether the pairs ``k`` are blocked at elevations ``e`` (len(k),)."""
            ce = np.cos(e)
            L = np.stack([ce * ca[k], ce * sa[k], np.sin(e)], -1)
            return occluder.occluded(shadow_origins(points, L, p[k]), L.astype(np.float32))
        use = np.nonzero((hb > lb) & ~mapped_mask[p])[0]
        b_lo, b_hi = blocked_at(lb[use], use), blocked_at(hb[use], use)
        lo_e, hi_e = lb.copy(), hb.copy()
        done = np.zeros(len(sel), bool)
        bis = np.zeros(len(sel), bool)
        bis[use[b_lo & ~b_hi]] = True
        up = use[b_lo & b_hi]                     # the edge above the bracket
        if len(up):
            t = blocked_at(e_top[up], up)
            # (blocked to the top: the terminator's edge; for a bracket of the ground's,
            # blocked at the horizon is no ground's edge: the whole scan, below)
            term = t & ~ground[up]
            hi[sel[up[term]]] = top[up[term]]
            done[up[term]] = True
            lo_e[up[~t]], hi_e[up[~t]] = hb[up[~t]], e_top[up[~t]]
            bis[up[~t]] = True
        down = use[~b_lo & ~b_hi]                 # below it, or nothing blocked
        # a ray over the horizon (the lower terminator's, if higher), where the bracket lies
        # above it; elsewhere the whole scan (under the horizon the ground is the scan's to find:
        # between it and a caster above, bisection could find either edge)
        down = down[lb[down] > e_up[down]]
        if len(down):
            t = blocked_at(e_up[down], down)
            lo_e[down[t]], hi_e[down[t]] = e_up[down[t]], lb[down[t]]
            bis[down[t]] = True
        k = np.nonzero(bis)[0]
        if len(k):
            hi[sel[k]] = _bisect(occluder, points, ca[k], sa[k], p[k], lo_e[k], hi_e[k], True,
                                 refine)
            done[k] = True
        rest = np.nonzero(~done)[0]
        if len(rest):          # the whole scan of these pairs (every ray in front cast: the
            # reach of their points, made for all azimuths, cost more than the rays it saved)
            lo[sel[rest]], hi[sel[rest]] = scan.pairs(a[rest], p[rest], None)
        yield int(sel[-1]) + 1
    return lo, hi


def _search(occluder, points, L, L32, part: slice, idx, cast, which=None):
    """The highest and the lowest blocked elevation (indices into ``L``, (J, 3)) of the points
    ``part`` (``idx`` the same as indices), rays only where ``cast`` (J, n); or, ``which``
    given, of n (point, azimuth) pairs: ``idx`` (n,) their points, ``which`` (n,) their
    azimuths' columns in ``L`` (J, g, 3), ``part`` unused. Down from the top
    until a point's first blocked ray, then up from the bottom until its first one below that.
    The scan it replaces cast every elevation; the elevations between the two are never
    needed (only the hull is kept): 17 % fewer scan rays on the bumps demo, 22-23 % on the
    statue demo's objects (balanced preset, 256^2, the same intervals bit for bit). Returns
    ``(top, bottom, rays)``: top -1 and bottom J where nothing is blocked; rays cast. One
    engine call per elevation and direction of search (the direction given once, unless per
    pair). The bottom is sought from the horizontal (:data:`J0`) up: under a top above it the
    elevations below the horizon are not kept (a floating interval keeps the sky under it), and
    under a top below it the ground blocks from below."""
    J, n = cast.shape
    rays = 0

    def blocked(j, pick):
        nonlocal rays
        rays += pick.size
        if which is not None:           # a direction per pair (float32 as the origins take it)
            d = np.take(L32[j], which[pick], axis=0)
            return occluder.occluded(shadow_origins(points, d, np.take(idx, pick)), d)
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
    for j in range(J0, J):
        pick = np.flatnonzero(cast[j] & (bottom > j))
        if pick.size:
            bottom[pick[blocked(j, pick)]] = j
    bottom[top < 0] = J
    return top, bottom, rays


#: The widest step of the elevations the open bands are sought at (degrees): a band narrower
#: than a step can fall between two scanned elevations, both blocked (a window seen past a
#: box's top from across a room: 21-25 degrees, between the scan's 20 and 25), so the gap
#: search adds the midpoint of every wider step above the horizon (:func:`gap_grid`). On the
#: gallery's interior (2026-12-08, against 1,024-spp truths): 20 degrees under a 10- and a
#: 2-degree Sun 0.047 -> 0.040 and 0.039 -> 0.037, no other cell moved; its band rays 18.6 M
#: -> 30.1 M, its horizons' seconds 4.18 -> 4.26 (short rays, to the room's walls); the other
#: scenes 0.01-1.9 M rays more, no cell moved.
GAP_STEP = 3.0


def gap_grid(els, L, care, cast, top, bottom):
    """The elevations the open bands are sought at: ``els`` (J,) radians (the scan's, the
    horizontal at :data:`J0`) and the midpoint of each step above the horizon wider than
    :data:`GAP_STEP`, with the directions ``L`` (J, g, 3) there (the azimuth's horizontal
    direction turned up), in front ``care`` where both ends are (along one azimuth the
    directions in front form one range), cast where one end is (``cast`` (J, m)), and the
    search's ``top`` and ``bottom`` (m,) as indices into the new grid. Returns ``(els, L,
    L32, care, cast, top, bottom)``; the scan's elevations keep their directions bit for
    bit."""
    els = np.asarray(els, np.float64)
    wide = np.flatnonzero((np.arange(len(els) - 1) >= J0)
                          & (np.diff(els) > np.radians(GAP_STEP)))
    if not wide.size:
        return els, L, L.astype(np.float32), care, cast, top, bottom
    mid = 0.5 * (els[wide] + els[wide + 1])
    order = np.argsort(np.concatenate([els, mid]), kind="stable")
    new_index = np.empty(len(order), np.int64)
    new_index[order] = np.arange(len(order))
    at = new_index[:len(els)]                 # the scan's elevation j -> its place in the grid
    flat = L[J0]                                                 # (g, 3) the horizontals
    Lm = (np.cos(mid)[:, None, None] * flat[None]
          + np.sin(mid)[:, None, None] * np.array([0.0, 0.0, 1.0]))
    L2 = np.concatenate([L, Lm])[order]
    care2 = np.concatenate([care, care[wide] & care[wide + 1]])[order]
    cast2 = np.concatenate([cast, care[wide] & care[wide + 1]
                            & (cast[wide] | cast[wide + 1])])[order]
    J = len(els)

    def move(k):                               # -1 and J stay outside the grid
        return np.where(k < 0, -1, np.where(k >= J, len(order), at[np.clip(k, 0, J - 1)]))
    return (np.concatenate([els, mid])[order], L2, L2.astype(np.float32), care2, cast2,
            move(top), move(bottom))


def _gaps(occluder, points, L, L32, idx, care, cast, top, bottom, which, els=None):
    """The widest open band strictly inside each pair's blocked hull (the scan's ``bottom``
    to ``top``, :func:`_search`): the elevations between them (which the search does not
    cast) are cast where in front of the point; an elevation no caster can reach is open,
    one behind the point blocked (its cosine is 0 whatever). ``(ga, gb, rays)``: the band's
    first and last open indices into the elevations (n,), -1 where the hull has no open
    elevation inside -- a room's wall around its window, the sky between two casters, which
    the hull alone counts blocked (the gallery's interior at 64^2: the map's direct light 0.43-1.0
    from Cycles' at 3-75 degrees, the hull blocking every sun through the window). ``els``
    (J,) radians: the elevations of ``L``'s rows (the scan's by default, :func:`gap_grid`)."""
    J, n = cast.shape
    rays = 0
    open_ = np.zeros((J, n), bool)
    inside = (bottom >= 0) & (top - bottom >= 2)
    for j in range(J0 + 1, J - 1):
        between = inside & (bottom < j) & (top > j)
        if not between.any():
            continue
        open_[j] = between & care[j] & ~cast[j]      # in front, no caster there: open
        pick = np.flatnonzero(between & cast[j])
        if pick.size:
            rays += pick.size
            d = np.take(L32[j], which[pick], axis=0)
            b = occluder.occluded(shadow_origins(points, d, np.take(idx, pick)), d)
            open_[j, pick] = ~b
    # the widest run of open elevations (in radians), per pair
    els = np.radians(np.asarray(ELEVATIONS)) if els is None else np.asarray(els)
    ga = np.full(n, -1, np.int64)
    gb = np.full(n, -1, np.int64)
    best = np.zeros(n)
    start = np.full(n, -1, np.int64)
    for j in range(J0 + 1, J):
        o = open_[j] if j < J - 1 else np.zeros(n, bool)
        start = np.where(o & (start < 0), j, start)
        ends = ~o & (start >= 0)             # a run ended at j - 1
        if ends.any():
            width = els[j] - els[np.maximum(start - 1, 0)]      # the bracket's span
            better = ends & (width > best)
            ga[better], gb[better], best[better] = start[better], j - 1, width[better]
            start = np.where(ends, -1, start)
    return ga, gb, rays


def _bounds(occluder, points: ShadingPoints, azimuths: int, part: slice | None = None):
    """Where the upward rays of the points ``part`` (all by default) can meet a caster
    (:func:`.reach.reach`): ``(covered (A, n), e_lo (n,), e_hi (n,))``, or None when the
    engine does not expose its triangles."""
    V, T = getattr(occluder, "vertices", None), getattr(occluder, "triangles", None)
    if V is None or T is None or not len(T):
        return None
    a, b = (0, points.size) if part is None else part.indices(points.size)[:2]
    # the boxes once per engine (every call of the scan on the same casters asks for them)
    cached = getattr(occluder, "_reach_boxes", None)
    if cached is None or cached[0] is not T:
        cached = (T, reach_mod.clusters(V, T))
        try:
            occluder._reach_boxes = cached
        except AttributeError:     # an engine that takes no attributes: computed each time
            pass
    boxes = cached[1]
    # in pieces of REACH_POINTS: the arcs' counts take (A + 1) x 8 bytes per point
    parts = [_reach(boxes, points, slice(s0, min(s0 + REACH_POINTS, b)), azimuths)
             for s0 in range(a, b, REACH_POINTS)]
    return (np.concatenate([p[0] for p in parts], axis=1),
            np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))


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


#: An elevation beyond every disc (radians): the cosine's lit range :func:`lit_range` uses
#: where it has no bound on one side (the node tree the same, with no infinities in it).
BEYOND = 10.0


def lit_range(el, cos, slope):
    """The elevations ``(a, b)`` (radians, arrays like ``cos``) over which a shading cosine
    linear in elevation across a sun's disc, ``cos + slope (e - el)`` (``cos`` the disc
    centre's, ``slope`` its derivative in elevation), is positive: it is 0 at ``e0 = el - cos
    / slope``, lit above it where the slope is positive (a floor: ``e0`` is the horizon), below
    it where negative (a ceiling); the other bound :data:`BEYOND`. A zero slope counts as a
    tiny negative one (lit everywhere where ``cos > 0``, nowhere where ``cos < 0``)."""
    cos, slope = np.asarray(cos, np.float64), np.asarray(slope, np.float64)
    up = slope > 0
    safe = np.where(up, np.maximum(slope, 1e-9), np.minimum(slope, -1e-9))
    e0 = np.clip(el - cos / safe, -BEYOND, BEYOND)
    return np.where(up, e0, -BEYOND), np.where(up, BEYOND, e0)


def part_above(el, x, radius):
    """The part of a disc (``radius``, centre at ``el``) above the elevation ``x``."""
    return disc_fraction((el - x) / radius)


class Lit(NamedTuple):
    """A lit range ``[a, b]`` (:func:`lit_range`) and the parts of one disc (its centre ``el``,
    its ``radius``) over it: ``above_b`` the part above ``b``, ``whole`` the part between,
    ``whole_m`` that part's first moment (:func:`visible_moment`) -- the same at every azimuth
    a relight reads, so computed once (:func:`lit_parts`)."""
    a: np.ndarray
    b: np.ndarray
    above_b: np.ndarray
    whole: np.ndarray
    whole_m: np.ndarray


def lit_parts(el, lit, radius: float) -> Lit:
    """:class:`Lit` of the lit range ``lit`` (``(a, b)``, or a :class:`Lit` already) for a
    disc of ``radius`` centred at elevation ``el``."""
    if isinstance(lit, Lit):
        return lit
    a, b = lit
    above_b = part_above(el, b, radius)
    return Lit(a, b, above_b, part_above(el, a, radius) - above_b,
               radius * (disc_moment((el - a) / radius) - disc_moment((el - b) / radius)))


def visible_fraction(el, lo, hi, radius: float, radius_hi=None, lit=None) -> np.ndarray:
    """The part of a sun's disc (angular ``radius`` > 0, centre at elevation ``el``) outside
    the blocked elevations ``[lo, hi]``, each edge taken as a straight line across the disc
    (an empty interval, ``lo >= hi``, blocks nothing). ``radius_hi`` (array or float): the
    upper edge is cut by a wider disc (a soft edge: the edge's spread over a texel's
    footprint folded into the disc, :func:`...transport.horizon_map.spread_radius`).
    ``lit`` (``(a, b)``, :func:`lit_range`, or its :class:`Lit`): only the part between ``a``
    and ``b`` counts,
    where the surface faces the sun -- the disc clipped at the surface's terminator, as each
    of Cycles' rays is (a 10-degree Sun 1 degree high over an open floor: 0.62 of its light
    without the clip). The lower edge is then clamped into ``[a, b]`` and the upper edge cut
    where it is, or at ``b`` where that is lower (with a wider disc than the sun's, the
    blocked part kept within ``[0, whole]``: continuous as an edge crosses ``a`` or ``b``)."""
    r_hi = radius if radius_hi is None else radius_hi
    if lit is None:
        return 1.0 - np.maximum(disc_fraction((el - lo) / radius)
                                - disc_fraction((el - hi) / r_hi), 0.0)
    lit = lit_parts(el, lit, radius)
    blocked = (part_above(el, np.clip(lo, lit.a, lit.b), radius)
               - np.maximum(part_above(el, hi, r_hi), lit.above_b))
    return lit.whole - np.clip(blocked, 0.0, lit.whole)


def visible_moment(el, lo, hi, radius: float, radius_hi=None, lit=None) -> np.ndarray:
    """The first moment in elevation of the part of the sun's disc :func:`visible_fraction`
    counts, about the disc's centre, over the disc's area (radians): ``fraction x (the visible
    part's mean elevation - el)``. The whole disc's is 0; the part above a line ``t`` radii
    under the centre has ``r (2/3) (1 - t^2)^(3/2) / pi`` (:func:`disc_moment`); a blocked band
    takes its part away. A shading cosine linear in elevation over the disc is then exact:
    ``cos(el) fraction + d cos / d el x moment``, where the centre's cosine alone counts the
    visible part at the centre's height (a 10-degree Sun 3 degrees high whose upper half is
    visible lights a floor 1.7 times as much as its centre says). ``lit``: as
    :func:`visible_fraction`'s (the part between ``a`` and ``b``: its moment, less the
    clamped interval's, both edges cut by the sun's own disc)."""
    if lit is not None:   # (clamped, both edges cut by one disc: blocked where lo < hi)
        lit = lit_parts(el, lit, radius)
        lo, hi = np.clip(lo, lit.a, lit.b), np.clip(hi, lit.a, lit.b)
        cut = radius * (disc_moment((el - hi) / radius) - disc_moment((el - lo) / radius))
        return lit.whole_m + np.where(lo < hi, cut, 0.0)
    r_hi = radius if radius_hi is None else radius_hi
    t_lo, t_hi = (el - lo) / radius, (el - hi) / r_hi
    blocked = disc_fraction(t_lo) > disc_fraction(t_hi)
    return np.where(blocked, r_hi * disc_moment(t_hi) - radius * disc_moment(t_lo), 0.0)


def disc_moment(t) -> np.ndarray:
    """First moment (in radii, along the line's normal, over the disc's area) of the part of
    a disc of radius 1 on the far side of a line at signed distance ``t`` from its centre:
    ``(2/3) (1 - t^2)^(3/2) / pi`` (0 for |t| >= 1)."""
    t = np.clip(np.asarray(t, np.float64), -1.0, 1.0)
    return (2.0 / 3.0) * (1.0 - t * t) ** 1.5 / np.pi


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
