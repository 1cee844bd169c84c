"""The horizon map: a texture's direct sunlight as per-texel horizons and shading normals.

A relightable texture's direct term under a sun towards ``d`` (unit, world space) of angular
diameter ``a`` is ``E / pi = cos(N, d) * V / pi``. The transport store holds it at S baked
directions, and a light between them blends its neighbours' shadows: a low sun's shadow is drawn
as faint offset copies (ghosting). The horizon map holds instead, per texel, the elevation
``h(phi)`` above which the sky is open along each of ``A`` azimuths (:mod:`..rays.horizon`, found
by rays), and the texel's closure normal. A sun is then visible where it stands above the
horizon line -- for a disc, the part of it above the line (:func:`..rays.horizon.disc_fraction`)
-- so a shadow edge moves continuously with the sun, at any sun size, from ``A`` bytes per texel.

It is exact where a texel's occluded elevations along an azimuth form one interval from below
(heightfields, a ground under an object); where the sky shows below an overhang it is not, and
:func:`agreement` measures that against T's own rays before the viewport is chosen.

Arrays: ``q`` (A, R, R) uint8, ``h = q / 255 * pi / 2`` (row 0 at v = 0); ``normals`` (R, R, 3)
float16 world unit vectors (zeros on texels no triangle covers). Azimuth ``a`` is
``2 pi a / A`` from +x toward +y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rays.horizon import disc_fraction

FORMAT = "relightable_textures.horizon_map"
#: Azimuths of a horizon map by default: 2.8 degrees apart. Measured on the bumps demo at 256^2
#: (benchmarks/bench_ray_horizons.py, direct light against 128-spp Cycles at 10 degrees
#: elevation, 2-degree Sun): 32 azimuths 0.100, 64 0.050, 128 0.030; 64 hard suns by rays
#: over the disc (no table) 0.025; T at 1600 directions 0.143.
DEFAULT_AZIMUTHS = 128
#: The smallest sun radius (radians) the relight uses: a point sun is a disc this small, so the
#: NumPy relight and the viewport's node tree compute the same thing at every size.
SUN_RADIUS_MIN = 1e-4


def quantize(H) -> np.ndarray:
    """Horizons in radians [0, pi/2] -> uint8 codes (0.35 degrees a step)."""
    x = np.clip(np.asarray(H, np.float64) / (np.pi / 2), 0.0, 1.0)
    return np.rint(x * 255.0).astype(np.uint8)


@dataclass
class HorizonMap:
    q: np.ndarray          # (A, R, R) uint8
    normals: np.ndarray    # (R, R, 3) float16

    @property
    def azimuths(self) -> int:
        return int(self.q.shape[0])

    @property
    def resolution(self) -> int:
        return int(self.q.shape[1])

    def horizons(self) -> np.ndarray:
        """(A, R, R) float32 radians."""
        return self.q.astype(np.float32) * np.float32(np.pi / 2 / 255.0)

    def direct(self, d, sun_angle_deg: float = 0.0) -> np.ndarray:
        """Direct ``E / pi`` (R, R) float32 under a unit sun towards ``d``: the closure
        normal's cosine times the part of the sun's disc above the horizon line (linear between
        the two azimuths around the sun's), the viewport's computation
        (:func:`...operators.preview.transport_preview.build_horizon_group`)."""
        d = np.asarray(d, np.float64)
        d = d / np.linalg.norm(d)
        if d[2] <= 0:
            return np.zeros((self.resolution,) * 2, np.float32)
        A = self.azimuths
        x = (np.arctan2(d[1], d[0]) % (2 * np.pi)) / (2 * np.pi) * A
        k0 = int(np.floor(x)) % A
        f = x - np.floor(x)
        q = (1 - f) * self.q[k0].astype(np.float64) + f * self.q[(k0 + 1) % A]
        h = q * (np.pi / 2 / 255.0)
        el = np.arcsin(np.clip(d[2], -1.0, 1.0))
        r = max(np.radians(sun_angle_deg) / 2, SUN_RADIUS_MIN)
        vis = disc_fraction((el - h) / r)
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
    """GPU memory of a horizon viewport: the horizons as an 8-bit RGBA atlas (three azimuths
    per tile) and the normals with the albedo in a half-float RGBA atlas (two tiles)."""
    from ..io.atlas import atlas_layout

    h = atlas_layout(-(-int(azimuths) // 3), int(resolution))
    n = atlas_layout(2, int(resolution))
    return int(h["width"] * h["height"] * 4 + n["width"] * n["height"] * 8)


def from_points(H, texel, resolution: int, normals, margin=None) -> HorizonMap:
    """A map from one object's shading points: ``H`` (A, P) radians and ``normals`` (P, 3) at
    the covered texels ``texel`` (P,) flat indices; ``margin``: ``(dst, op)`` of
    :func:`..rays.texels.extend_margin`, which fills the bake margin as Cycles' Extend does
    (horizons linearly, normals then renormalised)."""
    H = np.asarray(H, np.float64)
    A, P = H.shape
    R = int(resolution)
    texel = np.asarray(texel)
    img = np.zeros((A, R * R))
    img[:, texel] = H
    nrm = np.zeros((R * R, 3))
    nrm[texel] = np.asarray(normals, np.float64)
    if margin is not None and len(margin[0]):
        dst, op = margin
        img[:, dst] = (op @ H.T).T
        n = op @ np.asarray(normals, np.float64)
        nrm[dst] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return HorizonMap(quantize(img).reshape(A, R, R), nrm.reshape(R, R, 3).astype(np.float16))


def agreement(hm: HorizonMap, store, count: int = 48, seed: int = 0) -> dict:
    """How far the map's point-sun relight is from T's own rays at ``count`` of T's directions
    (spread over the set, seeded): relative RMSE over texels, combined over the directions, and
    the worst direction. Both are hard suns at a baked direction, so what differs is the map's
    single-interval horizon (overhangs), its 8-bit steps, its azimuth interpolation and the
    bump terminator term a normal alone does not carry."""
    D = store.directions.directions
    rng = np.random.default_rng(seed)
    up = np.nonzero(D[:, 2] > 0.02)[0]
    pick = np.sort(rng.choice(up, size=min(count, len(up)), replace=False))
    errs, num, den = [], 0.0, 0.0
    for s in pick:
        t = np.asarray(store.array[s], np.float64)
        m = hm.direct(D[s]).reshape(-1).astype(np.float64)
        e2, n2 = float(np.sum((m - t) ** 2)), float(np.sum(t * t))
        num += e2
        den += n2
        if n2 > 0:
            errs.append(np.sqrt(e2 / n2))
    return {"directions": int(len(pick)), "rel_rmse": float(np.sqrt(num / max(den, 1e-30))),
            "worst_direction_rel_rmse": float(max(errs) if errs else 0.0)}


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
