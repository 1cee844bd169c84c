"""The horizon map: a texture's direct sunlight as per-texel horizons and shading normals.

A relightable texture's direct term under a sun towards ``d`` (unit, world space) of angular
diameter ``a`` is ``E / pi = cos(N, d) * V / pi``. The transport store holds it at S baked
directions, and a light between them blends its neighbours' shadows: a low sun's shadow is drawn
as faint offset copies (ghosting). The horizon map holds instead, per texel and for each of ``A``
azimuths, the elevations ``[lo, hi]`` between which the sky is blocked (:mod:`..rays.horizon`,
found by rays), and the texel's closure normal. A sun is visible outside the interval -- for a
disc, the part of it outside (:func:`..rays.horizon.visible_fraction`) -- so a shadow edge moves
continuously with the sun, at any sun size, from ``2 A`` bytes per texel.

It is exact where a texel's occluded elevations along an azimuth form one interval; where they
form two (the sky between), their hull darkens the gap. Before the viewport is chosen,
:func:`heldout_errors` measures the map and T against rays at directions neither holds.

Arrays: ``q`` (2, A, R, R) uint8 codes -- ``q[1]`` the upper edges ``hi = q / 255 * pi / 2``,
``q[0]`` the lower edges, the same but code 0 for "blocked from below" (``-pi / 2``); rows from
v = 0 -- and ``normals`` (R, R, 3) float16 world unit vectors (zeros on texels no triangle
covers). Azimuth ``a`` is ``2 pi a / A`` from +x toward +y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rays.horizon import FROM_BELOW, visible_fraction

FORMAT = "relightable_textures.horizon_map"
#: Azimuths of a horizon map by default: 2.8 degrees apart. Measured on the bumps demo at 256^2
#: (benchmarks/bench_ray_horizons.py, direct light against 128-spp Cycles at 10 degrees
#: elevation, 2-degree Sun): 32 azimuths 0.100, 64 0.050, 128 0.030; 64 hard suns by rays
#: over the disc (no table) 0.025; T at 1600 directions 0.143.
DEFAULT_AZIMUTHS = 128
#: The smallest sun radius (radians) the relight uses: a point sun is a disc this small, so the
#: NumPy relight and the viewport's node tree compute the same thing at every size.
SUN_RADIUS_MIN = 1e-4
#: Radians per code step (0.35 degrees).
STEP = np.pi / 2 / 255.0


def quantize(H) -> np.ndarray:
    """Intervals (2, ...) in radians -> uint8 codes (module docstring): upper edges in
    [0, pi/2] round to 0..255; lower edges below 0 (blocked from below) are code 0, others
    round to 1..255."""
    H = np.asarray(H, np.float64)
    q = np.rint(np.clip(H / (np.pi / 2), 0.0, 1.0) * 255.0).astype(np.uint8)
    q[0] = np.where(H[0] < 0, 0, np.maximum(q[0], 1))
    return q


def decode(q) -> np.ndarray:
    """uint8 codes (2, ...) -> radians float64 (lower code 0 -> ``-pi/2``)."""
    h = np.asarray(q, np.float64) * STEP
    h[0] = np.where(np.asarray(q[0]) == 0, FROM_BELOW, h[0])
    return h


@dataclass
class HorizonMap:
    q: np.ndarray          # (2, A, R, R) uint8
    normals: np.ndarray    # (R, R, 3) float16

    @property
    def azimuths(self) -> int:
        return int(self.q.shape[1])

    @property
    def resolution(self) -> int:
        return int(self.q.shape[2])

    def direct(self, d, sun_angle_deg: float = 0.0) -> np.ndarray:
        """Direct ``E / pi`` (R, R) float32 under a unit sun towards ``d``: the closure
        normal's cosine times the part of the sun's disc outside the blocked interval, at the
        two azimuths around the sun's and linear between them -- the viewport's computation
        (:func:`...operators.preview.transport_preview.build_horizon_group`). Interpolating the
        visibility rather than the edges between azimuths was measured better at a 2-degree
        Sun (statue demo's ground at 10 degrees elevation: 0.042 against 0.074; bumps 0.033
        against 0.031, and 0.016 against 0.019 at 30 degrees;
        benchmarks/bench_ray_horizons.py)."""
        d = np.asarray(d, np.float64)
        d = d / np.linalg.norm(d)
        if d[2] <= 0:
            return np.zeros((self.resolution,) * 2, np.float32)
        A = self.azimuths
        x = (np.arctan2(d[1], d[0]) % (2 * np.pi)) / (2 * np.pi) * A
        k0 = int(np.floor(x)) % A
        f = x - np.floor(x)
        el = np.arcsin(np.clip(d[2], -1.0, 1.0))
        r = max(np.radians(sun_angle_deg) / 2, SUN_RADIUS_MIN)
        h0, h1 = decode(self.q[:, k0]), decode(self.q[:, (k0 + 1) % A])
        vis = (1 - f) * visible_fraction(el, *h0, r) + f * visible_fraction(el, *h1, r)
        n = self.normals.astype(np.float64)
        length = np.linalg.norm(n, axis=-1)
        cos = np.maximum(n @ d, 0.0) / np.maximum(length, 1e-12)
        return (cos * vis / np.pi).astype(np.float32)

    def gpu_bytes(self) -> int:
        """GPU memory of the viewport's images (:func:`gpu_bytes`)."""
        return gpu_bytes(self.azimuths, self.resolution)

    def storage_bytes(self) -> int:
        return int(self.q.nbytes + self.normals.nbytes)


def gpu_bytes(azimuths: int, resolution: int) -> int:
    """GPU memory of a horizon viewport: the lower and upper edges as one 8-bit RGBA atlas
    (three azimuths per tile) and the normals with the albedo in a half-float RGBA atlas (two
    tiles)."""
    from ..io.atlas import atlas_layout

    h = atlas_layout(2 * -(-int(azimuths) // 3), int(resolution))
    n = atlas_layout(2, int(resolution))
    return int(h["width"] * h["height"] * 4 + n["width"] * n["height"] * 8)


def from_points(H, texel, resolution: int, normals, margin=None) -> HorizonMap:
    """A map from one object's shading points: ``H`` (2, A, P) radians and ``normals`` (P, 3)
    at the covered texels ``texel`` (P,) flat indices; ``margin``: ``(dst, op)`` of
    :func:`..rays.texels.extend_margin`, which fills the bake margin as Cycles' Extend does
    (edges linearly -- a lower edge blocked from below counts as 0 there --, normals then
    renormalised). One azimuth at a time: memory holds the codes and one row."""
    _, A, P = H.shape
    R = int(resolution)
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
    nrm = np.zeros((R * R, 3))
    nrm[texel] = np.asarray(normals, np.float64)
    if has_margin:
        n = margin[1] @ np.asarray(normals, np.float64)
        nrm[margin[0]] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return HorizonMap(q.reshape(2, A, R, R), nrm.reshape(R, R, 3).astype(np.float16))


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
                   kernel: str = "linear") -> dict:
    """Both viewports' direct light against rays at held-out directions: ``rows`` (n, R*R) the
    mean of hard suns by rays over each sun's disc (``directions`` (n, 3), ``sun_angle``
    degrees), against which the horizon map's relight and T's kernel relight (what the T
    viewport shows, before its tables) are compared. Relative RMSE over texels, combined over
    the directions as ``sqrt(sum err^2 / sum ref^2)``, and per direction."""
    from . import texture as tt

    num = {"horizon": 0.0, "transport": 0.0}
    den = 0.0
    per = []
    for d, ref in zip(np.asarray(directions, np.float64), rows):
        ref = np.asarray(ref, np.float64).reshape(-1)
        idx, w = tt.sun_weights(store.directions, d, sun_angle, kernel)
        got = {"horizon": hm.direct(d, sun_angle).reshape(-1).astype(np.float64),
               "transport": store.relight(idx, w).reshape(-1).astype(np.float64)}
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
        np.savez_compressed(tmp, q=hm.q, normals=hm.normals,
                            **{k: np.array(v) for k, v in versions.stamp(FORMAT).items()})


def load(path: str) -> HorizonMap:
    """The map :func:`save` wrote (a newer format version is refused in one line)."""
    from ..io import versions

    with np.load(path, allow_pickle=False) as z:
        versions.check({"format": str(z["format"]), "format_version": int(z["format_version"])},
                       FORMAT, path, "a horizon map")
        return HorizonMap(np.asarray(z["q"], np.uint8), np.asarray(z["normals"], np.float16))
