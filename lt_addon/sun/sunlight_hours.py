"""Sunlight hours per texel from a transport-texture bake (bpy-free).

A transport bake holds ``T[s, p] = cos(n_p, w_s) V(p, w_s) / pi``: the direct light of a hard
sun of unit irradiance from each baked direction ``w_s`` on a white texel ``p``
(:mod:`..transport.texture`). A sun study asks, per texel, for how many hours the Sun shines
on it: above the horizon, in front of the surface and not blocked. That is the visibility
``V`` at the Sun's direction, which T holds only multiplied by the cosine and only at the baked
directions. Here:

* **The visibility at a sun** ``d`` is the ratio of two interpolations with the same kernel
  weights ``k_s(d)`` (:func:`..transport.texture.sun_weights`, the relight's own):
  ``V(d) = sum_s k_s T[s] / sum_s k_s c_s`` with ``c_s = max(0, n . w_s) / pi`` the texel's
  unshadowed T. It is the cosine-weighted mean visibility of the baked directions the sun
  blends, exactly V where ``d`` is a baked direction, and in [0, 1] (clipped: the texel
  footprints' rays, :mod:`..rays.footprint`, are not the centre's). The alternative
  ``pi E(d) / cos(n, d)`` divides the interpolated light by the exact cosine: the linear
  kernel interpolates the cosine below its value between directions (a chord under an arc), so
  a lit texel would read V < 1, and at grazing suns both are small and the quotient noisy. The
  ratio's errors cancel. ``V = 0`` where the Sun is behind the surface (``n . d <= 0``) or the
  texel's unshadowed light there is below :data:`C_MIN` (grazing within 0.2 degrees).
* **The texel's normal** ``n`` is fitted to T itself (:func:`fit_normals`): where a texel is
  lit, ``pi T[s] = n . w_s`` exactly, so ``n`` is the least-squares solution over the baked
  directions where ``T > 0``, refitted without those whose ``T`` is below 0.9 of the fit (a
  shadow edge crossing the texel's footprint). Every bake has T; only some keep normals (a
  horizon map), and a fitted ``n`` is the cosine T was baked with, bump corrections included.
  A texel no baked direction lights gets ``n = 0`` and no sunlight.
* **Counting**: each study instant stands for ``weight_h`` hours (its step; one hour each for a
  list of clock hours) and adds ``weight_h * [V >= 0.5]`` (``visibility="threshold"``, the
  default: the texel is lit or not) or ``weight_h * V`` (``"fraction"``: a texel half in the
  blend of a shadow edge, or half covered at a wall's foot, counts half). Against a ray count
  from the texel centres (tests/blender/test_sun_study.py, docs/sun-studies.md) the threshold
  was closer on average: on a courtyard baked as users bake it (footprint texels, 400
  directions plus the study's sun paths at 1 degree) 0.02 h a texel against 0.20 h over a
  36-hour study, and its worst texel too (0.8 h against 5.2 h).

Where the Sun is far from every baked direction the blend of neighbours' shadows places a
shadow edge wrongly by up to the spacing: :func:`nearest_baked` says how far, and
:func:`..sun.study_times.with_study` extends a bake's directions along the study's sun paths.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

__all__ = ["VISIBILITY", "C_MIN", "LIT_MIN", "fit_normals", "covered_texels",
           "sun_weight_matrix", "nearest_baked", "visibility", "sunlight_hours",
           "SunlightHours", "direct_light"]

#: How a texel's visibility at each instant is counted (module docstring); the first is the
#: default.
VISIBILITY = ("threshold", "fraction")
#: The smallest unshadowed ``T`` (``cos / pi``) at which the visibility ratio is taken: a sun
#: within ~0.2 degrees of the surface's plane counts as not shining on it.
C_MIN = 1e-3 / np.pi
#: ``T`` above this counts as lit when the normals are fitted (float16's T is exact to ~5e-4
#: relative; 1e-4 is a cosine of 3e-4, 0.02 degrees from grazing).
LIT_MIN = 1e-4
#: Visibilities within this of 1 or 0 are 1 or 0: T is stored in half floats (2^-11 relative),
#: so a lit texel's ratio reads 0.9995.
SNAP = 2e-3
#: Float32 bytes of one (instants x texels) working block.
BLOCK_BYTES = 32 << 20


def _chunks(n: int, rows: int):
    c = max(256, BLOCK_BYTES // (4 * max(int(rows), 1)))
    return [(a, min(a + c, n)) for a in range(0, n, c)]


def fit_normals(store, *, keep: float = 0.9, texels=None) -> np.ndarray:
    """Per texel, the vector ``n`` with ``pi T[s] = n . w_s`` at the baked directions that
    light it (least squares, then again without the samples below ``keep`` of the first fit:
    shadow edges through the texel's footprint), made unit length: a texel whose footprint is
    partly covered from every direction (at the foot of a wall) fits a shorter ``n``, and keeps
    that fraction as its visibility. ``(P, 3)`` float32 (``P`` the store's texels,
    or ``len(texels)``); zero where no direction lights the texel. Directions that light a
    texel from a narrow cone only (a courtyard floor) fix ``n`` along that cone; its other
    components come out as the smallest that fit (a pseudo-inverse), which is what the
    visibility ratio needs: it reads ``n`` only near directions that light the texel."""
    W = np.asarray(store.directions.directions, np.float64)             # (S, 3)
    arr = store.array
    P = store.n_texels if texels is None else len(texels)
    out = np.zeros((P, 3), np.float32)
    WW = np.einsum("si,sj->sij", W, W).reshape(len(W), 9)                # (S, 9)
    for a, b in _chunks(P, len(W) * 2):
        cols = slice(a, b) if texels is None else np.asarray(texels)[a:b]
        T = np.asarray(arr[:, cols], np.float64) * np.pi                   # (S, c)
        m = T > LIT_MIN * np.pi
        n = _solve(WW, W, T, m)
        pred = n @ W.T                                                     # (c, S)
        m2 = m & (T >= keep * pred.T)
        n2 = _solve(WW, W, T, m2)
        length = np.linalg.norm(n2, axis=1, keepdims=True)
        out[a:b] = np.divide(n2, length, out=np.zeros_like(n2), where=length > 0)
    return out


def _solve(WW, W, T, m) -> np.ndarray:
    """(c, 3): per column of ``T`` (S, c), the least-squares ``n`` over the rows ``m``."""
    mf = m.astype(np.float64)
    A = (mf.T @ WW).reshape(-1, 3, 3)                                      # (c, 3, 3)
    rhs = (T * mf).T @ W                                                   # (c, 3)
    n = np.zeros_like(rhs)
    ok = mf.sum(0) > 0
    if ok.any():
        pinv = np.linalg.pinv(A[ok], rcond=1e-4, hermitian=True)
        n[ok] = np.einsum("cij,cj->ci", pinv, rhs[ok])
    return n


def covered_texels(albedo, store, normals=None) -> np.ndarray:
    """(P,) bool: the texels the bake filled -- a non-zero albedo or any light in T (a texel
    no triangle covers, beyond the bake's margin, holds neither). A black texel no baked
    direction lights cannot be told from an empty one and is left out."""
    a = np.asarray(albedo, np.float32).reshape(-1, np.shape(albedo)[-1]).max(axis=1) > 0
    if normals is not None:
        lit = np.any(np.asarray(normals) != 0, axis=1)
    else:
        lit = np.zeros(store.n_texels, bool)
        arr = store.array
        for a0, b0 in _chunks(store.n_texels, store.directions.size):
            lit[a0:b0] = np.asarray(arr[:, a0:b0]).max(axis=0) > 0
    return a | lit


def sun_weight_matrix(dset, directions, sun_angle_deg: float = 0.0, kernel: str = "linear"):
    """The relight's kernel weights (:func:`..transport.texture.sun_weights`) of each sun of
    ``directions`` (M, 3) over the baked directions: a CSR matrix (M, S), rows summing to 1
    (0 for a sun below the horizon)."""
    import scipy.sparse

    from ..transport.texture import sun_weights

    D = np.asarray(directions, np.float64).reshape(-1, 3)
    rows, cols, vals = [], [], []
    for i, d in enumerate(D):
        idx, w = sun_weights(dset, d, sun_angle_deg, kernel)
        rows.append(np.full(len(idx), i))
        cols.append(idx)
        vals.append(w)
    if not D.size:
        return scipy.sparse.csr_matrix((0, dset.size))
    return scipy.sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                           np.concatenate(cols))),
                                   shape=(len(D), dset.size))


def nearest_baked(dset, directions) -> np.ndarray:
    """Degrees from each of ``directions`` (M, 3) to the nearest baked direction (M,)."""
    from scipy.spatial import cKDTree

    D = np.asarray(directions, np.float64).reshape(-1, 3)
    if not len(D):
        return np.zeros(0)
    chord, _ = cKDTree(np.asarray(dset.directions, np.float64)).query(D, k=1)
    return np.degrees(2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0)))


def visibility(store, normals, directions, *, sun_angle_deg: float = 0.0,
               kernel: str = "linear", texels=None, weights=None) -> np.ndarray:
    """``V`` (M, P) float32 in [0, 1]: each texel's visibility of each sun of ``directions``
    (module docstring: the ratio of T's and the unshadowed T's interpolations), 0 behind the
    surface; ``texels`` (flat indices) to compute only there; ``weights`` the
    :func:`sun_weight_matrix` when already made. Memory: M x P float32 (use
    :func:`sunlight_hours` for sums over many suns)."""
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    Wm = sun_weight_matrix(store.directions, D, sun_angle_deg, kernel) if weights is None \
        else weights
    P = store.n_texels if texels is None else len(texels)
    out = np.zeros((len(D), P), np.float32)
    for a, b, V in _blocks(store, normals, D, Wm, texels):
        out[:, a:b] = V
    return out


def _blocks(store, normals, D, Wm, texels):
    """(a, b, V (M, b - a) float32) over blocks of texels: :func:`visibility`'s computation,
    in single precision (T is half precision; a year of hourly suns at 256^2 took 14 s in
    double, 2026-12-06)."""
    Wm = Wm.tocsc()
    used = np.flatnonzero(np.diff(Wm.indptr) > 0)
    Wu = Wm[:, used].tocsr().astype(np.float32)                            # (M, k)
    B = np.asarray(store.directions.directions, np.float32)[used]          # (k, 3)
    D = np.asarray(D, np.float32)
    arr = store.array
    nrm = np.asarray(normals, np.float32).reshape(-1, 3)
    P = store.n_texels if texels is None else len(texels)
    for a, b in _chunks(P, max(len(D), len(used))):
        if texels is None:
            T = np.asarray(arr[used, a:b], np.float32) if len(used) else np.zeros((0, b - a))
            n = nrm[a:b]
        else:
            t = np.asarray(texels, np.int64)[a:b]
            T = (np.asarray(arr[np.ix_(used, t)], np.float32) if len(used) else
                 np.zeros((0, b - a), np.float32))
            n = nrm[t]
        E = np.asarray(Wu @ T, np.float32)                                 # (M, c)
        C = np.asarray(Wu @ (np.maximum(B @ n.T, 0.0) * np.float32(1.0 / np.pi)),
                       np.float32)                                         # (M, c)
        ok = (D @ n.T > 0.0) & (C > C_MIN)                                 # sun in front
        V = np.zeros(E.shape, np.float32)
        np.divide(E, C, out=V, where=ok)
        np.clip(V, 0.0, 1.0, out=V)
        V[V > 1.0 - SNAP] = 1.0          # T's half floats: lit and dark exactly
        V[V < SNAP] = 0.0
        yield a, b, V


@dataclass
class SunlightHours:
    """One object's sunlight hours.

    Attributes
    ----------
    hours : ndarray (R, R) float32
        Hours of direct sun per texel (row 0 at v = 0, as the bake's images); 0 on texels the
        bake did not fill.
    covered : ndarray (R, R) bool
        The texels the bake filled (:func:`covered_texels`).
    possible_h : float
        Hours the Sun is above the horizon over the study (the most any texel can get).
    visibility : str
    seconds : dict
        ``normals`` (the fit), ``hours`` (the count).
    """

    hours: np.ndarray
    covered: np.ndarray
    possible_h: float
    visibility: str
    seconds: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """min / mean / max hours and percentiles over the covered texels."""
        h = self.hours[self.covered]
        if not h.size:
            return {"texels": 0}
        p10, p50, p90 = np.percentile(h, [10, 50, 90])
        return {"texels": int(h.size), "min_h": float(h.min()), "mean_h": float(h.mean()),
                "max_h": float(h.max()), "p10_h": float(p10), "median_h": float(p50),
                "p90_h": float(p90), "possible_h": float(self.possible_h)}


def sunlight_hours(store, directions, weight_h, *, albedo=None, normals=None,
                   sun_angle_deg: float = 0.0, kernel: str = "linear",
                   visibility: str = "threshold") -> SunlightHours:
    """Hours of direct sun per texel: each sun of ``directions`` (M, 3; unique, above the
    horizon: :attr:`..sun.study_times.StudySuns.directions`) counted ``weight_h`` (M,) hours
    (the instants that share it times their step). ``normals`` (P, 3): :func:`fit_normals`
    when None. ``albedo`` (R, R, 3): with T, which texels the bake filled. Streams over
    blocks of texels; memory M x block."""
    if visibility not in VISIBILITY:
        raise ValueError(f"visibility must be one of {VISIBILITY}, got {visibility!r}")
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    wh = np.asarray(weight_h, np.float64).reshape(-1)
    if len(wh) != len(D):
        raise ValueError(f"{len(wh)} weights for {len(D)} suns")
    t0 = time.perf_counter()
    if normals is None:
        normals = fit_normals(store)
    t1 = time.perf_counter()
    R = store.resolution
    hours = np.zeros(store.n_texels, np.float64)
    if len(D):
        Wm = sun_weight_matrix(store.directions, D, sun_angle_deg, kernel)
        wh32 = wh.astype(np.float32)
        for a, b, V in _blocks(store, normals, D, Wm, None):
            if visibility == "threshold":
                V = (V >= 0.5).astype(np.float32)
            hours[a:b] = wh32 @ V
    covered = (covered_texels(albedo, store, normals) if albedo is not None
               else np.any(np.asarray(normals) != 0, axis=1))
    hours[~covered] = 0.0
    t2 = time.perf_counter()
    return SunlightHours(hours.reshape(R, R).astype(np.float32), covered.reshape(R, R),
                         float(wh.sum()), visibility,
                         {"normals": round(t1 - t0, 4), "hours": round(t2 - t1, 4)})


def direct_light(store, direction, sun_angle_deg: float = 0.0, kernel: str = "linear"):
    """(R, R) float32: ``cos V`` (= ``pi T`` relit, a white surface's direct light under a sun
    of unit irradiance, 1 facing it unshadowed) at ``direction``; 0 below the horizon."""
    return (np.pi * store.sun(direction, sun_angle_deg, kernel)).astype(np.float32)
