"""The horizon map: a texture's direct sunlight as per-texel horizons and shading normals.

A relightable texture's direct term under a sun towards ``d`` (unit, world space) of angular
diameter ``a`` is ``E / pi = cos(N, d) * V / pi``. The transport store holds it at S baked
directions, and a light between them blends its neighbours' shadows: a low sun's shadow is drawn
as faint offset copies (ghosting). The horizon map holds instead, per texel and for each of ``A``
azimuths, the elevations ``[lo, hi]`` between which the sky is blocked (:mod:`..rays.horizon`,
found by rays), and the texel's closure normal. A sun is visible outside the interval -- for a
disc, the part of it outside (:func:`..rays.horizon.visible_fraction`), read at five azimuths
across the disc (:data:`STRIPS`) -- so a shadow edge moves continuously with the sun, at any sun
size, from ``2 A`` bytes per texel (``3 A`` with the edges' spreads, below).

It is exact where a texel's occluded elevations along an azimuth form one interval; where they
form two (the sky between), their hull darkens the gap. Before the viewport is chosen,
:func:`heldout_errors` measures the map and T against rays at directions neither holds.

A texel is its footprint, as a converged Cycles bake sees it (:mod:`..rays.footprint`), not its
centre: where the upper edge moves within the footprint (a shadow edge or a relief's rims
across the texel) one centre's edge draws the texel wholly lit or wholly dark, where the bake
sees it partly lit. The bake finds the horizons of a few sub-samples of such texels
(:data:`..rays.footprint.HORIZON_LATTICE`) and keeps, per azimuth, the footprint's mean upper
edge and its spread (standard deviation, :func:`pair_edges`); the relight folds the spread
into the disc that cuts the upper edge (:func:`spread_radius`). On the gallery's relief at
128^2 (direct light against the 16-sample footprint of rays): 0.127 -> 0.045 at 3 degrees,
0.109 -> 0.044 at 8 under a 0.526-degree Sun.

Where the sky opens between two blocked elevations along an azimuth (a room's window, the sky
between two casters) the hull would block it: a map may keep the widest such open band too
(``q[2:]``, :func:`..rays.horizon._gaps`), and the disc's part inside it counts lit again.
On the gallery's interior (the window 1.6 x 1.2 m) the hull blocked every sun through the
window: its box's map erred 0.80 against rays at held-out suns, 0.33 with the band. The
band's two edges are the footprint's too, where they vary between neighbours (and the
neighbouring azimuths have the band: beside a jamb the crossings draw the edge): their means
and spreads (:func:`band_edges`, ``band_spread``), each edge cut by its own wider disc. On
the interior (against Cycles' 1,024-spp bake, 2026-12-08) the box's shadow seen through the
window at 45 degrees under a 2-degree Sun 0.065 -> 0.055 and the window's patch at 75 degrees
under a 0.526-degree one 0.107 -> 0.070 (at 3 degrees 0.042 -> 0.046: there the edges' codes
step by 0.26 degrees, the 0.526-degree Sun's radius, and the spread blurs that step).

Between two azimuths the relight reads the visibility linearly, which is right where the
horizon changes smoothly (a rim, a roof's edge) and draws a vertical edge (a window's jamb, a
post, a cylinder's silhouette: one azimuth at every elevation) anywhere between them. Where a
texel's horizon jumps within a gap the bake finds the edge's azimuth by rays
(:mod:`..rays.crossing`) and the map keeps it (``cross``); the relight then reads each strip's
place in that gap through a ramp at the edge (:func:`..rays.crossing.warp`). On the gallery
at 96 azimuths (256-spp truths, 2026-12-07) the mutual shadows at 8 degrees went from 0.077 /
0.061 / 0.045 to 0.030 / 0.023 / 0.031 under the 0.526 / 2 / 10-degree Sun, the interior at 3
degrees from 0.229 / 0.187 / 0.120 to 0.097 / 0.086 / 0.086 (docs/bench/2026-12-gallery.md).

Arrays: ``q`` (2, A, Rh, Rh) uint8 codes (or (4, A, Rh, Rh): ``q[2]``, ``q[3]`` the open
band's lower and upper edges, coded as upper edges; an empty band ``q[2] == q[3]``) --
``q[1]`` the upper edges (:func:`decode`: -10
to 90 degrees, finest at the horizon; an upper edge under the horizon is the ground's, seen
from a wall or a slope, which a large sun near the horizon reaches), ``q[0]`` the lower edges,
the same but code 0 for "blocked from below" (``-pi / 2``); rows from v = 0 --, ``spread``
(A, Rh, Rh) uint8 codes of the upper edges' spread over the footprint (:func:`encode_spread`;
None in a map without it: a sharp edge) and ``normals`` (R, R, 3) float16 world unit vectors
(zeros on texels no triangle covers), ``cross`` (2, A, Rh, Rh) uint8 (:func:`..rays.crossing.
encode`: a gap's crossing times its weight, and the weight; 0 a linear gap; None in a map
without them). Azimuth ``a`` is ``2 pi a / A`` from +x
toward +y; gap ``a`` lies between azimuths ``a`` and ``a + 1``.
Where the bake has a margin, ``island`` (R, R) bool (the texels the UV triangles cover) and
``margin`` (its Extend passes): :meth:`HorizonMap.direct` lights the island from the codes and
fills the margin from the island's light, as Cycles' Extend margin fills a baked texture (the
viewport's lookups still read the codes' margin, averaged edges, at an island's border).

The horizons may be kept at a coarser side ``Rh`` than the texture's ``R`` (:func:`side`): a
shadow's edge is as sharp as the sun's penumbra, which on a large receiver spans many texels
(a 2-degree sun over an object 1 m high: 35 mm; a 5 m ground at 2048^2: 2.4 mm texels), while
the horizons' memory and rays grow with the texels. The texture's texels then read the codes
bilinearly at their centres, as the viewport's linear image lookup does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..rays.horizon import (BELOW, FROM_BELOW, lit_parts, lit_range, visible_fraction,
                            visible_moment)
from ..io.npz import save_npz
from ..rays.crossing import RAMP, warp

FORMAT = "relightable_textures.horizon_map"
#: Azimuths of a horizon map by default: 2.8 degrees apart. Measured on the bumps demo at 256^2
#: (benchmarks/bench_ray_horizons.py, direct light against 128-spp Cycles at 10 degrees
#: elevation, 2-degree Sun): 32 azimuths 0.100, 64 0.050, 128 0.030; 64 hard suns by rays
#: over the disc (no table) 0.025; T at 1600 directions 0.143.
DEFAULT_AZIMUTHS = 128
#: The smallest sun radius (radians) the relight uses: a point sun is a disc this small, so the
#: NumPy relight and the viewport's node tree compute the same thing at every size.
SUN_RADIUS_MIN = 1e-4
#: Where the sun's disc is read (:meth:`HorizonMap.direct`): (azimuth offset across the disc in
#: radii, weight), the 5-point Gauss-Legendre rule weighted by the chord sqrt(1 - x^2) there,
#: normalised. A wide sun spans azimuth gaps (a 10-degree Sun 8 degrees high: 2.7 gaps of 96
#: azimuths), and a thin caster (a window's mullion, a picket) can hide between three strips.
#: On the gallery's interior (its Room's direct light under a 10-degree Sun against Cycles'
#: 1,024-spp 0-bounce bake, 2026-12-08) three strips erred 0.059 / 0.080 / 0.108 / 0.082 at
#: 3 / 8 / 20 / 45 degrees, five 0.045 / 0.039 / 0.075 / 0.074, seven 0.041 / 0.025 / 0.070 /
#: 0.073; over the whole gallery five moved no cell the wrong way by more than 0.001. Each
#: strip costs the viewport 4 lookups (2 more with spreads, 4 with open bands and 4 more with
#: their edges' spreads, 2 with crossings).
_X, _W = np.polynomial.legendre.leggauss(5)
_W = _W * np.sqrt(1 - _X * _X)
STRIPS = tuple(zip(_X.tolist(), (_W / _W.sum()).tolist()))
#: The smallest cos(elevation) the strips' azimuth offsets divide by (a sun near the zenith
#: spans every azimuth; its disc is then read over 1/COS_MIN radii of azimuth at most).
COS_MIN = 1e-3
#: The edges' codes (:func:`decode`): 1-degree steps under the horizon (the ground's edges
#: seen from a wall, down to the scan's lowest, :data:`..rays.horizon.BELOW`: only a sun a few
#: degrees wide reaches there), from the horizon up a quadratic in the code whose steps widen
#: from :data:`STEP_HORIZON` to 0.49 degrees at the zenith (a low sun's shadow edges are low;
#: a 0.526-degree Sun's radius is 0.26 degrees). On the gallery's relief (a 0.526-degree Sun 3
#: degrees high) the viewport erred 0.073 with 0.35-degree steps everywhere (the codes before
#: edges under the horizon), 0.080 with even 0.39-degree steps from -10 degrees, 0.071 with
#: these, 0.058 with 0.044-degree steps (not 8-bit); between two texels' codes the viewport's
#: linear lookup bends the edge by 0.2 degrees midway across a 12-degree jump (1.2 across 30)
#: (docs/bench/2026-12-gallery.md, "Under the horizon").
CODE_ZERO = 10
#: The step under the horizon, and at the horizon (radians).
STEP_BELOW = np.radians(1.0)
STEP_HORIZON = np.radians(0.25)
#: The elevation of code 0 (radians).
EDGE_MIN = -CODE_ZERO * STEP_BELOW
#: The quadratic's coefficient: ``h = STEP_HORIZON u + CURVE u^2`` for ``u = code - CODE_ZERO``,
#: pi/2 at code 255.
CURVE = (np.pi / 2 - STEP_HORIZON * (255 - CODE_ZERO)) / (255 - CODE_ZERO) ** 2
#: The widest step (radians): 0.49 degrees, at the zenith.
STEP = STEP_HORIZON + 2 * CURVE * (255 - CODE_ZERO)
assert EDGE_MIN <= BELOW
#: The code step of maps before format 4, whose codes started at the horizon (0.35 degrees):
#: :func:`load` recodes them.
STEP_V3 = np.pi / 2 / 255.0
#: The largest spread of an upper edge a code holds (radians): codes are ``sqrt(spread /
#: SPREAD_MAX)`` in 255 steps, fine where a hard sun needs them (0.0002 degrees at code 1, 0.03
#: degrees a step near 1 degree).
SPREAD_MAX = np.radians(15.0)
#: Neighbouring texels whose edges differ by more than this (radians) at some azimuth mark a
#: texel whose footprint the bake samples (:func:`varying`): 1 degree. Where the edge varies
#: smoothly, a neighbour's difference over a half-texel box is a spread of about a seventh of
#: it (0.14 degrees here, against a 0.526-degree Sun's 0.26-degree radius).
VARYING = np.radians(1.0)
#: The horizons' side at most when the settings leave it to the bake (0). With 128 azimuths a
#: 2048^2 texture's horizon viewport then takes 426 MiB of GPU memory (its normals and albedo
#: at 2048^2 included; 1507 MiB with the horizons at 2048^2), within the default 512 MiB
#: budget; a 4096^2 texture's 618 MiB. The edges' spreads add a third of the horizons' part
#: (594 MiB at 2048^2: over the default budget, such a bake leaves them out).
AUTO_SIDE = 1024


def side(resolution: int, horizon_resolution: int = 0) -> int:
    """The horizons' side for a texture of side ``resolution``: ``horizon_resolution`` when
    given (> 0), else :data:`AUTO_SIDE`; never more than the texture's."""
    want = int(horizon_resolution) if horizon_resolution else AUTO_SIDE
    return max(1, min(int(resolution), want))


#: The fewest azimuths of the horizons when the scene's Sun is animated (its path is in the
#: direction set): a low Sun on its path needs the horizons at the texture's side and this many
#: azimuths (:func:`for_sun_path`; measured in docs/bench/2026-transport-log.md).
PATH_AZIMUTHS = 128


def for_sun_path(resolution: int, azimuths: int, horizon_resolution: int,
                 budget_bytes: int) -> tuple[int, int]:
    """``(azimuths, horizon_resolution)`` of the horizons a bake whose Sun is animated makes,
    for a texture of side ``resolution``: at the texture's side (at most :data:`AUTO_SIDE`) and
    at least :data:`PATH_AZIMUTHS` azimuths, as far as the viewport's GPU memory stays within
    ``budget_bytes`` (:func:`gpu_bytes`): more azimuths are dropped first, then the finer side.
    Never fewer azimuths or a coarser side than asked; ``azimuths`` 0 (none asked) stays 0."""
    A, given = int(azimuths), side(resolution, horizon_resolution)
    if A == 0:
        return 0, int(horizon_resolution)
    full = side(resolution, 0)
    for a, h in ((max(A, PATH_AZIMUTHS), full), (A, full), (A, given)):
        if h >= given and gpu_bytes(a, resolution, h) <= budget_bytes:
            return a, h
    return A, int(horizon_resolution)


def encode_spread(S) -> np.ndarray:
    """Spreads (radians, any shape) -> uint8 codes ``rint(sqrt(S / SPREAD_MAX) * 255)``."""
    S = np.clip(np.asarray(S, np.float64) / SPREAD_MAX, 0.0, 1.0)
    return np.rint(np.sqrt(S) * 255.0).astype(np.uint8)


def decode_spread(c) -> np.ndarray:
    """Codes (uint8, or interpolated floats) -> spreads in radians: ``(c / 255)^2 SPREAD_MAX``
    -- the viewport's rule."""
    c = np.asarray(c, np.float64) / 255.0
    return c * c * SPREAD_MAX


def spread_radius(radius, spread):
    """The disc radius that cuts an upper edge spread by ``spread`` (radians, standard
    deviation over the footprint) for a sun of ``radius``: the disc's vertical variance
    ``r^2 / 4`` plus the edge's, as one disc's, ``sqrt(r^2 + 4 s^2)``."""
    return np.sqrt(radius * radius + 4.0 * np.asarray(spread, np.float64) ** 2)


def pair_edges(lo_c, hi_c, lo_s, hi_s, group, weight, centre_w):
    """The footprint's upper edge of ``n`` (azimuth, texel) pairs: ``(mean, spread)`` (n,)
    float64 radians, the weighted mean and standard deviation of the edges of the texel's
    centre and its sub-samples along that azimuth. The centres' edges ``lo_c``, ``hi_c`` (n,),
    the sub-samples' ``lo_s``, ``hi_s`` (N,), each sub-sample's pair ``group`` (N,) and
    ``weight`` (N,), the centres' ``centre_w`` (n,) (:class:`..rays.footprint.Footprint`
    ``._sub_points``; a texel's weights sum to 1). A sub-sample open along the azimuth (an
    empty interval) counts as an edge at its centre's lower edge (at 0 under one blocked from
    below): visible wherever the centre's interval does not block. Under a centre blocked from
    below, a sub-sample's upper edge under the horizon (the ground's) is an edge, and an open
    one counts at :data:`EDGE_MIN` where the ground is some edge of the pair's (visible under
    the horizon too); under a floating or open centre, whose lower edge the map keeps, a
    sub-sample that sees only the ground counts as open (its edge under the centre's lower
    one would empty the interval: the caster's shadow gone)."""
    lo_c, hi_c = np.asarray(lo_c, np.float64), np.asarray(hi_c, np.float64)
    lo_s, hi_s = np.asarray(lo_s, np.float64), np.asarray(hi_s, np.float64)
    group = np.asarray(group, np.int64)
    n = len(lo_c)
    below = lo_c < 0                                 # the centre blocked from below
    ground_s = (hi_s > lo_s) & (hi_s < 0) & below[group]
    ground = below & (((hi_c > lo_c) & (hi_c < 0)) | (np.bincount(
        group, weights=ground_s.astype(np.float64), minlength=n) > 0))
    floor = np.where(ground, EDGE_MIN, np.maximum(lo_c, 0.0))
    hc = np.where(hi_c > lo_c, hi_c, floor)
    hs = np.where((hi_s > lo_s) & ((hi_s >= 0) | below[group]), hi_s, floor[group])
    w = np.asarray(weight, np.float64)
    cw = np.asarray(centre_w, np.float64)
    total = cw + np.bincount(group, weights=w, minlength=n)
    mean = (cw * hc + np.bincount(group, weights=w * hs, minlength=n)) / total
    sq = (cw * hc * hc + np.bincount(group, weights=w * hs * hs, minlength=n)) / total
    return mean, np.sqrt(np.maximum(sq - mean * mean, 0.0))


def varying_pairs(H, texel, R: int, found=None, tol: float = VARYING, normals=None) -> np.ndarray:
    """(A, P) bool: the (azimuth, texel) pairs whose lower or upper edge differs from a grid
    neighbour's by more than ``tol`` (radians) along that azimuth: where the footprint's edges
    may move within the texel. ``H`` (2, A, P); ``texel`` (P,); ``found`` (P,) bool: the points
    whose horizons are known (neighbours not found do not count). An open azimuth (an empty
    interval) has no edges, whatever its placeholder (:func:`..rays.horizon.place_open`).
    ``normals`` (P, 3): the closure normals, whose terminator bounds the range of elevations in
    front (:mod:`..rays.horizon`): an edge at the terminator is no caster's (the cosine is 0
    there: a smooth surface's terminator moves from texel to texel without any shadow edge),
    so a lower edge there counts as "from below" and an upper one as "to the zenith"."""
    H = np.asarray(H)
    texel = np.asarray(texel, np.int64)
    A = H.shape[1]
    ok = np.ones(len(texel), bool) if found is None else np.asarray(found, bool)
    mask = np.zeros(R * R, bool)
    mask[texel[ok]] = True
    mask = mask.reshape(R, R)
    out = np.zeros((A, len(texel)), bool)
    N = None if normals is None else np.asarray(normals, np.float64)
    OPEN = 10.0                          # an open azimuth's edges (far from any elevation)
    for a in range(A):
        lo = np.maximum(np.asarray(H[0, a], np.float64), -1.0)      # from below: -1
        hi = np.asarray(H[1, a], np.float64)
        if N is not None:                # the terminator's elevations below and above
            phi = 2 * np.pi * a / A
            e0 = np.arctan2(N[:, 2], N[:, 0] * np.cos(phi) + N[:, 1] * np.sin(phi))
            lo = np.where(lo <= np.maximum(e0 - np.pi / 2, 0.0) + tol / 4, -1.0, lo)
            hi = np.where(hi >= np.clip(e0 + np.pi / 2, EDGE_MIN, np.pi / 2) - tol / 4,
                          np.pi / 2, hi)
        empty = np.asarray(H[1, a], np.float64) <= np.asarray(H[0, a], np.float64)
        flag = np.zeros((R, R), bool)
        for v in (np.where(empty, OPEN, lo), np.where(empty, OPEN, hi)):
            img = np.zeros(R * R, np.float32)
            img[texel] = v
            img = img.reshape(R, R)
            for sa, sb in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                           ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
                d = (np.abs(img[sa] - img[sb]) > tol) & mask[sa] & mask[sb]
                flag[sa] |= d
                flag[sb] |= d
        out[a] = flag.reshape(-1)[texel] & ok
    return out


#: A footprint's sub-samples look for their upper edges between the texel's and its grid
#: neighbours' upper edges, widened by this (radians) each way (:func:`brackets`).
BRACKET_MARGIN = np.radians(0.25)


def neighbours(texel, R: int) -> np.ndarray:
    """(4, P) the point index of each point's left, right, lower and upper grid neighbour
    (-1 where no point covers it), of points at ``texel`` (P,) on an (R, R) grid: made once
    per object for :func:`surrounded`, :func:`brackets` and :func:`smooth_spreads`."""
    texel = np.asarray(texel, np.int64)
    img = np.full((R + 2) * (R + 2), -1, np.int64)
    row, col = texel // R, texel % R
    img[(row + 1) * (R + 2) + col + 1] = np.arange(len(texel))
    img = img.reshape(R + 2, R + 2)
    r, c = row + 1, col + 1
    return np.stack([img[r, c - 1], img[r, c + 1], img[r - 1, c], img[r + 1, c]])


def surrounded(nb, found) -> np.ndarray:
    """(P,) bool: the points found whose covered grid neighbours (``nb``: :func:`neighbours`)
    are all found -- whose :func:`varying_pairs` and :func:`brackets` no later point
    changes."""
    found = np.asarray(found, bool)
    ok = found.copy()
    for k in range(4):
        ok &= (nb[k] < 0) | found[np.maximum(nb[k], 0)]
    return ok


def brackets(H, nb, ai, ti, margin: float = BRACKET_MARGIN):
    """``(lo_b, hi_b)`` (n,) radians for the (azimuth, point) pairs ``ai``, ``ti``: the least
    and greatest upper edge of the point and its grid neighbours (``nb``: :func:`neighbours`)
    along that azimuth (where their intervals are not empty), widened by ``margin`` -- where
    the sub-samples of its footprint find their edges (:func:`..rays.horizon.
    iter_pair_edges`)."""
    ai, ti = np.asarray(ai, np.int64), np.asarray(ti, np.int64)
    nb = np.asarray(nb)[:, ti]                                          # (4, n)
    cand = [ti] + [nb[k] for k in range(4)]
    # an edge under the horizon (the ground's) brackets only a pair whose own edge is one: the
    # ground beside a caster's edge would widen the bracket over the sky under the caster
    lo0, hi0 = np.asarray(H[0, ai, ti], np.float64), np.asarray(H[1, ai, ti], np.float64)
    own_ground = (hi0 > lo0) & (hi0 < 0)
    lo_b = np.full(len(ti), np.inf)
    hi_b = np.full(len(ti), -np.inf)
    for c in cand:
        has = c >= 0
        cc = np.maximum(c, 0)
        lo_e = np.asarray(H[0, ai, cc], np.float64)
        hi_e = np.asarray(H[1, ai, cc], np.float64)
        real = has & (hi_e > lo_e) & ((hi_e >= 0) | own_ground)
        lo_b = np.where(real, np.minimum(lo_b, hi_e), lo_b)
        hi_b = np.where(real, np.maximum(hi_b, hi_e), hi_b)
    none = ~np.isfinite(lo_b)
    return (np.where(none, 0.0, lo_b - margin), np.where(none, 0.0, hi_b + margin))


#: An edge whose second difference over the grid (either axis) is under this (radians) is
#: taken as linear across the texel (:func:`smooth_spreads`): 0.5 degrees.
SMOOTH = np.radians(0.5)
#: ... and so is one that differs from no neighbour's by more than this (radians): 3 degrees,
#: where a jump (a rim, a post's side) is tens of degrees.
JUMP = np.radians(3.0)


def smooth_spreads(H, nb, ai, ti, box: float, tol: float = SMOOTH, jump: float = JUMP):
    """``(smooth (n,) bool, spread (n,) radians)`` for the (azimuth, point) pairs ``ai``,
    ``ti``: where the upper edges of the point and its four grid neighbours (``nb``:
    :func:`neighbours`) are all edges
    (their intervals not empty) and vary linearly (second differences under ``tol`` along both
    axes) or differ by under ``jump`` from each, the footprint's edges are taken as a linear
    function over its box (``box`` texels a side), whose spread is ``|gradient| box /
    sqrt(12)`` -- no rays needed (a smooth floor beside a sphere); elsewhere (a jump: a
    relief's rim, a thin post) rays are."""
    ai, ti = np.asarray(ai, np.int64), np.asarray(ti, np.int64)
    nb = np.asarray(nb)[:, ti]                                          # (4, n) l, r, d, u
    ok = np.all(nb >= 0, axis=0)
    lo0 = np.asarray(H[0, ai, ti], np.float64)
    h0 = np.asarray(H[1, ai, ti], np.float64)
    ok &= h0 > lo0
    h = []
    for k in range(4):
        c = np.maximum(nb[k], 0)
        lo_k = np.asarray(H[0, ai, c], np.float64)
        h_k = np.asarray(H[1, ai, c], np.float64)
        ok &= h_k > lo_k
        h.append(h_k)
    linear = (np.abs(h[0] - 2 * h0 + h[1]) < tol) & (np.abs(h[2] - 2 * h0 + h[3]) < tol)
    small = np.max(np.abs(np.stack(h) - h0), axis=0) < jump
    ok &= linear | small
    gx, gy = 0.5 * (h[1] - h[0]), 0.5 * (h[3] - h[2])
    return ok, np.where(ok, np.hypot(gx, gy) * float(box) / np.sqrt(12.0), 0.0)


def quantize(H) -> np.ndarray:
    """Intervals (2, ...) in radians -> uint8 codes (module docstring): edges in
    [EDGE_MIN, pi/2] round to the nearest of 0..255 (:func:`decode`); lower edges below 0
    (blocked from below) are code 0, others round to CODE_ZERO..255."""
    H = np.asarray(H, np.float64)
    u = np.where(H < 0, H / STEP_BELOW,       # the quadratic's inverse above the horizon
                 2 * H / (STEP_HORIZON + np.sqrt(STEP_HORIZON ** 2 + 4 * CURVE * np.maximum(H, 0))))
    q = np.rint(np.clip(u + CODE_ZERO, 0.0, 255.0)).astype(np.uint8)
    q[0] = np.where(H[0] < 0, 0, np.maximum(q[0], 1))
    return q


def decode(q) -> np.ndarray:
    """Codes (2, ...) -> radians float64: uint8 codes, or codes interpolated between texels
    as floats -- the viewport's rule: ``u = code - CODE_ZERO``, ``STEP_BELOW u`` under the
    horizon (u < 0), ``(CURVE u + STEP_HORIZON) u`` above; a lower code under 0.5 is "from
    below", ``-pi/2`` plus the code's part (exactly ``-pi/2`` for code 0)."""
    qf = np.asarray(q, np.float64)
    u = qf - CODE_ZERO
    up = np.maximum(u, 0.0)
    h = np.minimum(u, 0.0) * STEP_BELOW + (up * CURVE + STEP_HORIZON) * up
    h[0] = np.where(qf[0] < 0.5, h[0] + (FROM_BELOW - EDGE_MIN), h[0])
    return h


def recode_v3(q) -> np.ndarray:
    """A format-3 (or 2) map's codes (2, ...) uint8, whose edges were ``q * STEP_V3`` from the
    horizon, as this format's codes (each edge within half a step of the old one)."""
    qf = np.asarray(q, np.float64)
    h = qf * STEP_V3
    h[0] = np.where(qf[0] < 0.5, FROM_BELOW, h[0])
    return quantize(h)


def upsample(img, R: int) -> np.ndarray:
    """``img`` (..., Rh, Rh) read bilinearly at the centres of an (R, R) grid's texels over the
    same square, edges clamped (the atlas' edge padding): the viewport's linear lookup.
    float64; ``img`` itself when Rh == R."""
    img = np.asarray(img, np.float64)
    Rh = img.shape[-1]
    if Rh == R:
        return img
    x = (np.arange(R) + 0.5) * (Rh / R) - 0.5
    i0 = np.floor(x).astype(np.int64)
    w = x - i0
    a, b = np.clip(i0, 0, Rh - 1), np.clip(i0 + 1, 0, Rh - 1)
    rows = img[..., a, :] * (1 - w)[:, None] + img[..., b, :] * w[:, None]
    return rows[..., a] * (1 - w) + rows[..., b] * w


def upsample_at(img, R: int, texels) -> np.ndarray:
    """:func:`upsample` read only at flat ``texels`` (n,) of the (R, R) grid: (..., n), the
    same operations in the same order, so the same bits."""
    img = np.asarray(img, np.float64)
    texels = np.asarray(texels, np.int64)
    row, col = texels // R, texels % R
    Rh = img.shape[-1]
    if Rh == R:
        return img[..., row, col]
    x = (np.arange(R) + 0.5) * (Rh / R) - 0.5
    i0 = np.floor(x).astype(np.int64)
    w = x - i0
    a, b = np.clip(i0, 0, Rh - 1), np.clip(i0 + 1, 0, Rh - 1)
    wr, wc = w[row], w[col]
    r0 = img[..., a[row], a[col]] * (1 - wr) + img[..., b[row], a[col]] * wr
    r1 = img[..., a[row], b[col]] * (1 - wr) + img[..., b[row], b[col]] * wr
    return r0 * (1 - wc) + r1 * wc


def band_edges(g_lo_c, g_hi_c, lo_s, hi_s, shut_s, group, weight, centre_w):
    """The footprint's open band of ``n`` (azimuth, texel) pairs: ``(mean_lo, mean_hi,
    spread_lo, spread_hi)`` (n,) float64 radians, the weighted means and standard deviations
    of the band's edges at the texel's centre (``g_lo_c``, ``g_hi_c`` (n,)) and its
    sub-samples along that azimuth (``lo_s``, ``hi_s`` (N,), each sub-sample's pair ``group``
    and ``weight`` (N,), the centres' ``centre_w`` (n,), as :func:`pair_edges`). A sub-sample
    that sees no band (``shut_s``: blocked at the centre's band's middle -- behind a box's
    edge seen through a window) counts as a band shut there, both edges at that middle: the
    spread edges then let through about the share of the footprint that sees the band (the
    gallery's interior at 45 degrees, the box's shadow through the window; with the edges
    clamped to their search's bracket instead, the shadow's edge stayed the centre's)."""
    g_lo_c, g_hi_c = np.asarray(g_lo_c, np.float64), np.asarray(g_hi_c, np.float64)
    group = np.asarray(group, np.int64)
    n = len(g_lo_c)
    mid = 0.5 * (g_lo_c + g_hi_c)
    shut = np.asarray(shut_s, bool)
    w = np.asarray(weight, np.float64)
    cw = np.asarray(centre_w, np.float64)
    total = cw + np.bincount(group, weights=w, minlength=n)
    out = []
    for c, e in ((g_lo_c, lo_s), (g_hi_c, hi_s)):
        e = np.where(shut, mid[group], np.asarray(e, np.float64))
        mean = (cw * c + np.bincount(group, weights=w * e, minlength=n)) / total
        sq = (cw * c * c + np.bincount(group, weights=w * e * e, minlength=n)) / total
        out.append((mean, np.sqrt(np.maximum(sq - mean * mean, 0.0))))
    return out[0][0], out[1][0], out[0][1], out[1][1]


@dataclass
class HorizonMap:
    q: np.ndarray          # (2, A, Rh, Rh) uint8
    normals: np.ndarray    # (R, R, 3) float16
    spread: np.ndarray | None = None    # (A, Rh, Rh) uint8 (encode_spread), or None
    #: (R, R) bool: the texels the UV triangles cover (the bake's shading points), and the
    #: bake's Extend margin in texels around them; None / 0 in a map without them (before
    #: 2026-12-07, and the viewport's tiles): its margin is then relit from its own codes
    island: np.ndarray | None = field(default=None, compare=False)
    margin: int = 0
    #: (2, A, Rh, Rh) uint8: where between azimuth ``a`` and ``a + 1`` each texel's horizon
    #: jumps, and how much (:func:`..rays.crossing.encode`: 0 linear), or None (all linear)
    cross: np.ndarray | None = None
    #: (2, A, Rh, Rh) uint8 (encode_spread): the open band's lower and upper edges' spread over
    #: the footprint (:func:`band_edges`; ``q[2:]`` then hold their means), where the map has
    #: bands and footprints; None: the bands' edges are sharp (the centres')
    band_spread: np.ndarray | None = None
    _extend: tuple | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def azimuths(self) -> int:
        return int(self.q.shape[1])

    @property
    def gaps(self) -> bool:
        """Whether the map keeps an open band inside each interval (``q[2:]``)."""
        return int(self.q.shape[0]) == 4

    def without_bands(self) -> "HorizonMap":
        """The same map without its open bands (the hull alone; its island's Extend operator
        shared)."""
        m = HorizonMap(self.q[:2], self.normals, self.spread, self.island, self.margin,
                       self.cross)
        m._extend = self._extend
        return m

    def without_band_spread(self) -> "HorizonMap":
        """The same map with its bands' edges sharp (its island's Extend operator shared)."""
        m = HorizonMap(self.q, self.normals, self.spread, self.island, self.margin, self.cross)
        m._extend = self._extend
        return m

    def extend(self):
        """``(island, dst, op)``: the island's flat texels (P,) ascending, and the margin's
        texels and Extend operator (:func:`..rays.texels.extend_margin`, its columns the
        island's texels) -- or None where the map keeps no island. Built once per map (a map
        made by :func:`from_points` takes the bake's own)."""
        if self.island is None or self.margin <= 0:
            return None
        if self._extend is None:
            from ..rays.texels import extend_margin

            island = np.asarray(self.island, bool)
            dst, op = extend_margin(island, int(self.margin))
            self._extend = (np.flatnonzero(island), dst, op)
        return self._extend

    @property
    def resolution(self) -> int:
        """The texture's side (the normals')."""
        return int(self.normals.shape[0])

    @property
    def horizon_resolution(self) -> int:
        """The horizons' side (<= the texture's)."""
        return int(self.q.shape[2])

    def direct(self, d, sun_angle_deg: float = 0.0, texels=None,
               moments: bool = True) -> np.ndarray:
        """Direct ``E / pi`` (R, R) float32 under a unit sun towards ``d`` (:meth:`direct_codes`
        at each texel), where the map keeps its island (:meth:`extend`) the margin filled from
        the island's light as the bake's Extend margin fills it -- as Cycles bakes a texture and
        T holds it. The codes' own margin (Extend of the edges, the viewport's) is not the same
        light where an edge jumps across the island's border: averaging a lit neighbour's low
        edge with a shadowed one's high edge shades the margin texel dark where Cycles' Extend
        averages their light (on the gallery's mutual shadows at 128^2, a 0.526-degree Sun 3
        degrees high: 90 % of one box's squared error was in margin texels, 0.34 -> 0.18 with
        this fill). ``texels``: flat indices (n,) to compute only there (the same values, bit
        for bit)."""
        if self.island is None or self.margin <= 0:
            return self.direct_codes(d, sun_angle_deg, texels, moments)
        R = self.resolution
        if texels is None:        # the codes' light everywhere, then the margin refilled
            out = self.direct_codes(d, sun_angle_deg, None, moments).reshape(-1)
            island, dst, op = self.extend()
            if len(dst):
                out[dst] = (op @ out[island].astype(np.float64)).astype(np.float32)
            return out.reshape(R, R)
        texels = np.asarray(texels, np.int64).reshape(-1)
        if texels.size and (texels.min() < 0 or texels.max() >= R * R):
            raise IndexError(f"texel indices outside 0..{R * R - 1}")
        flat = np.asarray(self.island, bool).reshape(-1)
        on = flat[texels]
        out = np.zeros(len(texels), np.float32)
        if on.any():
            out[on] = self.direct_codes(d, sun_angle_deg, texels[on], moments)
        if not on.all():          # margin texels (others: 0, as the codes' zero normals)
            island, dst, op = self.extend()
            off = texels[~on]
            pos = np.searchsorted(dst, off)           # (dst ascending: extend_margin's)
            hit = pos < len(dst)
            hit[hit] = dst[pos[hit]] == off[hit]
            if hit.any():
                rows = op[pos[hit]]
                src = np.unique(rows.indices)
                vals = np.zeros(len(island))
                vals[src] = self.direct_codes(d, sun_angle_deg, island[src], moments)
                sub = np.zeros(len(off), np.float32)
                sub[hit] = (rows @ vals).astype(np.float32)
                out[~on] = sub
        return out

    def direct_codes(self, d, sun_angle_deg: float = 0.0, texels=None,
                     moments: bool = True) -> np.ndarray:
        """Direct ``E / pi`` (R, R) float32 under a unit sun towards ``d`` from the codes at
        every texel, the margin's too: the closure
        normal's cosine times the part of the sun's disc outside the blocked interval, read
        across the disc at :data:`STRIPS` azimuths, plus the cosine's slope in elevation
        times that part's first moment (:func:`..rays.horizon.visible_moment`: the cosine
        over the visible part, not at the disc's centre; ``moments`` False: the centre's) --
        the viewport's computation (:func:`...operators.preview.transport_preview.
        build_horizon_group`). ``texels``: flat indices (n,) at the texture's side to compute
        only there (the same values, bit for bit): (n,) float32.

        The moments matter where a wide sun is low: on a floor 0.1 m under a wall's top, a
        10-degree Sun 4 / 6 degrees high erred 0.29 / 0.13 against rays over its disc with the
        centre's cosine, 0.010 / 0.007 with the moments; a 2-degree Sun 4 degrees high 0.043 /
        0.030 (tests/core/test_horizons.py).

        The disc counts only where that linear cosine is positive (:func:`..rays.horizon.
        lit_range`): clipped at the surface's terminator, as each of Cycles' rays is. Over an
        open floor a 10-degree Sun 1 / 2 / 3 degrees high got 0.62 / 0.87 / 0.96 of its light
        without the clip (its part under the floor counted with a negative cosine), within 0.2
        % of the disc's integral with it; a face tilted away from the sun was dark while the
        terminator was above the disc's centre (the same test). A sun whose centre has set is
        dark, as in the other relights: under a floating interval (an eave over a wall, a
        window's top seen from below its sill's height) the map keeps no ground, so the disc
        under the horizon would light there whether a ground blocks it or not (a wall under an
        eave, a 10-degree Sun 3 degrees under the horizon: 0.318 where 0.045 is right; counting
        it blocked instead took the gallery's interior at 1 degree from 0.146 to 0.343).

        At each strip's azimuth (the sun's, and either side of it by 0.54 and 0.91 of the
        disc's radius: :data:`STRIPS`) the disc is cut by that azimuth's interval
        (:func:`..rays.horizon.visible_fraction`; the upper edge by the wider disc of
        :func:`spread_radius` where the map has spreads), the visibility linear between the
        two azimuths around it (interpolating the visibility rather than the edges was measured better: statue demo's
        ground at a 2-degree Sun 0.042 against 0.074) -- or, in a gap where the map keeps a
        crossing (``cross``: a vertical edge), a ramp :data:`..rays.crossing.RAMP` sun radii
        either side of it (:func:`..rays.crossing.warp`); the strips are weighted by the disc's
        chord there. A straight horizon is cut exactly, as by one cut at the sun's azimuth;
        where the horizon changes across a wide sun the strips see it. On the bumps demo (128
        azimuths at 256^2, direct light against 256-spp Cycles, 2026-12-05) a 10-degree Sun
        erred 0.0338 / 0.0136 at 10 / 30 degrees elevation with one cut, 0.0228 / 0.0092 with
        three (cutting chords, not the disc, at five azimuths: 0.0219 / 0.0088; 64 hard suns
        by rays over the disc, the floor: 0.0162 / 0.0093); a 2-degree Sun 0.0333 / 0.0163
        and 0.0336 / 0.0161."""
        d = np.asarray(d, np.float64)
        d = d / np.linalg.norm(d)
        shape = (self.resolution,) * 2 if texels is None else (len(texels),)
        if d[2] <= 0:
            return np.zeros(shape, np.float32)
        A = self.azimuths
        xa = (np.arctan2(d[1], d[0]) % (2 * np.pi)) / (2 * np.pi) * A
        el = np.arcsin(np.clip(d[2], -1.0, 1.0))
        r = max(np.radians(sun_angle_deg) / 2, SUN_RADIUS_MIN)
        # azimuth steps per radian across the disc at this elevation
        across = A / (2 * np.pi) / max(np.cos(el), COS_MIN)
        R = self.resolution
        if texels is None:
            n = self.normals.astype(np.float64)
        else:
            n = self.normals.reshape(-1, 3)[np.asarray(texels)].astype(np.float64)
        length = np.linalg.norm(n, axis=-1)
        # the cosine linear in elevation across the disc: its slope along d / d el
        ch = np.hypot(d[0], d[1])
        g = (np.array([-d[2] * d[0] / ch, -d[2] * d[1] / ch, ch]) if ch > 1e-9 else
             np.zeros(3))
        cos, slope = n @ d, n @ g
        # the elevations where that cosine is positive: the disc is clipped at the terminator
        lit = lit_parts(el, lit_range(el, cos, slope), r)     # (once: the same at every k)
        seen = {}

        def vis_at(k):        # the disc's visible part at azimuth k (strips often share one)
            if k not in seen:
                h = decode(upsample(self.q[:, k], R) if texels is None else
                           upsample_at(self.q[:, k], R, texels))
                r_hi = None
                if self.spread is not None:    # the upper edge's spread over the footprint
                    c = (upsample(self.spread[k], R) if texels is None else
                         upsample_at(self.spread[k], R, texels))
                    r_hi = spread_radius(r, decode_spread(c))
                vis_k = visible_fraction(el, h[0], h[1], r, r_hi, lit)
                # (the sun's own disc: a spread is the edge's over the footprint, seen at
                # the sun's one height)
                mom_k = visible_moment(el, h[0], h[1], r, lit=lit) if moments else 0.0
                if len(h) == 4:      # the open band inside the interval lit again (within it)
                    g_lo = np.clip(np.maximum(h[2], h[0]), lit.a, lit.b)
                    g_hi = np.clip(np.minimum(h[3], h[1]), lit.a, lit.b)
                    r_lo = r_up = r
                    if self.band_spread is not None:   # its edges' spreads: wider discs
                        c = (upsample(self.band_spread[:, k], R) if texels is None else
                             upsample_at(self.band_spread[:, k], R, texels))
                        r_lo, r_up = spread_radius(r, decode_spread(c))
                    # (at most the disc's lit part: the interval's upper edge may be cut by a
                    # wider disc than the band's, which the footprint's mean edge can
                    # lower under the centre's band)
                    vis_k = np.minimum(vis_k + 1.0 - visible_fraction(el, g_lo, g_hi, r_lo,
                                                                      r_up), lit.whole)
                    if moments:
                        mom_k = mom_k - visible_moment(el, g_lo, g_hi, r)
                seen[k] = (vis_k, mom_k)
            return seen[k]
        vis, mom = 0.0, 0.0
        # a crossing's ramp half-width in gaps (:data:`..rays.crossing.RAMP` sun radii)
        ramp = RAMP * r * across
        for x, w in STRIPS:
            xs = xa + x * r * across
            k = np.floor(xs)
            f = xs - k
            k0 = int(k) % A
            if self.cross is not None:    # the gap's vertical edge, where it has one
                c, hc = (upsample(self.cross[:, k0], R) if texels is None else
                         upsample_at(self.cross[:, k0], R, texels))
                f = warp(f, c, hc, ramp)
            (v0, m0), (v1, m1) = vis_at(k0), vis_at((k0 + 1) % A)
            vis = vis + w * ((1 - f) * v0 + f * v1)
            mom = mom + w * ((1 - f) * m0 + f * m1)
        e = np.maximum(cos * vis + slope * mom, 0.0) / np.maximum(length, 1e-12)
        return (e / np.pi).astype(np.float32)

    def gpu_bytes(self) -> int:
        """GPU memory of the viewport's images (:func:`gpu_bytes`)."""
        return gpu_bytes(self.azimuths, self.resolution, self.horizon_resolution,
                         self.spread is not None, self.gaps, self.cross is not None,
                         self.band_spread is not None)

    def without_crossings(self) -> "HorizonMap":
        """The same map with every azimuth gap linear (its island's Extend operator shared)."""
        m = HorizonMap(self.q, self.normals, self.spread, self.island, self.margin,
                       band_spread=self.band_spread)
        m._extend = self._extend
        return m

    def storage_bytes(self) -> int:
        return int(self.q.nbytes + self.normals.nbytes
                   + (self.spread.nbytes if self.spread is not None else 0)
                   + (self.cross.nbytes if self.cross is not None else 0)
                   + (self.band_spread.nbytes if self.band_spread is not None else 0)
                   + (self.island.size if self.island is not None else 0))


def gpu_bytes(azimuths: int, resolution: int, horizon_resolution: int = 0,
              spread: bool = False, gaps: bool = False, cross: bool = False,
              band_spread: bool = False) -> int:
    """GPU memory of a horizon viewport: the lower and upper edges (and their ``spread``, where
    the map has them: a third more tiles; the open bands' two edges, where it has them: two
    thirds more; the gaps' crossings and their weights, ``cross``: two thirds more) as one
    8-bit RGBA atlas (three azimuths per tile) at the horizons' side (:func:`side`, of
    ``horizon_resolution``: 0 lets the bake choose) and the normals with the albedo in a
    half-float RGBA atlas (two tiles) at the texture's; the bands' edges' spreads,
    ``band_spread``: two thirds more. Whether a
    map can be shown at all is decided without the spreads (the bake leaves them out where they
    would not fit the budget)."""
    from ..io.atlas import atlas_layout

    h = atlas_layout((2 + bool(spread) + 2 * (bool(gaps) + bool(cross) + bool(band_spread)))
                     * -(-int(azimuths) // 3),
                     side(resolution, horizon_resolution))
    n = atlas_layout(2, int(resolution))
    return int(h["width"] * h["height"] * 4 + n["width"] * n["height"] * 8)


def from_points(H, texel, resolution: int, normals, margin=None, coarse=None,
                spread=None, margin_texels: int = 0, cross=None,
                band_spread=None) -> HorizonMap:
    """A map from one object's shading points: ``H`` (2, A, P) radians and ``normals`` (P, 3)
    at the covered texels ``texel`` (P,) flat indices; ``margin``: ``(dst, op)`` of
    :func:`..rays.texels.extend_margin`, which fills the bake margin as Cycles' Extend does
    (edges linearly -- a lower edge blocked from below counts as 0 there --, normals then
    renormalised). One azimuth at a time: memory holds the codes and one row.
    ``coarse``: ``(texel, side, margin)`` when ``H`` was found at the points of a coarser
    side (``normals`` stay at ``texel``, ``resolution``), and optionally those points'
    normals (their margin's sources facing away from an azimuth are left out, as
    :func:`_codes` does at the texture's side). ``spread``: (A, P) radians, the upper
    edges' spread over the footprint (:func:`pair_edges`; ``H[1]`` then holds the means),
    or None. ``margin_texels``: the passes of ``margin`` (the bake's Extend margin), kept with
    the covered texels so that the relight fills the margin from the island's light
    (:meth:`HorizonMap.direct`); 0 keeps neither. ``cross``: (A, P) the gaps' crossings, or
    ``(t, w)`` the crossings and their weights (:func:`..rays.crossing.crossings`), or None;
    a gap whose crossing does not matter,
    the margin's first ring of texels too, takes its neighbours' (:func:`..rays.crossing.
    fill`). ``band_spread``: (2, A, P) radians, the open bands' lower and upper edges' spreads
    over the footprint (:func:`band_edges`; ``H[2:]`` then hold the means), or None; kept
    where the map keeps its bands."""
    if coarse is not None:
        h_texel, Rh, h_margin = coarse[:3]
        h_normals = coarse[3] if len(coarse) > 3 else None
    else:
        h_texel, Rh, h_margin = texel, resolution, margin
        h_normals = normals
    q = _codes(H, np.asarray(h_texel), int(Rh), h_margin, h_normals)
    if len(q) == 4 and not (q[3] > q[2]).any():    # no open band anywhere: not kept
        q = q[:2]
    s_codes = (None if spread is None else
               _spread_codes(spread, np.asarray(h_texel), int(Rh), h_margin))
    R = int(resolution)
    texel = np.asarray(texel)
    nrm = np.zeros((R * R, 3))
    nrm[texel] = np.asarray(normals, np.float64)
    if margin is not None and len(margin[0]):
        n = margin[1] @ np.asarray(normals, np.float64)
        nrm[margin[0]] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    island = None
    if margin_texels > 0:
        island = np.zeros(R * R, bool)
        island[texel] = True
        island = island.reshape(R, R)
    c_codes = None
    cross, c_weight = cross if isinstance(cross, tuple) else (cross, None)
    if cross is not None and (np.asarray(cross) >= 0).any():
        from ..rays.crossing import encode, fill

        Rh_ = int(Rh)
        c_codes = np.zeros((2, cross.shape[0], Rh_, Rh_), np.uint8)
        for a in range(cross.shape[0]):      # (one gap at a time: memory)
            T = np.full((1, Rh_ * Rh_), np.nan, np.float32)
            T[0, np.asarray(h_texel)] = cross[a]
            W = None
            if c_weight is not None:
                W = np.zeros((1, Rh_ * Rh_), np.float32)
                W[0, np.asarray(h_texel)] = c_weight[a]
            c_codes[:, a] = encode(*fill(T, Rh_, W))[:, 0].reshape(2, Rh_, Rh_)
    b_codes = None
    if band_spread is not None and len(q) == 4:
        b_codes = np.stack([_spread_codes(np.asarray(band_spread[i]), np.asarray(h_texel),
                                          int(Rh), h_margin) for i in range(2)])
    hm = HorizonMap(q, nrm.reshape(R, R, 3).astype(np.float16), s_codes, island,
                    int(margin_texels) if island is not None else 0, c_codes, b_codes)
    if island is not None and margin is not None:     # the bake's own Extend operator
        hm._extend = (np.flatnonzero(island.reshape(-1)), np.asarray(margin[0]), margin[1])
    return hm


def _spread_codes(S, texel, R: int, margin) -> np.ndarray:
    """The spread codes (A, R, R) of spreads ``S`` (A, P) at ``texel``, the margin filled as
    the edges are (linearly); 0 (sharp) elsewhere."""
    A = S.shape[0]
    out = np.zeros((A, R * R), np.uint8)
    has_margin = margin is not None and len(margin[0])
    for a in range(A):
        img = np.zeros(R * R)
        img[texel] = S[a]
        if has_margin:
            img[margin[0]] = margin[1] @ np.asarray(S[a], np.float64)
        out[a] = encode_spread(img)
    return out.reshape(A, R, R)


def _codes(H, texel, R: int, margin, normals=None) -> np.ndarray:
    """The codes (2, A, R, R) of intervals ``H`` (2, A, P) at ``texel``, margin filled; of
    ``H`` (4, A, P) (open bands inside, ``H[2:]``) (4, A, R, R), an empty band placed at its
    neighbours' (:func:`place_gaps`)."""
    K, A, P = H.shape
    texel = np.asarray(texel)
    q = np.zeros((K, A, R * R), np.uint8)           # uncovered: open, [-pi/2, 0]
    has_margin = margin is not None and len(margin[0])
    covered = np.zeros(R * R, bool)
    covered[texel] = True
    if has_margin:
        import scipy.sparse as sp

        csr = sp.csr_matrix(margin[1])
        rows = np.repeat(np.arange(csr.shape[0]), np.diff(csr.indptr))
        nrm = None if normals is None else np.asarray(normals, np.float64)[csr.indices]
    for a in range(A):
        img = np.zeros((K, R * R))
        img[0] = FROM_BELOW
        img[:, texel] = H[:, a]
        if K == 4:
            place_gaps(img[2:], covered, R)
        if has_margin:
            dst = margin[0]
            op = csr
            if nrm is not None:
                # a source facing away from this azimuth (none of its elevations in front:
                # its interval is "open" for want of a cosine) is left out of the mean: a box
                # top's [25, 90] and its side's open mixed to [12, 45] opened the sky over a
                # closed room's box
                phi = 2 * np.pi * a / A
                e0 = np.arctan2(nrm[:, 2], nrm[:, 0] * np.cos(phi) + nrm[:, 1] * np.sin(phi))
                away = (e0 > np.pi - BACK) | (e0 < BACK - np.pi / 2)
                if away.any():
                    w = np.where(away, 0.0, csr.data)
                    total = np.bincount(rows, weights=w, minlength=csr.shape[0])
                    keep = total > 0                  # (all away: the mean of all)
                    w = np.where(keep[rows], w / np.where(keep, total, 1.0)[rows], csr.data)
                    op = sp.csr_matrix((w, csr.indices, csr.indptr), shape=csr.shape)
            lo = np.asarray(H[0, a], np.float64)
            below = lo < 0
            share = op @ below.astype(np.float64)          # weight of "from below"
            img[0, dst] = np.where(share >= 0.5, FROM_BELOW, op @ np.where(below, 0.0, lo))
            img[1, dst] = op @ np.asarray(H[1, a], np.float64)
            if K == 4:
                img[2:, dst] = np.stack([op @ img[2, texel], op @ img[3, texel]])
        q[:, a] = quantize(img)
    return q.reshape(K, A, R, R)


#: A margin's source counts as facing away from an azimuth when fewer than this many radians
#: of its elevations 0-90 degrees along it are in front (:func:`_codes`): 5 degrees.
BACK = np.radians(5.0)


def place_gaps(G, covered, R: int) -> None:
    """An empty open band (``G`` (2, R * R) radians, ``lo >= hi``) of a covered texel next to
    texels with one becomes ``[m, m]``, ``m`` the mean middle of theirs: between the two the
    viewport's linear lookup then narrows the band to nothing where it is, instead of moving
    it towards wherever the empty one sat. In place."""
    lo, hi = G[0].reshape(R, R), G[1].reshape(R, R)
    has = ((hi > lo) & covered.reshape(R, R))
    if not has.any():
        G[:] = 0.0
        return
    mid = np.where(has, 0.5 * (lo + hi), 0.0)
    pad_m, pad_h = np.pad(mid, 1), np.pad(has.astype(np.float64), 1)
    s = sum(pad_m[1 + dy:R + 1 + dy, 1 + dx:R + 1 + dx] for dy, dx in _FOUR)
    w = sum(pad_h[1 + dy:R + 1 + dy, 1 + dx:R + 1 + dx] for dy, dx in _FOUR)
    m = np.where(w > 0, s / np.maximum(w, 1.0), 0.0)
    empty = ~has
    lo[empty] = m[empty]
    hi[empty] = m[empty]


_FOUR = ((0, 1), (0, -1), (1, 0), (-1, 0))


#: The lowest elevation (degrees) of a held-out direction on a Sun's path.
PATH_HELDOUT_MIN_DEG = 1.0


def heldout_directions(count: int = 16, seed: int = 0, path=None) -> np.ndarray:
    """``count`` unit directions (count, 3) off any baked set: half with elevations 3-20
    degrees (where shadows are long and sets are sparse), half 20-85, azimuths spread by the
    golden angle from a seeded start. ``path`` (P, 3): the baked directions along the scene
    Sun's animated path, in order: the Sun the viewport will show is on it, so the directions
    are midway between consecutive ones (those at least :data:`PATH_HELDOUT_MIN_DEG` high,
    evenly along the path; where fewer than ``count / 2`` are, the sky's as above) -- on the
    gallery's animated day Sun T, which holds the path, was 3 times closer to Cycles than the
    horizon map the sky's directions chose (0.019 against 0.059 at 3 degrees)."""
    if path is not None and len(path) > 1:
        p = np.asarray(path, np.float64)
        mid = p[:-1] + p[1:]
        mid /= np.maximum(np.linalg.norm(mid, axis=1, keepdims=True), 1e-12)
        # consecutive samples of one curve (a band or several days' paths jump between them)
        gap = np.arccos(np.clip(np.einsum("ij,ij->i", p[:-1], p[1:]), -1.0, 1.0))
        ok = (gap <= 1.5 * np.median(gap)) & \
            (mid[:, 2] >= np.sin(np.radians(PATH_HELDOUT_MIN_DEG)))
        cand = mid[ok]
        if len(cand) >= max(1, count // 2):
            pick = np.unique(np.linspace(0, len(cand) - 1, min(count, len(cand))).round()
                             .astype(np.int64))
            return cand[pick]
    rng = np.random.default_rng(seed)
    half = count // 2
    el = np.concatenate([np.linspace(3, 20, half, endpoint=False),
                         np.linspace(20, 85, count - half)]) + rng.uniform(0, 1.5, count)
    az = (rng.uniform(0, 360) + 137.50776 * np.arange(count)) % 360
    a, e = np.radians(az), np.radians(el)
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1)


def heldout_errors(hm: HorizonMap, store, directions, rows, sun_angle: float,
                   kernel: str = "linear", texels=None) -> dict:
    """Both viewports' direct light against rays at held-out directions: ``rows`` (n, R*R) the
    mean of hard suns by rays over each sun's disc (``directions`` (n, 3), ``sun_angle``
    degrees), against which the horizon map's relight and T's kernel relight (what the T
    viewport shows, before its tables) are compared. Relative RMSE over texels, combined over
    the directions as ``sqrt(sum err^2 / sum ref^2)``, and per direction. ``texels``: flat
    indices (m,) to compare at only (``rows`` then (n, m)): the trial on sampled tiles
    (:mod:`.horizon_trial`). Both fill the bake margin from their island's light (T holds it
    so; the map's :meth:`HorizonMap.direct`), as Cycles' texture does: the margin, which the
    viewport reads only at an island's border, counts alike for both."""
    from . import texture as tt

    num = {"horizon": 0.0, "transport": 0.0}
    den = 0.0
    per = []
    for d, ref in zip(np.asarray(directions, np.float64), rows):
        ref = np.asarray(ref, np.float64).reshape(-1)
        idx, w = tt.sun_weights(store.directions, d, sun_angle, kernel)
        got = {"horizon": hm.direct(d, sun_angle, texels).reshape(-1).astype(np.float64),
               "transport": store.relight(idx, w, texels).reshape(-1).astype(np.float64)}
        n2 = float(ref @ ref)
        den += n2
        row = {"elevation": round(float(np.degrees(np.arcsin(d[2]))), 2)}
        for k, v in got.items():
            e2 = float(np.sum((v - ref) ** 2))
            num[k] += e2
            row[k] = round(float(np.sqrt(e2 / max(n2, 1e-30))), 4)
        per.append(row)
    return {**{k: float(np.sqrt(v / max(den, 1e-30))) for k, v in num.items()},
            "directions": per, "sun_angle": float(sun_angle)}


def save(path: str, hm: HorizonMap) -> None:
    """Write ``<object>_horizons.npz`` atomically (whole or not at all)."""
    from ..io import atomic, versions

    with atomic.atomic_path(path) as tmp:
        extra = {} if hm.spread is None else {"spread": hm.spread}
        if hm.cross is not None:
            extra["cross"] = hm.cross
        if hm.band_spread is not None:
            extra["band_spread"] = hm.band_spread
        if hm.island is not None and hm.margin > 0:
            extra.update(island=np.asarray(hm.island, np.uint8),
                         margin=np.array(int(hm.margin)))
        save_npz(tmp, compressed=True, q=hm.q, normals=hm.normals, **extra,
                 **{k: np.array(v) for k, v in versions.stamp(FORMAT).items()})


#: The widest bake margin a map may say it has (texels): the bakes' own (``ray_direct.bake``,
#: Cycles' sessions alike). Its Extend operator grows with the margin's square per texel: a
#: file's wider margin over a crafted island would make the first relight build a huge one.
MAX_MARGIN = 4


def load(path: str, resolution: int | None = None) -> HorizonMap:
    """The map :func:`save` wrote (a newer format version is refused in one line), read as a
    file from elsewhere (:func:`..io.untrusted.open_npz`: capped, each array's header checked
    before it is inflated): ``q`` (2, A, Rh, Rh) uint8 with 3 <= A <= 4096 azimuths, Rh at
    most the texture's side; ``spread`` (A, Rh, Rh), ``cross`` and ``band_spread`` (2, A, Rh,
    Rh) uint8 where present; ``normals`` (R, R, 3) float16, finite, R = ``resolution``
    (T's) when given."""
    from ..io import untrusted as ut, versions

    with ut.open_npz(path) as z:
        version = ut.npz_scalar(z, "format_version", int)
        versions.check({"format": ut.npz_scalar(z, "format", str),
                        "format_version": version}, FORMAT, path, "a horizon map")
        (n_shape, n_dtype) = z.header("normals") if "normals" in z else ((), None)
        R = resolution if resolution is not None else (n_shape[0] if n_shape else 1)
        ut.check_count(path, R, ut.MAX_RESOLUTION, "resolution", lo=1)
        normals = z.get("normals", shape=(R, R, 3), dtype="f")
        qs, _ = z.header("q") if "q" in z else ((), None)
        if (len(qs) != 4 or qs[0] not in (2, 4) or not 3 <= qs[1] <= 4096
                or not 1 <= qs[2] <= R or qs[2] != qs[3] or (qs[0] == 4 and version < 5)):
            raise ut.UntrustedFileError(path, f"has horizon codes of shape {qs}, expected "
                                              f"(2 or 4, azimuths 3..4096, Rh, Rh) with "
                                              f"Rh <= {R}")
        q = z.get("q", shape=(int(qs[0]), None, None, None), dtype=np.uint8)
        spread = (z.get("spread", shape=tuple(qs[1:]), dtype=np.uint8) if "spread" in z
                  else None)          # (version 2 maps have none: sharp edges)
        if "cross" in z and version < 6:
            raise ut.UntrustedFileError(path, f"has crossings in a format {version} map (they "
                                              f"came with format 6)")
        cross = (z.get("cross", shape=(2,) + tuple(qs[1:]), dtype=np.uint8) if "cross" in z
                 else None)           # (maps before 2026-12-07 have none: linear gaps)
        if "band_spread" in z and (version < 7 or qs[0] != 4):
            raise ut.UntrustedFileError(path, f"has band spreads in a format {version} map "
                                              f"with {qs[0]} code planes (they came with "
                                              f"format 7, with open bands)")
        band_spread = (z.get("band_spread", shape=(2,) + tuple(qs[1:]), dtype=np.uint8)
                       if "band_spread" in z else None)     # (before 2026-12-08: sharp)
        island, margin = None, 0
        if "island" in z:                 # (maps before 2026-12-07 have none)
            island = np.asarray(z.get("island", shape=(R, R), dtype=np.uint8)) != 0
            margin = ut.npz_scalar(z, "margin", int)
            ut.check_count(path, margin, MAX_MARGIN, "margin", lo=1)
            if not island.any():
                raise ut.UntrustedFileError(path, "has an island without a covered texel")
        ut.check_values(path, normals, what="normals")
        q = np.asarray(q, np.uint8)
        if version < 4:                      # codes from the horizon up (recoded)
            q = recode_v3(q)
        return HorizonMap(q, np.asarray(normals, np.float16),
                          None if spread is None else np.asarray(spread, np.uint8),
                          island, margin, None if cross is None else np.asarray(cross, np.uint8),
                          None if band_spread is None else np.asarray(band_spread, np.uint8))
