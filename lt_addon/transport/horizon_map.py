"""The horizon map: a texture's direct sunlight as per-texel horizons and shading normals.

A relightable texture's direct term under a sun towards ``d`` (unit, world space) of angular
diameter ``a`` is ``E / pi = cos(N, d) * V / pi``. The transport store holds it at S baked
directions, and a light between them blends its neighbours' shadows: a low sun's shadow is drawn
as faint offset copies (ghosting). The horizon map holds instead, per texel and for each of ``A``
azimuths, the elevations ``[lo, hi]`` between which the sky is blocked (:mod:`..rays.horizon`,
found by rays), and the texel's closure normal. A sun is visible outside the interval -- for a
disc, the part of it outside (:func:`..rays.horizon.visible_fraction`), read at three azimuths
across the disc (:data:`STRIPS`) -- so a shadow edge moves continuously with the sun, at any sun
size, from ``2 A`` bytes per texel.

It is exact where a texel's occluded elevations along an azimuth form one interval; where they
form two (the sky between), their hull darkens the gap. Before the viewport is chosen,
:func:`heldout_errors` measures the map and T against rays at directions neither holds.

Arrays: ``q`` (2, A, Rh, Rh) uint8 codes -- ``q[1]`` the upper edges ``hi = q / 255 * pi / 2``,
``q[0]`` the lower edges, the same but code 0 for "blocked from below" (``-pi / 2``); rows from
v = 0 -- and ``normals`` (R, R, 3) float16 world unit vectors (zeros on texels no triangle
covers). Azimuth ``a`` is ``2 pi a / A`` from +x toward +y.

The horizons may be kept at a coarser side ``Rh`` than the texture's ``R`` (:func:`side`): a
shadow's edge is as sharp as the sun's penumbra, which on a large receiver spans many texels
(a 2-degree sun over an object 1 m high: 35 mm; a 5 m ground at 2048^2: 2.4 mm texels), while
the horizons' memory and rays grow with the texels. The texture's texels then read the codes
bilinearly at their centres, as the viewport's linear image lookup does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rays.horizon import FROM_BELOW, visible_fraction
from ..io.npz import save_npz

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
#: radii, weight), the 3-point Gauss-Legendre rule weighted by the chord sqrt(1 - x^2) there,
#: normalised.
_X = np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
_W = np.array([5 / 9, 8 / 9, 5 / 9]) * np.sqrt(1 - _X * _X)
STRIPS = tuple(zip(_X.tolist(), (_W / _W.sum()).tolist()))
#: The smallest cos(elevation) the strips' azimuth offsets divide by (a sun near the zenith
#: spans every azimuth; its disc is then read over 1/COS_MIN radii of azimuth at most).
COS_MIN = 1e-3
#: Radians per code step (0.35 degrees).
STEP = np.pi / 2 / 255.0
#: The horizons' side at most when the settings leave it to the bake (0). With 128 azimuths a
#: 2048^2 texture's horizon viewport then takes 426 MiB of GPU memory (its normals and albedo
#: at 2048^2 included; 1507 MiB with the horizons at 2048^2), within the default 512 MiB
#: budget; a 4096^2 texture's 618 MiB.
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


def quantize(H) -> np.ndarray:
    """Intervals (2, ...) in radians -> uint8 codes (module docstring): upper edges in
    [0, pi/2] round to 0..255; lower edges below 0 (blocked from below) are code 0, others
    round to 1..255."""
    H = np.asarray(H, np.float64)
    q = np.rint(np.clip(H / (np.pi / 2), 0.0, 1.0) * 255.0).astype(np.uint8)
    q[0] = np.where(H[0] < 0, 0, np.maximum(q[0], 1))
    return q


def decode(q) -> np.ndarray:
    """Codes (2, ...) -> radians float64: uint8 codes, or codes interpolated between texels
    as floats -- the viewport's rule: ``q * STEP``, and a lower code under 0.5 is "from
    below", ``q * STEP - pi/2`` (exactly ``-pi/2`` for code 0)."""
    qf = np.asarray(q, np.float64)
    h = qf * STEP
    h[0] = np.where(qf[0] < 0.5, h[0] + FROM_BELOW, h[0])
    return h


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


@dataclass
class HorizonMap:
    q: np.ndarray          # (2, A, Rh, Rh) uint8
    normals: np.ndarray    # (R, R, 3) float16

    @property
    def azimuths(self) -> int:
        return int(self.q.shape[1])

    @property
    def resolution(self) -> int:
        """The texture's side (the normals')."""
        return int(self.normals.shape[0])

    @property
    def horizon_resolution(self) -> int:
        """The horizons' side (<= the texture's)."""
        return int(self.q.shape[2])

    def direct(self, d, sun_angle_deg: float = 0.0, texels=None) -> np.ndarray:
        """Direct ``E / pi`` (R, R) float32 under a unit sun towards ``d``: the closure
        normal's cosine times the part of the sun's disc outside the blocked interval, read
        across the disc at :data:`STRIPS` azimuths -- the viewport's computation
        (:func:`...operators.preview.transport_preview.build_horizon_group`). ``texels``: flat
        indices (n,) at the texture's side to compute only there (the same values, bit for
        bit): (n,) float32.

        At each strip's azimuth (the sun's, and either side of it by 0.77 of the disc's
        radius) the disc is cut by that azimuth's interval (:func:`..rays.horizon.
        visible_fraction`), the visibility linear between the two azimuths around it
        (interpolating the visibility rather than the edges was measured better: statue demo's
        ground at a 2-degree Sun 0.042 against 0.074); the strips are weighted by the disc's
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
        seen = {}

        def vis_at(k):        # the disc's visible part at azimuth k (strips often share one)
            if k not in seen:
                h = decode(upsample(self.q[:, k], R) if texels is None else
                           upsample_at(self.q[:, k], R, texels))
                seen[k] = visible_fraction(el, *h, r)
            return seen[k]
        vis = 0.0
        for x, w in STRIPS:
            xs = xa + x * r * across
            k = np.floor(xs)
            f = xs - k
            k0 = int(k) % A
            vis = vis + w * ((1 - f) * vis_at(k0) + f * vis_at((k0 + 1) % A))
        if texels is None:
            n = self.normals.astype(np.float64)
        else:
            n = self.normals.reshape(-1, 3)[np.asarray(texels)].astype(np.float64)
        length = np.linalg.norm(n, axis=-1)
        cos = np.maximum(n @ d, 0.0) / np.maximum(length, 1e-12)
        return (cos * vis / np.pi).astype(np.float32)

    def gpu_bytes(self) -> int:
        """GPU memory of the viewport's images (:func:`gpu_bytes`)."""
        return gpu_bytes(self.azimuths, self.resolution, self.horizon_resolution)

    def storage_bytes(self) -> int:
        return int(self.q.nbytes + self.normals.nbytes)


def gpu_bytes(azimuths: int, resolution: int, horizon_resolution: int = 0) -> int:
    """GPU memory of a horizon viewport: the lower and upper edges as one 8-bit RGBA atlas
    (three azimuths per tile) at the horizons' side (:func:`side`, of ``horizon_resolution``:
    0 lets the bake choose) and the normals with the albedo in a half-float RGBA atlas (two
    tiles) at the texture's."""
    from ..io.atlas import atlas_layout

    h = atlas_layout(2 * -(-int(azimuths) // 3), side(resolution, horizon_resolution))
    n = atlas_layout(2, int(resolution))
    return int(h["width"] * h["height"] * 4 + n["width"] * n["height"] * 8)


def from_points(H, texel, resolution: int, normals, margin=None, coarse=None) -> HorizonMap:
    """A map from one object's shading points: ``H`` (2, A, P) radians and ``normals`` (P, 3)
    at the covered texels ``texel`` (P,) flat indices; ``margin``: ``(dst, op)`` of
    :func:`..rays.texels.extend_margin`, which fills the bake margin as Cycles' Extend does
    (edges linearly -- a lower edge blocked from below counts as 0 there --, normals then
    renormalised). One azimuth at a time: memory holds the codes and one row.
    ``coarse``: ``(texel, side, margin)`` when ``H`` was found at the points of a coarser
    side (``normals`` stay at ``texel``, ``resolution``)."""
    if coarse is not None:
        h_texel, Rh, h_margin = coarse
        q = _codes(H, np.asarray(h_texel), int(Rh), h_margin)
    else:
        q = _codes(H, np.asarray(texel), int(resolution), margin)
    R = int(resolution)
    texel = np.asarray(texel)
    nrm = np.zeros((R * R, 3))
    nrm[texel] = np.asarray(normals, np.float64)
    if margin is not None and len(margin[0]):
        n = margin[1] @ np.asarray(normals, np.float64)
        nrm[margin[0]] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return HorizonMap(q, nrm.reshape(R, R, 3).astype(np.float16))


def _codes(H, texel, R: int, margin) -> np.ndarray:
    """The codes (2, A, R, R) of intervals ``H`` (2, A, P) at ``texel``, margin filled."""
    _, A, P = H.shape
    texel = np.asarray(texel)
    q = np.zeros((2, A, R * R), np.uint8)           # uncovered: open, [-pi/2, 0]
    has_margin = margin is not None and len(margin[0])
    for a in range(A):
        img = np.zeros((2, R * R))
        img[0] = FROM_BELOW
        img[:, texel] = H[:, a]
        if has_margin:
            dst, op = margin
            lo = np.asarray(H[0, a], np.float64)
            below = lo < 0
            share = op @ below.astype(np.float64)          # weight of "from below"
            img[0, dst] = np.where(share >= 0.5, FROM_BELOW, op @ np.where(below, 0.0, lo))
            img[1, dst] = op @ np.asarray(H[1, a], np.float64)
        q[:, a] = quantize(img)
    return q.reshape(2, A, R, R)


def heldout_directions(count: int = 16, seed: int = 0) -> np.ndarray:
    """``count`` unit directions (count, 3) off any baked set: half with elevations 3-20
    degrees (where shadows are long and sets are sparse), half 20-85, azimuths spread by the
    golden angle from a seeded start."""
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
    (:mod:`.horizon_trial`)."""
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
        save_npz(tmp, compressed=True, q=hm.q, normals=hm.normals,
                 **{k: np.array(v) for k, v in versions.stamp(FORMAT).items()})


def load(path: str, resolution: int | None = None) -> HorizonMap:
    """The map :func:`save` wrote (a newer format version is refused in one line), read as a
    file from elsewhere (:func:`..io.untrusted.open_npz`: capped, each array's header checked
    before it is inflated): ``q`` (2, A, Rh, Rh) uint8 with 3 <= A <= 4096 azimuths, Rh at
    most the texture's side; ``normals`` (R, R, 3) float16, finite, R = ``resolution``
    (T's) when given."""
    from ..io import untrusted as ut, versions

    with ut.open_npz(path) as z:
        versions.check({"format": ut.npz_scalar(z, "format", str),
                        "format_version": ut.npz_scalar(z, "format_version", int)},
                       FORMAT, path, "a horizon map")
        (n_shape, n_dtype) = z.header("normals") if "normals" in z else ((), None)
        R = resolution if resolution is not None else (n_shape[0] if n_shape else 1)
        ut.check_count(path, R, ut.MAX_RESOLUTION, "resolution", lo=1)
        normals = z.get("normals", shape=(R, R, 3), dtype="f")
        qs, _ = z.header("q") if "q" in z else ((), None)
        if len(qs) != 4 or not 3 <= qs[1] <= 4096 or not 1 <= qs[2] <= R or qs[2] != qs[3]:
            raise ut.UntrustedFileError(path, f"has horizon codes of shape {qs}, expected "
                                              f"(2, azimuths 3..4096, Rh, Rh) with Rh <= {R}")
        q = z.get("q", shape=(2, None, None, None), dtype=np.uint8)
        ut.check_values(path, normals, what="normals")
        return HorizonMap(np.asarray(q, np.uint8), np.asarray(normals, np.float16))
