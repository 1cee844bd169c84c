"""Clustered PCA (CPCA, Sloan et al. 2003) with the cost model of Mahajan et al. 2007.

The V vertices (or texels) are partitioned into clusters; cluster ``i`` with ``p_i`` members
keeps its own mean ``m_i`` (S,) and ``n_i`` orthonormal basis rows ``E_i`` (n_i, S), fitted with
:func:`.eigentransport.fit_eigentransport` (each cluster *is* an
:class:`~.eigentransport.Eigentransport` of its rows). Shading is exact for the kept rank:

    B(x) = rho / pi * ( m_i . Lw + C[x] . (E_i Lw) ),     x in cluster i

Rendering / storage cost (Mahajan 2007 eq. 17-19, lighting first projected to ``N`` global basis
functions): ``c = sum_i n_i (p_i + N)``, per vertex ``c / V``. The global dimension ``N`` is the
number of singular values of a random vertex subset of ``T`` holding 99.9% of its energy
(sec. 5.1, :func:`global_dimension`).

Counting the mean. The paper does not centre (footnote 2), so every basis vector it counts is
one of ours *or* the mean. Here ``n_i`` counts the cluster mean as one vector when it is non-zero
(it costs exactly like a basis vector: one N-term projection per cluster and one term per
vertex). Without this, a one-vertex cluster would cost nothing and adaptive subdivision would
degenerate to singletons. ``cost(count_mean=False)`` gives the centred-only count.

Tolerance. ``tol`` is the allowed *fraction of each cluster's energy* ``||T_i||_F^2`` left
unexplained: cluster ``i`` keeps the fewest components with
``||T_i - m_i - C_i E_i||_F^2 <= tol ||T_i||_F^2``, so the whole model has
``relative_rms_error(T, reconstruct()) <= sqrt(tol)``. ``tol = 1e-3`` is the paper's 99.9%.
``tol = 0`` keeps the full numerical rank, ``tol = 1`` keeps the means only.

Adaptive subdivision (sec. 5.2): :func:`adaptive_cpca` starts with a few clusters, tries to split
each in two with CPCA and keeps a split only if the cost falls, recursively.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from .eigentransport import (
    Eigentransport,
    _albedo_factor,
    read_sidecar_metadata,
    _lighting,
    _transport,
    fit_eigentransport,
    relative_rms_error,
)

FORMAT = "relightable_textures.cpca"
FORMAT_VERSION = 1

#: default fraction of energy for the global dimension N (Mahajan 2007 sec. 5.1: "usually 99.9%")
GLOBAL_ENERGY = 0.999
#: default size of the random vertex subset used for N
GLOBAL_SUBSET = 2000


# ----------------------------------------------------------------------------------------------
# global dimension


def energy_dimension(singular_values, energy: float) -> int:
    """Smallest ``n`` whose first ``n`` singular values hold ``energy`` of ``sum sigma^2``.

    Parameters
    ----------
    singular_values : array_like, shape (k,)
        Non-negative, any order (sorted here).
    energy : float in (0, 1]

    Returns
    -------
    int
        0 when all singular values are zero.
    """
    if not 0.0 < float(energy) <= 1.0:
        raise ValueError(f"energy must lie in (0, 1], got {energy!r}")
    s2 = np.sort(np.asarray(singular_values, dtype=np.float64) ** 2)[::-1]
    total = float(s2.sum())
    if total <= 0.0:
        return 0
    frac = np.cumsum(s2) / total
    return int(np.searchsorted(frac, float(energy) - 1e-12) + 1)


def singular_values(X) -> np.ndarray:
    """Singular values of a (m, k) float64 matrix, descending, via the eigenvalues of the
    smaller Gram matrix (``X X^T`` or ``X^T X``); several times faster than an SVD for the
    energy counts used here (relative accuracy ~eps of the largest squared value)."""
    X = np.asarray(X, dtype=np.float64)
    if X.size == 0:
        return np.zeros(0)
    G = X @ X.T if X.shape[0] <= X.shape[1] else X.T @ X
    lam = scipy.linalg.eigvalsh(G)[::-1]
    return np.sqrt(np.clip(lam, 0.0, None))


def global_dimension(T, energy: float = GLOBAL_ENERGY, subset: int | None = GLOBAL_SUBSET,
                     seed: int = 0) -> int:
    """Global dimension ``N`` of the transport (Mahajan 2007 sec. 5.1).

    SVD of a random subset of rows (no centring, as in the paper), ``N`` = number of singular
    values holding ``energy`` of the subset's energy.

    Parameters
    ----------
    T : array_like, shape (V, S)
    energy : float in (0, 1]
        Default 0.999.
    subset : int or None
        Number of rows drawn without replacement; None or >= V uses every row.
    seed : int
        Seed of the row draw.

    Returns
    -------
    int
        ``0 <= N <= min(subset, S)``; 0 for all-zero transport.
    """
    T = _transport(T)
    V = T.shape[0]
    if subset is not None:
        if int(subset) < 1:
            raise ValueError(f"subset must be >= 1 rows, got {subset!r}")
        if int(subset) < V:
            rows = np.random.default_rng(seed).choice(V, int(subset), replace=False)
            T = T[np.sort(rows)]
    return energy_dimension(singular_values(T), energy)


# ----------------------------------------------------------------------------------------------
# the model


def _cluster_dim(model: Eigentransport, count_mean: bool) -> int:
    return model.d + (1 if count_mean and np.any(model.mean != 0.0) else 0)


@dataclass
class CPCA:
    """A clustered PCA model of transport.

    Attributes
    ----------
    labels : ndarray, shape (V,), int64
        Cluster index of every vertex, ``0 <= labels < n_clusters``; every cluster non-empty.
    clusters : list of Eigentransport
        Cluster ``i``'s mean (S,), basis (n_i, S) and coefficients (p_i, n_i) of its members in
        increasing vertex order (``np.flatnonzero(labels == i)``).
    N : int
        Global dimension used by the cost model.
    info : dict
        JSON-safe fit record (criterion, iterations, dropped empty clusters, adaptive tree ...).
    """

    labels: np.ndarray
    clusters: list
    N: int
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.labels = np.asarray(self.labels, dtype=np.int64).reshape(-1)
        k = len(self.clusters)
        if k < 1:
            raise ValueError("a CPCA model needs at least one cluster")
        if self.labels.size and (self.labels.min() < 0 or self.labels.max() >= k):
            raise ValueError(f"labels must lie in [0, {k}), got range "
                             f"[{self.labels.min()}, {self.labels.max()}]")
        counts = np.bincount(self.labels, minlength=k)
        S = self.clusters[0].n_samples
        for i, c in enumerate(self.clusters):
            if c.n_samples != S:
                raise ValueError(f"cluster {i} has {c.n_samples} samples, cluster 0 has {S}")
            if c.n_vertices != counts[i]:
                raise ValueError(f"cluster {i} has {c.n_vertices} coefficient rows but "
                                 f"{counts[i]} labelled vertices")
        self.N = int(self.N)
        # member lists once (stable sort keeps increasing vertex order inside each cluster)
        order = np.argsort(self.labels, kind="stable")
        self._members = np.split(order, np.cumsum(counts)[:-1])

    # -- sizes -----------------------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return int(self.labels.shape[0])

    @property
    def n_samples(self) -> int:
        return int(self.clusters[0].n_samples)

    @property
    def n_clusters(self) -> int:
        return len(self.clusters)

    def members(self, i: int) -> np.ndarray:
        """Vertex indices of cluster ``i`` (increasing); shape (p_i,)."""
        return self._members[i]

    def sizes(self) -> np.ndarray:
        """``p_i``, shape (k,)."""
        return np.bincount(self.labels, minlength=self.n_clusters)

    def dims(self, count_mean: bool = True) -> np.ndarray:
        """``n_i``, shape (k,) (mean counted as one vector when non-zero, see module doc)."""
        return np.array([_cluster_dim(c, count_mean) for c in self.clusters], dtype=np.int64)

    # -- cost model ------------------------------------------------------------------------------
    def cost(self, count_mean: bool = True, N: int | None = None) -> float:
        """Total cost ``c = sum_i n_i (p_i + N)`` (Mahajan 2007 eq. 17/19), in multiply-adds per
        lighting (equivalently stored values)."""
        N = self.N if N is None else int(N)
        return float(np.sum(self.dims(count_mean) * (self.sizes() + N)))

    def cost_per_vertex(self, count_mean: bool = True, N: int | None = None) -> float:
        """``c / V`` (eq. 18): effective number of basis functions per vertex."""
        return self.cost(count_mean, N) / self.n_vertices

    # -- shading ---------------------------------------------------------------------------------
    def shade(self, L_weighted, albedo=1.0) -> np.ndarray:
        """Exact shading of the clustered reconstruction.

        ``B[x] = rho / pi * (m_i . Lw + C[x] . (E_i Lw))`` for ``x`` in cluster ``i``; equals
        ``rho / pi * reconstruct() @ Lw`` (same convention as :meth:`Eigentransport.shade`; pass
        ``albedo=np.pi`` for the plain product ``T Lw``).

        Parameters
        ----------
        L_weighted : array_like, shape (S,) or (S, C)
            Radiance (W m^-2 sr^-1) times solid angle (sr) per sample direction.
        albedo : float or array_like, shape (V,), (C,) or (V, C)

        Returns
        -------
        B : ndarray, shape (V,) or (V, C), float64
        """
        lw = _lighting(L_weighted, self.n_samples)
        B = np.empty((self.n_vertices,) + lw.shape[1:])
        for i, c in enumerate(self.clusters):
            mean_term, lc = c.project_lighting(lw)
            B[self.members(i)] = c.coefficients @ lc + mean_term
        return B * _albedo_factor(albedo, B.shape)

    def shade_local(self, L_weighted_per_vertex, albedo=1.0) -> np.ndarray:
        """Shading under per-vertex lighting (local lights), as
        :meth:`Eigentransport.shade_local` cluster by cluster.

        Parameters
        ----------
        L_weighted_per_vertex : array_like or scipy.sparse matrix, shape (V, S)
        albedo : float or array_like, shape (V,)

        Returns
        -------
        B : ndarray, shape (V,)
        """
        import scipy.sparse

        V, S = self.n_vertices, self.n_samples
        lw = (scipy.sparse.csr_matrix(L_weighted_per_vertex, dtype=np.float64)
              if scipy.sparse.issparse(L_weighted_per_vertex)
              else np.asarray(L_weighted_per_vertex, dtype=np.float64))
        if lw.shape != (V, S):
            raise ValueError(f"per-vertex lighting must have shape ({V}, {S}), got {lw.shape}")
        B = np.empty(V)
        for i, c in enumerate(self.clusters):
            idx = self.members(i)
            B[idx] = c.shade_local(lw[idx], albedo=np.pi)  # albedo pi: the plain dot product
        return B * _albedo_factor(albedo, B.shape)

    @property
    def d(self) -> int:
        """Largest per-cluster basis size ``max n_i`` (mean not counted)."""
        return int(max(c.d for c in self.clusters))

    def storage_bytes(self) -> dict:
        """Bytes of the stored arrays at 4 bytes per value (float32).

        Returns
        -------
        dict of int
            ``labels`` (4 V), ``coefficients`` (4 V max n_i, as stored padded),
            ``coefficients_packed`` (4 sum p_i n_i), ``mean`` (4 k S), ``basis`` (4 S sum n_i),
            ``sidecar`` (labels + padded coefficients + means + bases) and ``runtime``
            = 4 sum_i n_i (p_i + 1): the packed coefficients plus one projected lighting value
            per basis vector (the CPCA counterpart of eigentransport's ``paper_runtime``).
        """
        V, S = self.n_vertices, self.n_samples
        p, n = self.sizes(), np.array([c.d for c in self.clusters], dtype=np.int64)
        out = {"labels": 4 * V, "coefficients": 4 * V * self.d,
               "coefficients_packed": int(4 * np.sum(p * n)), "mean": 4 * self.n_clusters * S,
               "basis": int(4 * S * n.sum()), "runtime": int(4 * np.sum(n * (p + 1)))}
        out["sidecar"] = out["labels"] + out["coefficients"] + out["mean"] + out["basis"]
        return out

    def reconstruct(self) -> np.ndarray:
        """Clustered reconstruction; shape (V, S), float64."""
        out = np.empty((self.n_vertices, self.n_samples))
        for i, c in enumerate(self.clusters):
            out[self.members(i)] = c.reconstruct()
        return out

    # -- storage ---------------------------------------------------------------------------------
    def to_arrays(self) -> dict:
        """Arrays for an ``.npz`` sidecar (loads with ``allow_pickle=False``).

        Returns
        -------
        dict
            ``labels`` (V,) int32; ``mean`` (k, S) float32; ``basis`` (sum n_i, S) float32 (the
            clusters' bases stacked); ``basis_offsets`` (k + 1,) int64 (cluster ``i`` owns rows
            ``basis_offsets[i]:basis_offsets[i+1]``); ``coefficients`` (V, max n_i) float32
            (vertex ``x`` uses its first ``n_{labels[x]}`` entries, the rest are 0);
            ``eigenvalues`` (sum r_i,) float64 with ``eigen_offsets`` (k + 1,); ``metadata``
            0-d unicode JSON (format, version, N, per-cluster energies/selection, info).
        """
        k, V, S = self.n_clusters, self.n_vertices, self.n_samples
        d = np.array([c.d for c in self.clusters], dtype=np.int64)
        r = np.array([c.rank for c in self.clusters], dtype=np.int64)
        off = np.concatenate([[0], np.cumsum(d)]).astype(np.int64)
        eoff = np.concatenate([[0], np.cumsum(r)]).astype(np.int64)
        coef = np.zeros((V, int(d.max()) if k else 0), dtype=np.float32)
        for i, c in enumerate(self.clusters):
            coef[self.members(i), :c.d] = c.coefficients
        meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "N": self.N,
                "total_energy": [c.total_energy for c in self.clusters],
                "selection": [c.selection for c in self.clusters], "info": self.info}
        return {"labels": self.labels.astype(np.int32),
                "mean": np.stack([c.mean for c in self.clusters]).astype(np.float32),
                "basis": (np.concatenate([c.basis for c in self.clusters]) if off[-1]
                          else np.zeros((0, S))).astype(np.float32),
                "basis_offsets": off, "coefficients": coef,
                "eigenvalues": np.concatenate([c.eigenvalues for c in self.clusters]
                                              ).astype(np.float64),
                "eigen_offsets": eoff,
                "metadata": np.array(json.dumps(meta, allow_nan=True))}

    @classmethod
    def from_arrays(cls, arrays) -> "CPCA":
        """Inverse of :meth:`to_arrays` (dict or ``np.load`` result); float64 copies of the
        stored float32 values."""
        meta = read_sidecar_metadata(arrays, FORMAT, FORMAT_VERSION, "a CPCA")
        labels = np.asarray(arrays["labels"], dtype=np.int64)
        mean = np.asarray(arrays["mean"], np.float64)
        basis = np.asarray(arrays["basis"], np.float64)
        off = np.asarray(arrays["basis_offsets"], np.int64)
        eig = np.asarray(arrays["eigenvalues"], np.float64)
        eoff = np.asarray(arrays["eigen_offsets"], np.int64)
        coef = np.asarray(arrays["coefficients"], np.float64)
        clusters = []
        for i in range(mean.shape[0]):
            n = int(off[i + 1] - off[i])
            clusters.append(Eigentransport(
                mean[i], basis[off[i]:off[i + 1]].reshape(n, mean.shape[1]),
                coef[labels == i, :n], eig[eoff[i]:eoff[i + 1]], meta["total_energy"][i],
                None, meta["selection"][i]))
        return cls(labels, clusters, meta["N"], meta.get("info", {}))


# ----------------------------------------------------------------------------------------------
# fitting


def _fit_cluster(X: np.ndarray, tol: float | None, dims: int | None) -> Eigentransport:
    """PCA of one cluster's rows with ``n`` from ``dims`` (clipped to rank) or ``tol``."""
    full = fit_eigentransport(X, d=min(X.shape))        # every non-noise component
    if dims is not None:
        model = full.truncate(min(int(dims), full.d))
        model.selection.update(criterion="dims", target=int(dims),
                               clipped_to_rank=int(dims) > full.d)
        return model
    energy = float(np.sum(X * X))                       # uncentred ||T_i||_F^2
    allowed = tol * energy
    # residual after n components = centred energy - sum of the first n eigenvalues
    resid = full.total_energy - np.concatenate([[0.0], np.cumsum(full.eigenvalues)])
    ok = np.nonzero(resid <= allowed * (1.0 + 1e-12) + 1e-300)[0]
    n = int(ok[0]) if ok.size else full.d
    model = full.truncate(min(n, full.d))
    model.selection.update(criterion="tol", target=float(tol),
                           residual_fraction=float(resid[n] / energy) if energy > 0 else 0.0)
    return model


def _check_choice(tol, dims):
    if (tol is None) == (dims is None):
        raise ValueError("give exactly one of tol (fraction of each cluster's energy left "
                         "unexplained, in [0, 1]) or dims (basis vectors per cluster)")
    if tol is not None:
        tol = float(tol)
        if not 0.0 <= tol <= 1.0:
            raise ValueError(f"tol must lie in [0, 1] (0 = exact, 1 = cluster means only), "
                             f"got {tol!r}")
    if dims is not None:
        if isinstance(dims, bool) or not isinstance(dims, (int, np.integer)) or dims < 0:
            raise ValueError(f"dims must be a non-negative integer, got {dims!r}")
        dims = int(dims)
    return tol, dims


def kmeans(X, k: int, n_iter: int = 20, seed: int = 0) -> np.ndarray:
    """Lloyd's k-means with k-means++ seeding; labels (V,) in ``[0, k')``, ``k' <= k``.

    Empty clusters (identical rows, fewer distinct rows than ``k``) are dropped and the labels
    renumbered, so every returned label is used.
    """
    X = np.asarray(X, dtype=np.float64)
    V = X.shape[0]
    rng = np.random.default_rng(seed)
    sq = np.einsum("ij,ij->i", X, X)
    centres = [X[rng.integers(V)]]
    d2 = np.maximum(sq - 2 * X @ centres[0] + centres[0] @ centres[0], 0.0)
    for _ in range(1, k):
        tot = d2.sum()
        if tot <= 0.0:
            break                                   # every row coincides with a centre
        c = X[rng.choice(V, p=d2 / tot)]
        centres.append(c)
        d2 = np.minimum(d2, np.maximum(sq - 2 * X @ c + c @ c, 0.0))
    C = np.array(centres)
    labels = np.zeros(V, dtype=np.int64)
    for it in range(n_iter):
        dist = sq[:, None] - 2 * X @ C.T + np.einsum("ij,ij->i", C, C)[None]
        new = np.argmin(dist, axis=1)
        if it and np.array_equal(new, labels):
            break
        labels = new
        # centroids of all clusters at once (one pass over the rows, not one mask per cluster);
        # a cluster that lost every row keeps its centre
        order = np.argsort(labels, kind="stable")
        counts = np.bincount(labels, minlength=C.shape[0])
        used = np.nonzero(counts)[0]
        starts = np.concatenate([[0], np.cumsum(counts[used])[:-1]])
        C[used] = np.add.reduceat(X[order], starts, axis=0) / counts[used, None]
    return np.unique(labels, return_inverse=True)[1].astype(np.int64)


def _assignment_errors(X: np.ndarray, clusters) -> np.ndarray:
    """Squared reconstruction error of every row in every cluster's affine subspace; (V, k).

    ``||x - m_j||^2 - ||E_j (x - m_j)||^2`` (orthonormal rows ``E_j``), expanded so that all
    clusters take two matrix products, ``X M^T`` (V, k) and ``X E^T`` (V, sum n_j), instead
    of a centred (V, S) copy of ``X`` per cluster (measured: the analysis of a 4421 x 384
    statue spent 57 of its 128 s here). The expansion loses at most ~eps ||x||^2 per entry,
    far below the per-cluster tolerances it decides between.
    """
    M = np.stack([c.mean for c in clusters])                          # (k, S)
    sq = np.einsum("ij,ij->i", X, X)
    err = sq[:, None] - 2.0 * (X @ M.T) + np.einsum("ij,ij->i", M, M)[None, :]
    dims = np.array([c.basis.shape[0] for c in clusters])
    if dims.sum():
        E = np.concatenate([c.basis for c in clusters], axis=0)        # (sum n_j, S)
        offsets = np.concatenate([c.basis @ c.mean for c in clusters])  # E_j m_j, stacked
        P = X @ E.T - offsets[None, :]                                # E_j (x - m_j)
        P *= P
        starts = np.concatenate([[0], np.cumsum(dims)[:-1]])
        has = dims > 0
        err[:, has] -= np.add.reduceat(P, starts[has], axis=1)
    return err


def fit_cpca(T, n_clusters: int, tol: float | None = None, dims: int | None = None,
             n_iter: int = 10, seed: int = 0, N: int | None = None,
             global_energy: float = GLOBAL_ENERGY, global_subset: int | None = GLOBAL_SUBSET,
             labels=None) -> CPCA:
    """Clustered PCA (Sloan et al. 2003) of transport rows.

    k-means initialisation, then alternate (a) per-cluster PCA with ``n_i`` from ``tol`` or
    ``dims`` and (b) reassignment of every row to the cluster whose affine subspace
    ``m_i + span(E_i)`` reconstructs it best, until the labels stop changing or ``n_iter``
    rounds; clusters emptied on the way are dropped. The final model is the PCA of the last
    assignment.

    Parameters
    ----------
    T : array_like, shape (V, S)
        Transport (dimensionless), fitted in float64.
    n_clusters : int
        Requested cluster count ``1 <= k <= V``. Fewer clusters come back if the rows have
        fewer than ``k`` distinct values (``info["empty_dropped"]``).
    tol : float in [0, 1], optional
        Fraction of each cluster's energy ``||T_i||_F^2`` left unexplained (module doc).
    dims : int >= 0, optional
        Fixed basis vectors per cluster (clipped to each cluster's rank).
    n_iter : int >= 0
        Reassignment rounds (0 = plain k-means clusters).
    seed : int
        Seed of the k-means++ draw and of the subset for ``N``.
    N : int, optional
        Global dimension for the cost model; default :func:`global_dimension`.
    global_energy, global_subset
        Passed to :func:`global_dimension` when ``N`` is None.
    labels : array_like (V,), optional
        Initial assignment instead of k-means (values renumbered to ``0..k'-1``).

    Exactly one of ``tol``, ``dims``.

    Returns
    -------
    CPCA
    """
    T = _transport(T)
    tol, dims = _check_choice(tol, dims)
    V = T.shape[0]
    if isinstance(n_clusters, bool) or not isinstance(n_clusters, (int, np.integer)) \
            or n_clusters < 1:
        raise ValueError(f"n_clusters must be a positive integer, got {n_clusters!r}")
    if n_clusters > V:
        raise ValueError(f"n_clusters={n_clusters} exceeds the number of vertices V={V}; "
                         "a cluster needs at least one vertex")
    if int(n_iter) < 0:
        raise ValueError(f"n_iter must be >= 0, got {n_iter!r}")
    if N is None:
        N = global_dimension(T, global_energy, global_subset, seed)
    if labels is None and int(n_clusters) == V:
        # one cluster per distinct row: exact, and k-means++ with k = V would cost O(V^2 S)
        lab = np.unique(T, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)
        n_iter = 0
    elif labels is None:
        lab = kmeans(T, int(n_clusters), seed=seed)
    else:
        lab = np.asarray(labels).reshape(-1)
        if lab.shape != (V,):
            raise ValueError(f"labels must have shape ({V},), got {lab.shape}")
        lab = np.unique(lab, return_inverse=True)[1].astype(np.int64)
    iters = 0
    converged = False
    for it in range(int(n_iter)):
        k = int(lab.max()) + 1
        clusters = [_fit_cluster(T[lab == j], tol, dims) for j in range(k)]
        err = _assignment_errors(T, clusters)
        new = np.argmin(err, axis=1)
        # keep a row where it is when it ties (avoids flip-flopping on identical errors)
        stay = err[np.arange(V), lab] <= err[np.arange(V), new] * (1 + 1e-12) + 1e-300
        new = np.where(stay, lab, new)
        iters = it + 1
        if np.array_equal(new, lab):
            converged = True
            break
        lab = np.unique(new, return_inverse=True)[1].astype(np.int64)
    k = int(lab.max()) + 1
    clusters = [_fit_cluster(T[lab == j], tol, dims) for j in range(k)]
    info = {"criterion": "tol" if tol is not None else "dims",
            "target": tol if tol is not None else dims, "n_clusters_requested": int(n_clusters),
            "n_clusters": k, "empty_dropped": int(n_clusters) - k if labels is None else 0,
            "iterations": iters, "converged": converged,
            "relative_rms_error": relative_rms_error(T, _reconstruct(lab, clusters, T.shape))}
    return CPCA(lab, clusters, int(N), info)


def _reconstruct(labels, clusters, shape) -> np.ndarray:
    out = np.empty(shape)
    for j, c in enumerate(clusters):
        out[labels == j] = c.reconstruct()
    return out


# ----------------------------------------------------------------------------------------------
# adaptive subdivision (Mahajan 2007 sec. 5.2)


def _node_cost(c: Eigentransport, N: int, count_mean: bool) -> float:
    return float(_cluster_dim(c, count_mean) * (c.n_vertices + N))


def adaptive_cpca(T, start_clusters: int = 8, tol: float = 1e-3, n_iter: int = 10,
                  seed: int = 0, N: int | None = None, max_depth: int = 20,
                  min_size: int = 2, count_mean: bool = True,
                  global_energy: float = GLOBAL_ENERGY,
                  global_subset: int | None = GLOBAL_SUBSET, ways=(2,)) -> CPCA:
    """Adaptive hierarchical CPCA (Mahajan 2007 sec. 5.2).

    Run :func:`fit_cpca` with ``start_clusters``; then, for every cluster, fit a 2-cluster CPCA
    of its rows and keep the split only if ``n_a (p_a + N) + n_b (p_b + N) < n (p + N)``;
    recurse into the kept halves. The leaves' fits are used as they are, so the result never
    costs more than the initial clustering (``info["initial_cost"]``).

    Parameters
    ----------
    T : array_like, shape (V, S)
    start_clusters : int
        Initial CPCA cluster count (paper: 5-10); clipped to V.
    tol : float in [0, 1]
        Per-cluster tolerance (see module doc); the cost model needs ``n_i`` from a tolerance.
    n_iter, seed : as :func:`fit_cpca`.
    N : int, optional
        Global dimension; default :func:`global_dimension`.
    max_depth : int
        Maximum number of successive splits below an initial cluster.
    min_size : int >= 2
        Clusters with fewer vertices are not split.
    count_mean : bool
        Count each non-zero cluster mean as a basis vector in the cost (module doc).
    ways : sequence of int >= 2
        Split arities tried in turn until one lowers the cost: ``(2,)`` is the paper's binary
        split; ``(2, 4)`` looks one level further when halving alone does not pay (a cluster
        whose halves each still need most of its basis may pay off in quarters).

    Returns
    -------
    CPCA
        ``info["tree"]``: list of node dicts ``{"id", "parent", "depth", "size", "n", "cost",
        "split_cost" (None if not tried), "split" (bool), "children" [ids], "leaf" (index into
        ``clusters`` or None)}``; roots have ``parent`` None. ``info["initial_cost"]``,
        ``info["cost"]``, ``info["splits_tried"]``, ``info["splits_kept"]``.
    """
    T = _transport(T)
    tol, _ = _check_choice(tol, None)
    ways = tuple(int(w) for w in ways)
    if not ways or min(ways) < 2:
        raise ValueError(f"ways must be split arities >= 2, got {ways!r}")
    if int(min_size) < 2:
        raise ValueError(f"min_size must be >= 2 (a cluster of one vertex cannot split), "
                         f"got {min_size!r}")
    V = T.shape[0]
    if N is None:
        N = global_dimension(T, global_energy, global_subset, seed)
    N = int(N)
    start = fit_cpca(T, min(int(start_clusters), V), tol=tol, n_iter=n_iter, seed=seed, N=N)
    tree: list = []
    leaves: list = []                   # (vertex indices, Eigentransport, node id)
    stack = []
    for i, c in enumerate(start.clusters):
        nid = len(tree)
        tree.append({"id": nid, "parent": None, "depth": 0, "size": c.n_vertices,
                     "n": _cluster_dim(c, count_mean), "cost": _node_cost(c, N, count_mean),
                     "split_cost": None, "split": False, "children": [], "leaf": None})
        stack.append((start.members(i), c, nid))
    tried = kept = 0
    while stack:
        idx, c, nid = stack.pop()
        node = tree[nid]
        if idx.size >= int(min_size) and node["depth"] < int(max_depth) and node["n"] > 0:
            tried += 1
            accepted = None
            for way in ways:
                if idx.size < way:
                    break
                sub = fit_cpca(T[idx], way, tol=tol, n_iter=n_iter, seed=seed, N=N)
                if sub.n_clusters < 2:
                    break                           # identical rows: nothing to split
                split_cost = sum(_node_cost(s, N, count_mean) for s in sub.clusters)
                node["split_cost"] = split_cost
                if split_cost < node["cost"]:
                    accepted = sub
                    break
            if accepted is not None:
                kept += 1
                node["split"] = True
                for j, s in enumerate(accepted.clusters):
                    cid = len(tree)
                    tree.append({"id": cid, "parent": nid, "depth": node["depth"] + 1,
                                 "size": s.n_vertices, "n": _cluster_dim(s, count_mean),
                                 "cost": _node_cost(s, N, count_mean), "split_cost": None,
                                 "split": False, "children": [], "leaf": None})
                    node["children"].append(cid)
                    stack.append((idx[accepted.members(j)], s, cid))
                continue
        node["leaf"] = len(leaves)
        leaves.append((idx, c, nid))
    labels = np.empty(V, dtype=np.int64)
    for li, (idx, _, _) in enumerate(leaves):
        labels[idx] = li
    clusters = [c for _, c, _ in leaves]
    model = CPCA(labels, clusters, N, {})
    model.info = {"criterion": "tol", "target": tol, "adaptive": True,
                  "start_clusters": start.n_clusters, "n_clusters": model.n_clusters,
                  "initial_cost": start.cost(count_mean), "cost": model.cost(count_mean),
                  "count_mean": bool(count_mean), "ways": list(ways), "splits_tried": tried,
                  "splits_kept": kept,
                  "relative_rms_error": relative_rms_error(T, model.reconstruct()),
                  "tree": tree}
    return model


# ----------------------------------------------------------------------------------------------
# runtime helpers


def model_from_arrays(arrays):
    """An :class:`Eigentransport` or a :class:`CPCA`, whichever the sidecar holds."""
    try:
        fmt = json.loads(str(np.asarray(arrays["metadata"])[()])).get("format")
    except KeyError:
        raise ValueError("not a transport sidecar: no 'metadata' entry") from None
    return CPCA.from_arrays(arrays) if fmt == FORMAT else Eigentransport.from_arrays(arrays)


def cluster_colors(labels) -> np.ndarray:
    """A distinct, deterministic linear-RGB colour per cluster label.

    Hues step by the golden angle so neighbouring labels differ strongly; saturation and value
    alternate over three levels so large cluster counts stay distinguishable.

    Parameters
    ----------
    labels : array_like of int, shape (V,)

    Returns
    -------
    rgb : ndarray, shape (V, 3), float64 in [0, 1] (linear)
    """
    lab = np.asarray(labels, dtype=np.int64).reshape(-1)
    if lab.size and lab.min() < 0:
        raise ValueError("cluster labels must be >= 0")
    h = (lab * 0.6180339887498949) % 1.0
    sat = np.array([0.85, 0.6, 0.95])[lab % 3]
    val = np.array([0.9, 0.7, 0.5])[(lab // 3) % 3]
    k = (np.array([5.0, 3.0, 1.0])[None, :] + 6.0 * h[:, None]) % 6.0
    rgb_srgb = val[:, None] * (1.0 - sat[:, None] * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0))
    return rgb_srgb ** 2.2  # display values -> linear, so the viewport shows the intended hue
