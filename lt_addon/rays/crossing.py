"""Where between two azimuths a texel's horizon jumps: the azimuth of a vertical edge.

A horizon map holds each texel's blocked interval at ``A`` azimuths (:mod:`.horizon`) and the
relight reads the visibility linearly between two of them. Where the interval changes smoothly
(a slope's rim, a roof's edge) that is right; where it jumps (a window's jamb, a post, a
cylinder's silhouette: a vertical edge, which is one azimuth at every elevation) the linear
visibility draws the edge anywhere between the two azimuths: on the gallery's interior the
jamb at -3.4 degrees from a texel, between the map's -3.75 (blocked) and 0 (open), was drawn
at -1.9 and the texel lit 0.048 where Cycles lights 0.0975.

:func:`crossings` finds, per texel and azimuth gap where the blocked elevations of the two
azimuths differ over more than :data:`MIN_RUN`, the azimuth where the state changes, by
bisection along the azimuth at two elevations within the widest differing run (a quarter and
three quarters up it). Where the two agree (within :data:`AGREE` of the gap) the edge is
vertical there and the gap's crossing is their mean; where they do not, the edge is slanted
and the linear visibility stays. :data:`STEPS` bisections each: 2 x 5 rays per such pair.

Shapes: ``H`` (2 or 4, A, P) radians as :mod:`.horizon` keeps it (``H[2:]`` an open band);
gap ``k`` lies between azimuths ``k`` and ``k + 1`` (mod A). The result ``t`` (A, P) float16
is the crossing's place in its gap, 0..1 (:data:`SLANTED` or NaN where the visibility stays
linear); the map keeps codes (:func:`encode`), those of gaps where the crossing does not
matter filled from their neighbours' (:func:`fill`), read linearly between texels.
"""

from __future__ import annotations

import numpy as np

from .horizon import BELOW
from .shading import ShadingPoints, shadow_origins

#: The elevation grid (radians) on which two azimuths' blocked elevations are compared:
#: 0.5-degree steps from the scan's lowest elevation to the zenith.
GRID = np.radians(np.arange(np.degrees(BELOW), 90.0 + 1e-9, 0.5))
#: A gap is searched where the two azimuths' states differ over a run of at least this many
#: radians of elevation (2 degrees): narrower differences are a slope's rim moving.
MIN_RUN = np.radians(2.0)
#: Bisection steps along the azimuth: the gap / 2^5 (0.12 degrees at 96 azimuths).
STEPS = 5
#: The two elevations' crossings agree when they are within this part of the gap.
AGREE = 0.25
#: (Gap, point) pairs per chunk of points (memory: the grid's states and cosines, ~4 KB a
#: pair searched at most: 64 MiB).
BLOCK = 1 << 14


def blocked(H, a, p, els) -> np.ndarray:
    """Whether the intervals of pairs (azimuths ``a``, points ``p``, (m,)) block elevations
    ``els`` (E,): (m, E) bool -- inside ``[lo, hi]``, outside the open band where ``H`` keeps
    one (an empty interval blocks nothing)."""
    lo = H[0, a, p].astype(np.float64)[:, None]
    hi = H[1, a, p].astype(np.float64)[:, None]
    b = (els[None, :] >= lo) & (els[None, :] <= hi) & (lo < hi)
    if len(H) == 4:
        g_lo = H[2, a, p].astype(np.float64)[:, None]
        g_hi = H[3, a, p].astype(np.float64)[:, None]
        b &= ~((els[None, :] > g_lo) & (els[None, :] < g_hi))
    return b


def widest_run(diff) -> tuple:
    """The widest run of True per row of ``diff`` (m, E): ``(start, length)`` (m,) in grid
    steps (length 0 where none)."""
    m, E = diff.shape
    best_len = np.zeros(m, np.int64)
    best_end = np.zeros(m, np.int64)
    cur = np.zeros(m, np.int64)
    for j in range(E):
        cur = np.where(diff[:, j], cur + 1, 0)
        better = cur > best_len
        best_len[better] = cur[better]
        best_end[better] = j
    return best_end - best_len + 1, best_len


def crossings(occluder, points: ShadingPoints, H, rows=None) -> tuple:
    """``(t, figures)`` of :func:`iter_crossings`, run whole."""
    gen = iter_crossings(occluder, points, H, rows)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


def iter_crossings(occluder, points: ShadingPoints, H, rows=None):
    """Generator: yields the points done after each chunk of them (a caller may stop between
    chunks); returns ``(t, figures)``: the crossing of each pair (gap, point), ``t`` (A, P)
    float16 in 0..1 (NaN: linear), and ``figures`` -- ``pairs`` searched, ``vertical`` of them
    given a crossing, ``rays`` cast. ``t`` is :data:`SLANTED` where the two elevations' edges
    disagree (the gap stays linear) and NaN where the two azimuths do not differ over a run
    (the gap's crossing does not matter: :func:`fill` may give it its neighbours').
    ``rows``: only these points (indices) are searched (the others' ``t`` NaN)."""
    K, A, P = H.shape
    t = np.full((A, P), np.nan, np.float16)     # (a 2^-11 step: finer than the codes' 1/254)
    figures = {"pairs": 0, "vertical": 0, "rays": 0}
    rows = np.arange(P) if rows is None else np.asarray(rows, np.int64)
    chunk = max(1, BLOCK // A)
    for c0 in range(0, len(rows), chunk):
        part = rows[c0:c0 + chunk]
        _chunk(occluder, points, H, part, t, figures)
        yield c0 + len(part)
    return t, figures


#: Grid points a differing run must hold: MIN_RUN over the grid's step, and one.
RUN_POINTS = int(round(MIN_RUN / (GRID[1] - GRID[0]))) + 1


def _chunk(occluder, points, H, part, t, figures) -> None:
    """:func:`iter_crossings` over the points ``part`` (indices), into ``t`` and
    ``figures``."""
    K, A, P = H.shape
    els = GRID
    step = els[1] - els[0]
    # the two azimuths' blocked sets differ by at most the sum of their edges' moves (an
    # interval emptied between them moves each edge by half its height): only pairs whose
    # moves add up to a run of RUN_POINTS grid points can hold one
    Hc = np.asarray(H[:, :, part], np.float32)
    moves = np.abs(Hc - np.roll(Hc, -1, axis=1)).sum(0)                        # (A, n)
    a, p = np.nonzero(moves >= (RUN_POINTS - 1) * step * 0.999)
    if not a.size:
        return
    p = part[p]
    a1 = (a + 1) % A
    b0, b1 = blocked(H, a, p, els), blocked(H, a1, p, els)
    # only elevations in front of the point along both azimuths count
    phi0, phi1 = 2 * np.pi * a / A, 2 * np.pi * (a + 1) / A
    ce, se = np.cos(els)[None, :], np.sin(els)[None, :]
    n = np.asarray(points.Ns, np.float64)[p]
    front = np.ones(b0.shape, bool)
    for phi in (phi0, phi1):
        front &= (ce * (n[:, :1] * np.cos(phi)[:, None] + n[:, 1:2] * np.sin(phi)[:, None])
                  + se * n[:, 2:3]) > 0
    start, length = widest_run((b0 != b1) & front)
    pick = np.flatnonzero(length >= RUN_POINTS)
    if not pick.size:
        return
    figures["pairs"] += int(pick.size)
    e = np.concatenate([els[start[pick]] + 0.25 * (length[pick] - 1) * step,
                        els[start[pick]] + 0.75 * (length[pick] - 1) * step])
    # the state on the gap's first azimuth at each test elevation
    j = np.clip(np.round((e - els[0]) / step).astype(np.int64), 0, len(els) - 1)
    rows = np.concatenate([pick, pick])
    first = b0[rows, j]
    pts = p[rows]
    lo, hi = phi0[rows], phi1[rows]
    ce_, se_ = np.cos(e), np.sin(e)
    for _ in range(STEPS):
        mid = 0.5 * (lo + hi)
        L = np.stack([ce_ * np.cos(mid), ce_ * np.sin(mid), se_], -1)
        got = occluder.occluded(shadow_origins(points, L, pts), L.astype(np.float32))
        figures["rays"] += len(mid)
        same = got == first
        lo = np.where(same, mid, lo)
        hi = np.where(same, hi, mid)
    frac = (0.5 * (lo + hi) - phi0[rows]) / (2 * np.pi / A)
    f1, f2 = frac[:pick.size], frac[pick.size:]
    vertical = np.abs(f1 - f2) <= AGREE
    figures["vertical"] += int(vertical.sum())
    t[a[pick[vertical]], p[pick[vertical]]] = 0.5 * (f1 + f2)[vertical]
    t[a[pick[~vertical]], p[pick[~vertical]]] = SLANTED


#: ``t`` of a gap searched whose edge is slanted (its two elevations' crossings disagree):
#: read linearly, never filled.
SLANTED = -1.0


def fill(T, R: int) -> np.ndarray:
    """Crossings ``T`` (A, R * R) (NaN: no matter, :data:`SLANTED`: linear) with each
    no-matter texel next to (8 neighbours) texels with a crossing in that gap given their
    mean: the viewport reads the codes linearly between texels, and a texel whose two azimuths
    agree (its edge in another gap) would otherwise blend a linear code into its neighbour's
    crossing -- the shadow edge stepped texel by texel. Those texels' own light does not
    change (their two azimuths agree). A float32 copy, one gap at a time (memory: a few
    (R, R) images)."""
    T = np.asarray(T)
    out = np.empty(T.shape, np.float32)
    for a in range(T.shape[0]):
        img = T[a].reshape(R, R).astype(np.float64)
        known = np.isfinite(img) & (img >= 0)
        pv = np.pad(np.where(known, img, 0.0), 1)
        pk = np.pad(known.astype(np.float64), 1)
        total = np.zeros((R, R))
        count = np.zeros((R, R))
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy or dx:
                    total += pv[1 + dy:1 + dy + R, 1 + dx:1 + dx + R]
                    count += pk[1 + dy:1 + dy + R, 1 + dx:1 + dx + R]
        take = np.isnan(img) & (count > 0)
        img[take] = total[take] / count[take]
        out[a] = img.reshape(-1)
    return out


def encode(t) -> np.ndarray:
    """Codes (uint8) of crossings ``t`` (0..1; NaN or :data:`SLANTED`: linear): 0 linear,
    1..255 the crossing at ``(code - 1) / 254`` of its gap."""
    t = np.asarray(t, np.float64)
    linear = ~(np.isfinite(t) & (t >= 0))
    c = 1 + np.round(np.clip(np.where(linear, 0.0, t), 0.0, 1.0) * 254)
    return np.where(linear, 0, c).astype(np.uint8)


def decode(c) -> np.ndarray:
    """Crossings (float64, NaN linear) of codes ``c`` (:func:`encode`)."""
    c = np.asarray(c, np.float64)
    return np.where(c > 0, (c - 1) / 254.0, np.nan)


#: The half-width (in sun radii) of the ramp a crossing is read as by each of the relight's
#: strips across the disc: the three strips' sum of such ramps is nearest the disc's part past
#: a vertical edge (RMS 0.031 of the disc over all offsets; a hard step 0.105).
RAMP = 0.4


def warp(f, c, half_width):
    """The place ``f`` (0..1) in a gap read through the gap's crossing codes ``c`` (float: the
    codes read linearly between texels, as the viewport's image lookup does): linear (``f``)
    where the code is under 0.5, else a ramp ``half_width`` (in gaps) wide either side of the
    crossing ``(c - 1) / 254``."""
    c = np.asarray(c, np.float64)
    t = (c - 1) / 254.0
    hw = max(float(half_width), 1e-6)
    ramp = np.clip((f - t) / (2 * hw) + 0.5, 0.0, 1.0)
    return np.where(c > 0.5, ramp, f)
