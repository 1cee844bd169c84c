"""Eigentransport: PCA of per-vertex sampled transport (Nowrouzezahrai et al. 2008).

Transport ``T[v, j] = V(x_v, w_j) max(0, n_v . w_j)`` (eq. 1, optionally with bounces) is sampled
at the S directions ``w_j`` of a :class:`~.directions.DirectionSet` with solid angles ``dw_j``.
Diffuse shading (eq. 5) is the quadrature

    B(x) = rho / pi * sum_j T[x, j] L_j dw_j = rho / pi * T[x] . Lw,      Lw_j = L_j dw_j

(``Lw`` is the *weighted lighting*, radiance times solid angle, W m^-2 per sample).

PCA (eq. 2) with the mean ``m`` (S,), ``d`` orthonormal eigentransports ``E`` (d, S) and
coefficients ``C = (T - m) E^T`` (V, d) gives the rank-d reconstruction ``T_d = m + C E`` and the
**exact** shading of that reconstruction

    B_d(x) = rho / pi * ( m . Lw + C[x] . (E Lw) )

-- one global scalar plus a d-term dot product per vertex (:meth:`Eigentransport.shade`). The
paper's mean-compensated form (eq. 8-10) uses ``(C + m E^T) . (E Lw)`` instead, which drops
``(m - E^T E m) . Lw``, the part of the mean outside span(E) (kept here for comparison as
:meth:`Eigentransport.shade_mean_compensated`).

Lighting: :func:`project_environment` samples an equirectangular image (Blender/Cycles mapping of
:mod:`.hemisphere`) at the directions and multiplies by ``dw``; :func:`rotate_environment_samples`
rotates it by the paper's sec. 5 scheme (rotate the lattice, interpolate the already sampled
lighting); :func:`point_light_weights` builds per-vertex lighting for a local point light
(sec. 4.2.1), valid only outside the convex hull of the scene (sec. 8).

Precision: fitting and shading in float64; the sidecar (:meth:`Eigentransport.to_arrays`) stores
mean, basis and coefficients as float32 on purpose (the paper's 4 bytes per value).
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.spatial

from ..sphere.directions import DirectionSet, interpolation_weights, nearest_directions
from ..sphere.hemisphere import direction_to_equirect_uv, equirect_pixel_directions, normalize_directions

FORMAT = "relightable_textures.eigentransport"
FORMAT_VERSION = 1

#: Relative eigenvalue threshold below which a component counts as numerical noise (rank).
#: Eigenvalues are energies sigma^2; the covariance path computes them with an absolute error
#: of about S * eps * lambda_max, so anything below ~1e3 * S * eps * lambda_max is noise.
_RANK_RTOL = 1e3 * np.finfo(np.float64).eps


class LightInsideHullWarning(UserWarning):
    """A local light lies inside the convex hull of the scene; the approximation is invalid."""


# ----------------------------------------------------------------------------------------------
# validation helpers


def _transport(T) -> np.ndarray:
    t = np.asarray(T, dtype=np.float64)
    if t.ndim != 2 or t.shape[0] < 1 or t.shape[1] < 1:
        raise ValueError(f"T must have shape (V, S) with V, S >= 1, got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"T contains {int(np.count_nonzero(~np.isfinite(t)))} non-finite "
                         "value(s); transport must be finite")
    return t


def _lighting(Lw, S: int, name: str = "L_weighted") -> np.ndarray:
    lw = np.asarray(Lw, dtype=np.float64)
    if lw.ndim not in (1, 2) or lw.shape[0] != S:
        raise ValueError(f"{name} must have shape ({S},) or ({S}, C) (one value per sample "
                         f"direction, radiance x solid angle), got {lw.shape}")
    if not np.all(np.isfinite(lw)):
        raise ValueError(f"{name} contains NaN or inf")
    return lw


def _albedo_factor(albedo, out_shape: tuple) -> np.ndarray | float:
    """``albedo / pi`` broadcastable to a shading result of shape (V,) or (V, C)."""
    a = np.asarray(albedo, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError("albedo must be finite")
    V = out_shape[0]
    C = out_shape[1] if len(out_shape) == 2 else None
    if a.ndim == 0:
        return float(a) / np.pi
    if a.shape == out_shape or (C is not None and a.shape in ((V, 1), (1, C))):
        return a / np.pi
    if a.shape == (V,) and C == V:
        raise ValueError(f"albedo of shape ({V},) is ambiguous for {V} vertices and {C} "
                         f"channels: pass shape ({V}, 1) for one albedo per vertex or "
                         f"(1, {C}) for one per channel")
    if a.shape == (V,):                  # one albedo per vertex, all channels
        return (a / np.pi).reshape((V,) + (1,) * (len(out_shape) - 1))
    if C is not None and a.shape == (C,):   # one albedo per channel
        return a / np.pi
    raise ValueError(f"albedo must be a scalar or have shape {out_shape}, ({V},)"
                     + (f", ({C},), ({V}, 1) or (1, {C})" if C is not None else "")
                     + f"; got {a.shape}")


def relative_rms_error(reference, approx) -> float:
    """``||approx - reference|| / ||reference||`` over all entries (0 if both are zero).

    Parameters
    ----------
    reference, approx : array_like, same shape

    Returns
    -------
    float (inf if the reference is zero and the approximation is not)
    """
    r = np.asarray(reference, dtype=np.float64)
    a = np.asarray(approx, dtype=np.float64)
    nr = float(np.linalg.norm(r.ravel()))
    ne = float(np.linalg.norm((a - r).ravel()))
    if nr == 0.0:
        return 0.0 if ne == 0.0 else float("inf")
    return ne / nr


# ----------------------------------------------------------------------------------------------
# the model


@dataclass
class Eigentransport:
    """A fitted eigentransport basis and its per-vertex coefficients.

    Attributes
    ----------
    mean : ndarray, shape (S,), float64
        Mean transport ``m`` over vertices (dimensionless: visibility x cosine).
    basis : ndarray, shape (d, S), float64
        Eigentransports ``E``, orthonormal rows (Euclidean inner product over samples), sorted
        by decreasing eigenvalue.
    coefficients : ndarray, shape (V, d), float64
        ``C = (T - m) E^T``.
    eigenvalues : ndarray, shape (r,), float64
        Energies ``sigma_k^2`` of *all* numerically non-zero components of the centred transport
        (``r`` = rank), not only the kept ones.
    total_energy : float
        ``||T - m||_F^2`` (the sum of all eigenvalues, noise included).
    d_requested : int or None
        The ``d`` asked for before clipping to the rank (None when chosen from a target).
    selection : dict
        How ``d`` was chosen: ``{"criterion": "d" | "energy" | "shading_error", "target": ...,
        "achieved": ..., "clipped_to_rank": bool}`` plus the shading error at ``d`` when test
        environments were given.
    metadata : dict
        Free JSON-safe metadata carried into the sidecar (direction-set spec, bake settings).
    """

    mean: np.ndarray
    basis: np.ndarray
    coefficients: np.ndarray
    eigenvalues: np.ndarray
    total_energy: float
    d_requested: int | None = None
    selection: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        self.mean = np.asarray(self.mean, dtype=np.float64).reshape(-1)
        S = self.mean.shape[0]
        self.basis = np.asarray(self.basis, dtype=np.float64).reshape(-1, S)
        d = self.basis.shape[0]
        self.coefficients = np.asarray(self.coefficients, dtype=np.float64)
        if self.coefficients.ndim != 2 or self.coefficients.shape[1] != d:
            raise ValueError(f"coefficients must have shape (V, {d}), got "
                             f"{self.coefficients.shape}")
        self.eigenvalues = np.asarray(self.eigenvalues, dtype=np.float64).reshape(-1)
        self.total_energy = float(self.total_energy)

    # -- sizes -----------------------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return int(self.coefficients.shape[0])

    @property
    def n_samples(self) -> int:
        return int(self.mean.shape[0])

    @property
    def d(self) -> int:
        """Number of eigentransports kept (per-vertex coefficients)."""
        return int(self.basis.shape[0])

    @property
    def rank(self) -> int:
        """Numerical rank of the centred transport."""
        return int(self.eigenvalues.shape[0])

    @property
    def captured_energy(self) -> float:
        """Fraction of the centred transport's energy ``||T - m||_F^2`` kept by ``d`` components
        (1.0 for constant transport, whose centred energy is zero)."""
        return float(captured_energy_curve(self.eigenvalues, self.total_energy)[self.d])

    def energy_curve(self) -> np.ndarray:
        """Captured energy for ``d = 0..rank``; shape (rank + 1,)."""
        return captured_energy_curve(self.eigenvalues, self.total_energy)

    # -- lighting and shading ---------------------------------------------------------------------
    def project_lighting(self, L_weighted):
        """Global lighting terms for shading.

        Parameters
        ----------
        L_weighted : array_like, shape (S,) or (S, C)
            Radiance times solid angle per sample (:func:`project_environment`).

        Returns
        -------
        mean_term : float or ndarray (C,)
            ``m . Lw``.
        coefficients : ndarray, shape (d,) or (d, C)
            ``E Lw``.
        """
        lw = _lighting(L_weighted, self.n_samples)
        return self.mean @ lw, self.basis @ lw

    def shade(self, L_weighted, albedo=1.0) -> np.ndarray:
        """Exact diffuse shading of the rank-d transport.

        ``B = rho / pi * (m . Lw + C (E Lw))``, equal to ``rho / pi * reconstruct() @ Lw``.

        Parameters
        ----------
        L_weighted : array_like, shape (S,) or (S, C)
            Radiance (W m^-2 sr^-1) times solid angle (sr) per sample direction.
        albedo : float or array_like, shape (V,), (C,), (V, 1), (1, C) or (V, C)
            A 1-D albedo with V == C is ambiguous and refused; use (V, 1) or (1, C).
            Diffuse reflectance rho.

        Returns
        -------
        B : ndarray, shape (V,) or (V, C), float64
            Outgoing radiance (W m^-2 sr^-1).
        """
        mean_term, lc = self.project_lighting(L_weighted)
        B = self.coefficients @ lc + mean_term
        return B * _albedo_factor(albedo, B.shape)

    def shade_mean_compensated(self, L_weighted, albedo=1.0) -> np.ndarray:
        """The paper's eq. 10: ``rho / pi * (C + m E^T) . (E Lw)`` (drops the mean outside
        span(E)); shape as :meth:`shade`. For comparison only."""
        lw = _lighting(L_weighted, self.n_samples)
        lc = self.basis @ lw
        B = (self.coefficients + self.basis @ self.mean) @ lc
        return B * _albedo_factor(albedo, B.shape)

    def shade_local(self, L_weighted_per_vertex, albedo=1.0) -> np.ndarray:
        """Shading under per-vertex lighting (local lights, :func:`point_light_weights`).

        Parameters
        ----------
        L_weighted_per_vertex : array_like or scipy.sparse matrix, shape (V, S)
            Weighted lighting of each vertex.
        albedo : float or array_like, shape (V,)

        Returns
        -------
        B : ndarray, shape (V,)
            ``rho / pi * (Lw[x] . m + C[x] . (E Lw[x]))``.
        """
        V, S = self.n_vertices, self.n_samples
        if scipy.sparse.issparse(L_weighted_per_vertex):
            lw = scipy.sparse.csr_matrix(L_weighted_per_vertex, dtype=np.float64)
        else:
            lw = np.asarray(L_weighted_per_vertex, dtype=np.float64)
        if lw.shape != (V, S):
            raise ValueError(f"per-vertex lighting must have shape ({V}, {S}), got {lw.shape}")
        mean_term = np.asarray(lw @ self.mean).reshape(V)
        proj = np.asarray(lw @ self.basis.T).reshape(V, self.d)
        B = mean_term + np.einsum("vk,vk->v", self.coefficients, proj)
        return B * _albedo_factor(albedo, B.shape)

    def reconstruct(self) -> np.ndarray:
        """Rank-d transport ``m + C E``; shape (V, S), float64."""
        return self.mean + self.coefficients @ self.basis

    def truncate(self, d: int) -> "Eigentransport":
        """The same fit keeping only the first ``d`` components (``0 <= d <= self.d``)."""
        d = int(d)
        if not 0 <= d <= self.d:
            raise ValueError(f"d must lie in [0, {self.d}] for this fit, got {d}")
        sel = dict(self.selection, criterion="d", target=d, achieved=d, clipped_to_rank=False)
        sel.pop("shading_error_at_d", None)
        return Eigentransport(self.mean, self.basis[:d], self.coefficients[:, :d],
                              self.eigenvalues, self.total_energy, d, sel, dict(self.metadata))

    # -- storage ----------------------------------------------------------------------------------
    def storage_bytes(self) -> dict:
        """Bytes of the stored arrays at 4 bytes per value (float32).

        Returns
        -------
        dict of int
            ``coefficients`` (4 V d), ``mean`` (4 S), ``basis`` (4 d S), ``sidecar`` (their sum,
            what :meth:`to_arrays` writes apart from metadata and eigenvalues),
            ``paper_runtime`` = 4 d (V + 1) (paper sec. 7.1: per-vertex coefficients + one
            lighting vector) and ``exact_runtime`` = 4 (d (V + 1) + 1) (the exact form adds the
            single scalar ``m . Lw`` per lighting).
        """
        V, S, d = self.n_vertices, self.n_samples, self.d
        out = {"coefficients": 4 * V * d, "mean": 4 * S, "basis": 4 * d * S,
               "paper_runtime": 4 * d * (V + 1), "exact_runtime": 4 * (d * (V + 1) + 1)}
        out["sidecar"] = out["coefficients"] + out["mean"] + out["basis"]
        return out

    def to_arrays(self) -> dict:
        """Arrays for an ``.npz`` sidecar (``np.savez(path, **model.to_arrays())``).

        Returns
        -------
        dict
            ``mean`` (S,) float32, ``basis`` (d, S) float32, ``coefficients`` (V, d) float32,
            ``eigenvalues`` (r,) float64, ``metadata`` 0-d unicode array holding JSON (format,
            version, total energy, selection, user metadata). Loads with
            ``allow_pickle=False``.
        """
        meta = {"format": FORMAT, "format_version": FORMAT_VERSION,
                "total_energy": self.total_energy, "d_requested": self.d_requested,
                "selection": self.selection, "metadata": self.metadata,
                "captured_energy": self.captured_energy}
        return {"mean": self.mean.astype(np.float32),
                "basis": self.basis.astype(np.float32),
                "coefficients": self.coefficients.astype(np.float32),
                "eigenvalues": self.eigenvalues.astype(np.float64),
                "metadata": np.array(json.dumps(meta, allow_nan=True))}

    @classmethod
    def from_arrays(cls, arrays) -> "Eigentransport":
        """Inverse of :meth:`to_arrays` (accepts a dict or an ``np.load`` result); arrays come
        back as float64 copies of the stored float32 values."""
        meta = read_sidecar_metadata(arrays, FORMAT, FORMAT_VERSION, "an eigentransport")
        return cls(np.asarray(arrays["mean"], np.float64), np.asarray(arrays["basis"], np.float64),
                   np.asarray(arrays["coefficients"], np.float64),
                   np.asarray(arrays["eigenvalues"], np.float64), meta["total_energy"],
                   meta.get("d_requested"), meta.get("selection", {}), meta.get("metadata", {}))


def read_sidecar_metadata(arrays, fmt: str, version: int, what: str) -> dict:
    """The JSON ``metadata`` entry of an ``.npz`` sidecar, checked for format and version.

    Raises ValueError naming ``what`` (with its article, e.g. "an eigentransport") when it is
    not such a sidecar or is from a newer version.
    """
    try:
        meta = json.loads(str(np.asarray(arrays["metadata"])[()]))
    except KeyError:
        raise ValueError(f"not {what} sidecar: no 'metadata' entry") from None
    if meta.get("format") != fmt:
        raise ValueError(f"not {what} sidecar (format {meta.get('format')!r})")
    if meta.get("format_version", 0) > version:
        raise ValueError(f"sidecar format version {meta['format_version']} is newer than "
                         f"this code ({version}); update the extension")
    return meta


def captured_energy_curve(eigenvalues, total_energy: float) -> np.ndarray:
    """Captured fraction of the centred energy for ``d = 0..len(eigenvalues)``.

    Parameters
    ----------
    eigenvalues : array_like, shape (r,)
        Energies in decreasing order.
    total_energy : float

    Returns
    -------
    ndarray, shape (r + 1,), starts at 0 (1.0 everywhere if ``total_energy == 0``)
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    if total_energy <= 0.0:
        return np.ones(lam.shape[0] + 1)
    return np.minimum(np.concatenate([[0.0], np.cumsum(lam)]) / total_energy, 1.0)


# ----------------------------------------------------------------------------------------------
# fitting


def _principal_components(X: np.ndarray, scale: float):
    """Eigenvalues (r,) and orthonormal eigenvector rows (r, S) of a centred (V, S) matrix.

    V < S: thin SVD of X itself (cost V^2 S, memory V S). V >= S: symmetric eigendecomposition
    of the S x S scatter matrix X^T X (cost V S^2, memory S^2; never forms a V x V matrix). Both
    in float64; components with eigenvalue below ``_RANK_RTOL * max(V, S) * lambda_max``, or
    below the rounding floor ``V S (16 eps scale)^2`` of centring data of magnitude ``scale``,
    are dropped as noise.
    """
    V, S = X.shape
    if V < S:
        _, sv, vt = scipy.linalg.svd(X, full_matrices=False, lapack_driver="gesdd")
        lam, vecs = sv ** 2, vt
        method = "svd"
    else:
        lam, vecs = scipy.linalg.eigh(X.T @ X)
        lam, vecs = lam[::-1], vecs[:, ::-1].T
        method = "scatter_eigh"
    lam_max = float(lam[0]) if lam.size else 0.0
    # rounding floor: T - mean carries errors ~eps |T| per entry even for constant columns
    floor = V * S * (16.0 * np.finfo(np.float64).eps * scale) ** 2
    keep = (lam > _RANK_RTOL * max(V, S) * lam_max) & (lam > floor)
    r = int(np.count_nonzero(keep))
    vecs = np.ascontiguousarray(vecs[:r])
    # a deterministic sign: the largest-magnitude entry of each eigentransport is positive
    if r:
        big = np.argmax(np.abs(vecs), axis=1)
        vecs *= np.where(vecs[np.arange(r), big] < 0, -1.0, 1.0)[:, None]
    return lam[:r].astype(np.float64), vecs, method


def _envs(envs, S: int) -> np.ndarray:
    e = np.asarray(envs, dtype=np.float64)
    if e.ndim == 1:
        e = e[None]
    if e.ndim not in (2, 3) or e.shape[1] != S:
        raise ValueError(f"envs must have shape (K, {S}) or (K, {S}, C): weighted lighting "
                         f"(radiance x solid angle) of K test environments; got {e.shape}")
    if not np.all(np.isfinite(e)):
        raise ValueError("envs contains NaN or inf")
    return e.reshape(e.shape[0], S, -1)          # (K, S, C)


def shading_error_curve(T, mean, basis, envs, d_max: int | None = None) -> np.ndarray:
    """Worst relative RMS shading error over test environments for ``d = 0..d_max``.

    Parameters
    ----------
    T : array_like, shape (V, S)
    mean : array_like, shape (S,)
    basis : array_like, shape (r, S)
        Orthonormal rows, best first.
    envs : array_like, shape (K, S) or (K, S, C)
        Weighted lighting of K test environments.
    d_max : int, optional
        Default ``r``.

    Returns
    -------
    err : ndarray, shape (d_max + 1,)
        ``max_k ||B_d - B||_2 / ||B||_2`` over vertices (and channels), ``B = T Lw_k`` the
        full-transport shading (albedo cancels).
    """
    T = _transport(T)
    E = np.asarray(basis, dtype=np.float64)
    m = np.asarray(mean, dtype=np.float64)
    e = _envs(envs, T.shape[1])
    K = e.shape[0]
    d_max = E.shape[0] if d_max is None else min(int(d_max), E.shape[0])
    flat = e.transpose(1, 0, 2).reshape(T.shape[1], -1)           # (S, K C)
    B_full = T @ flat                                              # (V, K C)
    B = np.broadcast_to(m @ flat, B_full.shape).copy()
    norms = np.linalg.norm(B_full.reshape(T.shape[0], K, -1), axis=(0, 2))
    P = E[:d_max] @ flat                                           # (d_max, K C)
    out = np.empty(d_max + 1)
    block = 32
    for k0 in range(0, d_max + 1, block):
        k1 = min(k0 + block, d_max + 1)
        C = (T - m) @ E[k0:k1].T if k0 < d_max else np.zeros((T.shape[0], 0))
        for k in range(k0, k1):
            err = np.linalg.norm((B - B_full).reshape(T.shape[0], K, -1), axis=(0, 2))
            rel = np.where(norms > 0, err / np.where(norms > 0, norms, 1.0),
                           np.where(err > 0, np.inf, 0.0))
            out[k] = float(rel.max())
            if k < d_max:
                B += np.outer(C[:, k - k0], P[k])
    return out


def fit_eigentransport(T, d: int | None = None, energy: float | None = None,
                       shading_error: float | None = None, envs=None,
                       metadata: dict | None = None) -> Eigentransport:
    """PCA of per-vertex transport into eigentransports (paper sec. 3, eq. 2).

    Parameters
    ----------
    T : array_like, shape (V, S)
        Sampled transport (visibility x cosine, dimensionless; bounces allowed).
    d : int, optional
        Number of eigentransports. Values above the numerical rank of ``T - m`` are clipped to
        the rank (``selection["clipped_to_rank"]`` and ``d_requested`` record it).
    energy : float in (0, 1], optional
        Keep the smallest ``d`` whose components hold at least this fraction of the centred
        energy ``||T - m||_F^2`` (the "captured variance" of the paper's Fig. 2).
    shading_error : float > 0, optional
        Keep the smallest ``d`` whose worst relative RMS shading error over ``envs`` is at most
        this (see :func:`shading_error_curve`). Needs ``envs``.
    envs : array_like, shape (K, S) or (K, S, C), optional
        Weighted lighting of test environments. With any criterion, the shading error at the
        chosen ``d`` is reported in ``selection["shading_error_at_d"]``.
    metadata : dict, optional
        JSON-safe metadata kept with the model.

    Exactly one of ``d``, ``energy``, ``shading_error`` must be given.

    Returns
    -------
    Eigentransport
        Constant transport (including all-zero, fully occluded) has rank 0: ``d = 0`` and
        shading is the exact mean term. A one-vertex mesh is constant by definition.
    """
    T = _transport(T)
    given = [name for name, v in (("d", d), ("energy", energy),
                                  ("shading_error", shading_error)) if v is not None]
    if len(given) != 1:
        raise ValueError("give exactly one of d, energy or shading_error to choose the number "
                         f"of eigentransports (got {given or 'none'})")
    V, S = T.shape
    m = T.mean(axis=0)
    X = T - m
    total = float(np.sum(X * X))
    lam, vecs, method = _principal_components(X, float(np.max(np.abs(T))))
    r = lam.shape[0]
    if r == 0:
        total = 0.0        # what is left after centring is rounding noise: constant transport
    curve = captured_energy_curve(lam, total)
    sel = {"criterion": given[0], "method": method, "clipped_to_rank": False}
    d_requested = None
    err_curve = None
    if shading_error is not None and envs is not None:
        err_curve = shading_error_curve(T, m, vecs, envs)
    if d is not None:
        if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 0:
            raise ValueError(f"d must be a non-negative integer, got {d!r}")
        d_requested = int(d)
        d_use = min(d_requested, r)
        sel.update(target=d_requested, achieved=d_use, clipped_to_rank=d_requested > r)
    elif energy is not None:
        if not 0.0 < float(energy) <= 1.0:
            raise ValueError(f"energy must lie in (0, 1], got {energy!r}")
        # tolerate rounding in the cumulative sum when asking for everything
        ok = np.nonzero(curve >= float(energy) - 1e-12)[0]
        d_use = int(ok[0]) if ok.size else r
        sel.update(target=float(energy), achieved=float(curve[d_use]))
    else:
        if envs is None:
            raise ValueError("shading_error needs envs: the weighted lighting of test "
                             "environments to measure the shading error under")
        if not float(shading_error) > 0.0:
            raise ValueError(f"shading_error must be > 0, got {shading_error!r}")
        ok = np.nonzero(err_curve <= float(shading_error))[0]
        d_use = int(ok[0]) if ok.size else r
        sel.update(target=float(shading_error), achieved=float(err_curve[d_use]))
    sel["captured_energy"] = float(curve[d_use])
    E = vecs[:d_use]
    C = X @ E.T
    if err_curve is not None:
        sel["shading_error_at_d"] = float(err_curve[d_use])
    elif envs is not None:
        e = _envs(envs, S)
        sel["shading_error_at_d"] = max(
            relative_rms_error(T @ lw, m @ lw + C @ (E @ lw)) for lw in e)
    return Eigentransport(m, E, C, lam, total, d_requested, sel, dict(metadata or {}))


# ----------------------------------------------------------------------------------------------
# environment lighting


def _env_image(env_image) -> np.ndarray:
    env = np.asarray(env_image, dtype=np.float64)
    if env.ndim not in (2, 3) or env.shape[0] < 1 or env.shape[1] < 1:
        raise ValueError(f"env_image must have shape (H, W) or (H, W, C), got {env.shape}")
    if not np.all(np.isfinite(env)):
        raise ValueError("env_image contains NaN or inf")
    return env


def sample_equirect(env_image, directions, *, row_order: str, validate: bool = True) -> np.ndarray:
    """Bilinear lookup of an equirectangular image at directions (Blender/Cycles mapping).

    Parameters
    ----------
    env_image : array_like, shape (H, W) or (H, W, C)
        Radiance (W m^-2 sr^-1).
    directions : array_like, shape (Q, 3)
    row_order : {"top_first", "bottom_first"}
        Row 0 of ``env_image`` is the top (zenith side) or the bottom, see
        :func:`.hemisphere.equirect_pixel_directions`.

    Returns
    -------
    ndarray, shape (Q,) or (Q, C), float64
        Pixel centres at ``u = (col + 0.5) / W``, ``v = (row_b + 0.5) / H`` (``row_b`` counted
        from the bottom); wraps in ``u``, clamps in ``v`` (half a pixel at each pole).

    ``validate=False`` skips the float64 copy and the finiteness check of the whole image (10-20
    ms for a 2K HDRI) for a caller that checked it once (the viewport's environment preview).
    """
    if row_order not in ("top_first", "bottom_first"):
        raise ValueError(f"row_order must be 'top_first' or 'bottom_first', got {row_order!r}")
    env = _env_image(env_image) if validate else np.asarray(env_image)
    if row_order == "top_first":
        env = env[::-1]
    H, W = env.shape[:2]
    uv = direction_to_equirect_uv(directions).reshape(-1, 2)
    x = uv[:, 0] * W - 0.5
    y = np.clip(uv[:, 1] * H - 0.5, 0.0, H - 1.0)
    x0 = np.floor(x)
    fx = x - x0
    c0 = np.mod(x0.astype(np.int64), W)
    c1 = np.mod(c0 + 1, W)
    r0 = np.minimum(np.floor(y), max(H - 2, 0)).astype(np.int64)
    fy = y - r0
    r1 = np.minimum(r0 + 1, H - 1)
    if env.ndim == 3:
        fx, fy = fx[:, None], fy[:, None]
    return ((1 - fy) * ((1 - fx) * env[r0, c0] + fx * env[r0, c1])
            + fy * ((1 - fx) * env[r1, c0] + fx * env[r1, c1]))


def project_environment(env_image, directions, solid_angles, *, row_order: str) -> np.ndarray:
    """Weighted lighting ``Lw_j = L(w_j) dw_j`` of an equirectangular environment.

    Parameters
    ----------
    env_image : array_like, shape (H, W) or (H, W, C)
        Radiance (W m^-2 sr^-1).
    directions : array_like, shape (S, 3)
    solid_angles : array_like, shape (S,)
        sr.
    row_order : {"top_first", "bottom_first"}

    Returns
    -------
    ndarray, shape (S,) or (S, C), float64 (W m^-2 per sample)
    """
    w = np.asarray(solid_angles, dtype=np.float64)
    L = sample_equirect(env_image, directions, row_order=row_order)
    if w.shape != (L.shape[0],):
        raise ValueError(f"solid_angles must have shape ({L.shape[0]},), got {w.shape}")
    return L * (w if L.ndim == 1 else w[:, None])


def equirect_pixel_solid_angles(height: int, width: int, *, row_order: str) -> np.ndarray:
    """Exact solid angle (sr) of every pixel of an equirectangular image; shape (H, W)."""
    if row_order not in ("top_first", "bottom_first"):
        raise ValueError(f"row_order must be 'top_first' or 'bottom_first', got {row_order!r}")
    v = np.arange(height + 1) / height                             # bottom first
    band = np.diff(np.sin((v - 0.5) * np.pi)) * (2.0 * np.pi / width)
    if row_order == "top_first":
        band = band[::-1]
    return np.repeat(band[:, None], width, axis=1)


def project_environment_supersampled(env_image, direction_set: DirectionSet, *, row_order: str,
                                     supersample: int = 4, rotation=None) -> np.ndarray:
    """Brute-force reference projection: integrate the image over each sample's Voronoi cell.

    Every pixel is split into ``supersample^2`` sub-pixels (exact sub-pixel solid angles, the
    pixel's value -- box reconstruction); each sub-pixel adds ``L dw`` to the sample direction
    nearest to it. For a constant image this returns ``L * (Voronoi cell area)``, summing to
    ``4 pi L``. With ``rotation`` (3, 3), the *rotated* environment ``L(R^T w)`` is projected
    (sub-pixel directions are rotated by ``R``).

    Returns
    -------
    ndarray, shape (S,) or (S, C), float64
    """
    env = _env_image(env_image)
    H, W = env.shape[:2]
    n = int(supersample)
    if n < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample!r}")
    dirs = equirect_pixel_directions(H * n, W * n, row_order=row_order).reshape(-1, 3)
    dw = equirect_pixel_solid_angles(H * n, W * n, row_order=row_order).reshape(-1)
    if rotation is not None:
        dirs = dirs @ _rotation(rotation).T
    idx, _ = nearest_directions(direction_set, dirs, 1)
    vals = np.repeat(np.repeat(env, n, axis=0), n, axis=1).reshape(H * n * W * n, -1)
    out = np.zeros((direction_set.size, vals.shape[1]))
    np.add.at(out, idx[:, 0], vals * dw[:, None])
    return out[:, 0] if env.ndim == 2 else out


def _rotation(R) -> np.ndarray:
    r = np.asarray(R, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError(f"rotation must be a finite (3, 3) matrix, got shape {r.shape}")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
        raise ValueError("rotation must be a proper rotation matrix (R R^T = I, det R = +1)")
    return r


def rotation_about_axis(axis, degrees: float) -> np.ndarray:
    """Right-handed rotation matrix (3, 3) by ``degrees`` about ``axis`` (Rodrigues)."""
    k = normalize_directions(axis).reshape(3)
    a = np.radians(float(degrees))
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)


def rotate_environment_samples(radiance_samples, direction_set: DirectionSet, rotation,
                               method: str = "auto") -> np.ndarray:
    """Weighted lighting of a rotated environment from its canonical samples (paper sec. 5).

    The environment rotated by ``R`` is ``L_R(w) = L(R^T w)``. Instead of resampling the image,
    the lattice points are rotated by ``R^T`` and the *already sampled* radiance is
    interpolated there (bilinear on a latlong or cube lattice, barycentric on the hull for
    other sets; :func:`.directions.interpolation_weights`), then weighted by the solid angles.

    Parameters
    ----------
    radiance_samples : array_like, shape (S,) or (S, C)
        Radiance ``L(w_j)`` of the canonical environment at the sample directions (not weighted;
        e.g. :func:`sample_equirect`).
    direction_set : DirectionSet
    rotation : array_like, shape (3, 3)
        Proper rotation ``R`` applied to the environment.
    method : str
        Interpolation method, see :func:`.directions.interpolation_weights`.

    Returns
    -------
    ndarray, shape (S,) or (S, C), float64
        ``L(R^T w_j) dw_j``.
    """
    R = _rotation(rotation)
    L = np.asarray(radiance_samples, dtype=np.float64)
    if L.shape[:1] != (direction_set.size,) or L.ndim > 2:
        raise ValueError(f"radiance_samples must have shape ({direction_set.size},) or "
                         f"({direction_set.size}, C), got {L.shape}")
    q = direction_set.directions @ R          # rows are R^T w_j
    idx, w = interpolation_weights(direction_set, q, method)
    dw = direction_set.solid_angles
    if L.ndim == 1:
        return np.sum(L[idx] * w, axis=1) * dw
    return np.einsum("qk,qkc->qc", w, L[idx]) * dw[:, None]


# ----------------------------------------------------------------------------------------------
# local lights


def inside_convex_hull(points, query) -> np.ndarray | bool:
    """Whether query points lie strictly inside the convex hull of ``points``.

    Parameters
    ----------
    points : array_like, shape (V, 3)
        Scene vertices.
    query : array_like, shape (3,) or (Q, 3)

    Returns
    -------
    bool or ndarray of bool, shape (Q,)
        False for every query if the points span no volume (fewer than 4 points, or coplanar /
        collinear: a flat scene has an empty interior).
    """
    p = np.asarray(points, dtype=np.float64)
    q = np.asarray(query, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or q.shape[-1:] != (3,) or q.ndim > 2:
        raise ValueError(f"points (V, 3) and query (3,) or (Q, 3) expected, got {p.shape}, "
                         f"{q.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise ValueError("points and query must be finite")
    qq = q.reshape(-1, 3)
    inside = np.zeros(qq.shape[0], dtype=bool)
    if p.shape[0] >= 4:
        try:
            hull = scipy.spatial.ConvexHull(p)
        except scipy.spatial.QhullError:
            hull = None              # flat or degenerate: no interior
        if hull is not None:
            scale = max(float(np.ptp(p, axis=0).max()), 1e-300)
            inside = np.all(qq @ hull.equations[:, :3].T + hull.equations[:, 3]
                            < -1e-12 * scale, axis=1)
    return bool(inside[0]) if q.ndim == 1 else inside


def point_light_weights(positions, normals, direction_set: DirectionSet, light_pos, power: float,
                        k: int = 1, sparse: bool = False):
    """Per-vertex weighted lighting of an isotropic point light (paper sec. 4.2.1, eq. 4).

    For each vertex the light is placed on its ``k`` sample directions nearest to the direction
    towards the light, sharing the light's integrated radiance ``I / r^2`` (``I = power / 4 pi``
    W/sr, ``r`` the distance). Shading with these weights gives
    ``rho / pi * I / r^2 * T[x, j*]`` ~ ``rho / pi * I cos(theta) / r^2`` (times visibility),
    the diffuse response to a point light. Vertices facing away from the light (``n . l <= 0``)
    get zero.

    Only valid outside the convex hull of the scene (sec. 8: the sampled visibility is global);
    a :class:`LightInsideHullWarning` is issued otherwise.

    Parameters
    ----------
    positions : array_like, shape (V, 3)
        Vertex positions (m), world frame.
    normals : array_like, shape (V, 3)
    direction_set : DirectionSet
        The directions the transport was sampled at.
    light_pos : array_like, shape (3,)
    power : float
        Radiant power (W) of an isotropic source. (Blender's light "Power" may need a
        renderer-specific factor; calibrate against a bake.)
    k : int
        Number of nearest directions sharing the light (paper: usually 1).
    sparse : bool
        Return a ``scipy.sparse.csr_matrix`` instead of a dense array.

    Returns
    -------
    Lw : ndarray or csr_matrix, shape (V, S), float64 (W m^-2)
    """
    x = np.asarray(positions, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    lp = np.asarray(light_pos, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or n.shape != x.shape:
        raise ValueError(f"positions and normals must both have shape (V, 3), got {x.shape}, "
                         f"{n.shape}")
    if lp.shape != (3,) or not np.all(np.isfinite(lp)):
        raise ValueError(f"light_pos must be a finite 3-vector, got {lp!r}")
    if not np.isfinite(power):
        raise ValueError("power must be finite")
    if inside_convex_hull(x, lp):
        warnings.warn("the point light is inside the convex hull of the scene; the sampled "
                      "(global) visibility does not hold there and shading will be wrong "
                      "(Nowrouzezahrai et al. 2008, sec. 8)", LightInsideHullWarning,
                      stacklevel=2)
    to_light = lp - x
    r2 = np.sum(to_light * to_light, axis=1)
    if np.any(r2 == 0):
        raise ValueError("the point light coincides with a vertex")
    idx, _ = nearest_directions(direction_set, to_light, k)
    facing = np.einsum("vi,vi->v", n, to_light) > 0
    value = np.where(facing, float(power) / (4.0 * np.pi) / r2 / k, 0.0)
    V, S = x.shape[0], direction_set.size
    rows = np.repeat(np.arange(V), k)
    mat = scipy.sparse.csr_matrix((np.repeat(value, k), (rows, idx.ravel())), shape=(V, S))
    return mat if sparse else mat.toarray()
