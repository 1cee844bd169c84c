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
bisection along the azimuth at two elevations within the widest differing run. The two
azimuths' states are first tested by rays at :data:`TESTS` (a quarter, half and three quarters
up the run: the map's one interval may not hold them, as where a wall's part under a window's
sill is dropped); two elevations where the rays differ, the furthest apart, are bisected from
the ray's state, else the quarter and three quarters from the map's. Where the two crossings
agree (within :data:`AGREE` of the gap) the edge is vertical there and the gap's crossing is
their mean; where they do not, the edge is slanted and the linear visibility stays. 6 rays
and :data:`STEPS` bisections at each of two elevations: 16 rays per such pair.

A vertical edge near the texel moves across its footprint: seen from the texel's jitter box
(:mod:`.footprint`, what a converged bake averages) it spans ``u`` gaps of azimuth, the box's
side over the edge's horizontal distance (one ray more per vertical pair finds it). Such an edge
is kept with the weight ``1 - (u / BLUR)^2`` (:data:`BLUR`): the relight draws that much of
the ramp and the rest linearly, and an edge as wide as a gap is linear. On the bumps demo
(32^2, 48 azimuths, a 2-degree Sun at 20 degrees, against Cycles' 128-spp bake: 0.062
linear) the crossings taken sharp from the texel centres drew 0.071 -- most of its vertical
pairs were bumps within a few texels (a median span of 0.6 to 1.5 gaps) --, and a gap whose
edges move less than a run (a smooth rim) filled with its neighbours' crossing drew 0.064;
both fixed, 0.062.

Shapes: ``H`` (2 or 4, A, P) radians as :mod:`.horizon` keeps it (``H[2:]`` an open band);
gap ``k`` lies between azimuths ``k`` and ``k + 1`` (mod A). The result ``t`` (A, P) float16
is the crossing's place in its gap, 0..1 (:data:`SLANTED` where the visibility stays linear,
NaN where the two azimuths agree and the crossing does not matter), with ``w`` (A, P) float16
its weight (0..1, NaN but at crossings); the map keeps codes (:func:`encode`: the crossing
with its weight, 0 where the gap is linear), those of gaps where the crossing does not matter
filled from their neighbours' (:func:`fill`), read linearly between texels.
"""

from __future__ import annotations

import numpy as np

from .footprint import jitters
from .horizon import BELOW
from .shading import ShadingPoints, shadow_origins

#: The elevation grid (radians) on which two azimuths' blocked elevations are compared:
#: 0.5-degree steps from the scan's lowest elevation to the zenith.
GRID = np.radians(np.arange(np.degrees(BELOW), 90.0 + 1e-9, 0.5))
#: A gap is searched where the two azimuths' states differ over a run of at least this many
#: radians of elevation (2 degrees): narrower differences are a slope's rim moving.
MIN_RUN = np.radians(2.0)
#: A gap whose edges move by this much in all (radians) is read linearly where no vertical
#: crossing is found in it (never filled from its neighbours': a smooth rim moving less than
#: a run is what the linear visibility draws); below, its two azimuths are as good as equal.
LINEAR_MOVES = np.radians(0.5)
#: A vertical edge spanning this many gaps across the texel's footprint is read linearly
#: (weight 0); a sharp one (span 0) has weight 1, ``1 - (span / BLUR)^2`` between (the
#: weight that draws a step blurred over ``span`` nearest in the mean over the gap is about
#: ``1 - span``, but the relight's ramp already blurs it by the sun's disc: ``1 - span`` cost
#: the gallery's interior 0.003-0.005 at 3 degrees against the square's 0.000, and gained
#: the bumps nothing more).
BLUR = 1.0
#: Bisection steps along the azimuth: the gap / 2^5 (0.12 degrees at 96 azimuths).
STEPS = 5
#: Where up the widest differing run the two azimuths' states are tested by rays: the two
#: furthest apart of those where they differ are bisected (:func:`_chunk`; with fewer, the
#: first and last).
TESTS = (0.25, 0.5, 0.75)
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
    """``(t, w, figures)`` of :func:`iter_crossings`, run whole."""
    gen = iter_crossings(occluder, points, H, rows)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


def iter_crossings(occluder, points: ShadingPoints, H, rows=None):
    """Generator: yields the points done after each chunk of them (a caller may stop between
    chunks); returns ``(t, w, figures)``: the crossing of each pair (gap, point), ``t`` (A, P)
    float16 in 0..1, its weight ``w`` (A, P) float16 (1 a sharp edge, less one that moves
    across the footprint: :data:`BLUR`; NaN where ``t`` is no crossing), and ``figures`` --
    ``pairs`` searched, ``vertical`` of them given a crossing, ``rays`` cast. ``t`` is
    :data:`SLANTED` where the two elevations' edges disagree, or the edges move (by
    :data:`LINEAR_MOVES`) but not over a run (the gap stays linear), and NaN where the two
    azimuths are as good as equal (the gap's crossing does not matter: :func:`fill` may give
    it its neighbours'). ``rows``: only these points (indices) are searched (the others' NaN)."""
    K, A, P = H.shape
    t = np.full((A, P), np.nan, np.float16)     # (a 2^-11 step: finer than the codes' 1/254)
    w = np.full((A, P), np.nan, np.float16)
    figures = {"pairs": 0, "vertical": 0, "rays": 0}
    rows = np.arange(P) if rows is None else np.asarray(rows, np.int64)
    chunk = max(1, BLOCK // A)
    for c0 in range(0, len(rows), chunk):
        part = rows[c0:c0 + chunk]
        _chunk(occluder, points, H, part, t, w, figures)
        yield c0 + len(part)
    return t, w, figures


#: Grid points a differing run must hold: MIN_RUN over the grid's step, and one.
RUN_POINTS = int(round(MIN_RUN / (GRID[1] - GRID[0]))) + 1


def _chunk(occluder, points, H, part, t, w, figures) -> None:
    """:func:`iter_crossings` over the points ``part`` (indices), into ``t``, ``w`` and
    ``figures``."""
    K, A, P = H.shape
    els = GRID
    step = els[1] - els[0]
    # the two azimuths' blocked sets differ by at most the sum of their edges' moves (an
    # interval emptied between them moves each edge by half its height): only pairs whose
    # moves add up to a run of RUN_POINTS grid points can hold one
    Hc = np.asarray(H[:, :, part], np.float32)
    moves = np.abs(Hc - np.roll(Hc, -1, axis=1)).sum(0)                        # (A, n)
    la, lp = np.nonzero(moves >= LINEAR_MOVES)          # linear unless found vertical below
    t[la, part[lp]] = SLANTED
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
    # the two azimuths' states by rays at three elevations of the run (the map's intervals
    # may not hold them: one blocked interval drops a wall's part under a window's sill):
    # two elevations where the rays' states differ, the furthest apart, are bisected; with
    # fewer, the run's quarter and three quarters
    m = pick.size
    cols = np.arange(m)
    fr = np.array(TESTS)
    e3 = els[start[pick]][None, :] + fr[:, None] * ((length[pick] - 1) * step)[None, :]
    j3 = np.clip(np.round((e3 - els[0]) / step).astype(np.int64), 0, len(els) - 1)
    map0 = b0[pick[None, :], j3]                                         # (3, m)
    p3 = np.tile(p[pick], len(fr))
    ends = []
    for phi in (phi0[pick], phi1[pick]):
        ph = np.tile(phi, len(fr))
        ce3, se3 = np.cos(e3.reshape(-1)), np.sin(e3.reshape(-1))
        L = np.stack([ce3 * np.cos(ph), ce3 * np.sin(ph), se3], -1)
        ends.append(occluder.occluded(shadow_origins(points, L, p3),
                                      L.astype(np.float32)).reshape(len(fr), m))
        figures["rays"] += len(ph)
    differ = ends[0] != ends[1]                                          # (3, m)
    many = differ.sum(0) >= 2
    i1 = np.where(many & ~(differ[0] & differ[2]) & ~differ[0], 1, 0)
    i2 = np.where(many & ~(differ[0] & differ[2]) & ~differ[2], 1, 2)
    e = np.concatenate([e3[i1, cols], e3[i2, cols]])
    # each bisected from the first azimuth's state by its ray where the two rays differ, else
    # by the map (where they agree, the search finds an edge between them if there is one --
    # a fence's picket --, else it ends at the gap's end: 0.128 on the gallery's fence at 45
    # degrees, against 0.136 putting such a crossing at the end whose map state the rays
    # share)
    cut = np.concatenate([differ[i1, cols], differ[i2, cols]])
    first = np.where(cut, np.concatenate([ends[0][i1, cols], ends[0][i2, cols]]),
                     np.concatenate([map0[i1, cols], map0[i2, cols]]))
    rows = np.concatenate([pick, pick])
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
    weight = np.ones(pick.size)
    if vertical.any():
        v = np.flatnonzero(vertical)
        # the blocked side of the lower elevation's final bracket: the edge's distance there
        side = np.where(first[v], lo[v], hi[v])
        weight[v], cast = sharpness(occluder, points, pts[v], e[v], side, A)
        figures["rays"] += cast
    # (a weight under half a code step is a linear gap: 0 in the codes)
    vertical &= weight >= 0.5 / 255
    figures["vertical"] += int(vertical.sum())
    t[a[pick[vertical]], p[pick[vertical]]] = 0.5 * (f1 + f2)[vertical]
    w[a[pick[vertical]], p[pick[vertical]]] = weight[vertical]
    t[a[pick[~vertical]], p[pick[~vertical]]] = SLANTED


def footprint_sides(points: ShadingPoints, p) -> np.ndarray:
    """The side (m,) in metres of the jitter box of points ``p`` (m,) (:mod:`.footprint`: the
    box's side in texels times the texel's size on its triangle, the root of the triangle's
    area over its UV area in texels), at most the triangle's longest edge (the jitter stays
    on the triangle); 0 where the points have no footprint, and on a UV triangle of no area
    (Cycles does not jitter there: :func:`.footprint.jitters`)."""
    fp = getattr(points, "footprint", None)
    if fp is None:
        return np.zeros(len(p))
    tri = fp.triangle[p]
    V = np.asarray(fp.vertices, np.float64)[np.asarray(fp.triangles)[tri]]      # (m, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]), axis=1)
    uv = np.asarray(fp.uv, np.float64)[tri] * fp.resolution                     # (m, 3, 2)
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])              # 2 x UV area, texels
    ok = jitters(det)
    side = fp.box * np.sqrt(2.0 * area / np.where(ok, det, 1.0))
    longest = np.linalg.norm(V - np.roll(V, 1, axis=1), axis=2).max(1)
    return np.where(ok, np.minimum(side, longest), 0.0)


def sharpness(occluder, points: ShadingPoints, p, e, phi, A: int) -> tuple:
    """The weights (m,) of vertical edges seen from points ``p`` (m,) at elevations ``e`` and
    azimuths ``phi`` (m,) radians (just on the blocked side): ``1 - (u / BLUR)^2`` clipped to 0..1,
    ``u`` the gaps (of ``A`` azimuths) the edge spans seen across the point's footprint (its
    side, :func:`footprint_sides`, over the edge's horizontal distance: one ray each), and the
    rays cast (none where the points have no footprint: all 1)."""
    side = footprint_sides(points, p)
    if not side.any():
        return np.ones(len(p)), 0
    L = np.stack([np.cos(e) * np.cos(phi), np.cos(e) * np.sin(phi), np.sin(e)], -1)
    hit, dist = occluder.nearest(shadow_origins(points, L, p), L.astype(np.float32))
    span = side / np.maximum(dist * np.cos(e), 1e-9) / (2 * np.pi / A)
    return np.where(hit >= 0, np.clip(1.0 - (span / BLUR) ** 2, 0.0, 1.0), 1.0), len(p)


#: ``t`` of a gap searched whose edge is slanted (its two elevations' crossings disagree):
#: read linearly, never filled.
SLANTED = -1.0


def fill(T, R: int, W=None) -> tuple:
    """The crossings ``T`` (A, R * R) (0..1 vertical, :data:`SLANTED`, NaN: no matter) with
    their weights ``W`` (A, R * R) (default 1 at every crossing) as the map keeps them,
    ``(t, h)`` (A, R * R) float32: ``t`` the crossing and ``h`` its weight (0 slanted). The
    viewport reads both linearly between texels, ``h t`` and ``h`` (:func:`encode`), and
    draws ``h`` of the ramp and ``1 - h`` of the linear visibility (:func:`warp`): between a
    vertical texel and a slanted one the crossing fades out instead of a linear code blending
    into the crossing's (which drew the gallery's Suzanne's long floor shadow speckled from the
    camera). A no-matter texel (its edge in another gap;
    its own light does not change) next to (8 neighbours) texels searched takes their mean
    weight and their vertical ones' mean crossing, so that the edge moves smoothly between
    texels. One gap at a time (memory: a few (R, R) images)."""
    T = np.asarray(T)
    t_out = np.full(T.shape, np.nan, np.float32)
    h_out = np.zeros(T.shape, np.float32)
    for a in range(T.shape[0]):
        img = T[a].reshape(R, R).astype(np.float64)
        vert = np.isfinite(img) & (img >= 0)
        wt = (vert.astype(np.float64) if W is None else
              np.where(vert, np.nan_to_num(np.asarray(W[a], np.float64).reshape(R, R),
                                           nan=1.0), 0.0))
        known = np.isfinite(img)                      # vertical or slanted
        sums = []
        for v in (np.where(vert, img, 0.0), vert, known, wt):
            pv = np.pad(np.asarray(v, np.float64), 1)
            total = np.zeros((R, R))
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dy or dx:
                        total += pv[1 + dy:1 + dy + R, 1 + dx:1 + dx + R]
            sums.append(total)
        t_sum, n_vert, n_known, w_sum = sums
        t = np.where(vert, img, np.nan)
        h = wt.copy()
        take = np.isnan(img) & (n_known > 0)
        h[take] = w_sum[take] / n_known[take]
        some = take & (n_vert > 0)
        t[some] = t_sum[some] / n_vert[some]
        t_out[a], h_out[a] = t.reshape(-1), h.reshape(-1)
    return t_out, h_out


def encode(t, h=None) -> np.ndarray:
    """Codes (2, ...) uint8 of crossings ``t`` (0..1; NaN or :data:`SLANTED`: linear) with
    weights ``h`` (0..1; default 1 where ``t`` is a crossing): ``h (1 + 254 t)`` and ``255 h``
    -- both blend linearly between texels (:func:`warp` divides them again)."""
    t = np.asarray(t, np.float64)
    ok = np.isfinite(t) & (t >= 0)
    h = ok.astype(np.float64) if h is None else np.where(ok, np.asarray(h, np.float64), 0.0)
    c = h * (1 + 254 * np.clip(np.where(ok, t, 0.0), 0.0, 1.0))
    return np.stack([np.round(c), np.round(255 * h)]).astype(np.uint8)


def decode(codes) -> tuple:
    """``(t, h)`` (float64; t NaN where h is 0) of codes (2, ...) (:func:`encode`)."""
    c, hc = (np.asarray(x, np.float64) for x in codes)
    h = hc / 255.0
    return np.where(hc > 0, (c / np.maximum(h, 1e-12) - 1) / 254.0, np.nan), h


#: The half-width (in sun radii) of the ramp a crossing is read as by each of the relight's
#: strips across the disc (:data:`..transport.horizon_map.STRIPS`): the five strips' sum of
#: such ramps is nearest the disc's part past a vertical edge (RMS 0.0116 of the disc over the
#: edge's offsets within 1.2 radii; a hard step 0.070; three strips: 0.41, RMS 0.032).
RAMP = 0.27


def warp(f, c, hc, half_width):
    """The place ``f`` (0..1) in a gap read through the gap's crossing codes ``c`` and ``hc``
    (:func:`encode`; floats: read linearly between texels, as the viewport's image lookup
    does): ``h`` of a ramp ``half_width`` (in gaps) wide either side of the crossing ``(c / h
    - 1) / 254`` and ``1 - h`` of ``f`` itself (linear), ``h = hc / 255``."""
    h = np.asarray(hc, np.float64) / 255.0
    t = (np.asarray(c, np.float64) / np.maximum(h, 1e-6) - 1) / 254.0
    hw = max(float(half_width), 1e-6)
    ramp = np.clip((f - t) / (2 * hw) + 0.5, 0.0, 1.0)
    return h * ramp + (1 - h) * f
