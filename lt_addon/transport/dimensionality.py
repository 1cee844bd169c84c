"""Local dimensionality of transport vs patch size, and the cost theory built on it
(Mahajan et al. 2007, sec. 3-5).

Patches are grown around seed points: on a mesh by breadth-first search over its edges (graph
distance; :func:`graph_patch_order`), on a texel grid as square blocks centred on the seed
(:func:`grid_block`). The *dimensionality* of a patch is the number of singular values of its
transport rows (uncentred, as in the paper) holding 99.95% of the energy (Fig. 7).

From the log-log slope ``s`` of dimensionality vs patch size: ``mu = r^-s`` (r = 2 for CPCA
splits, 4 for block quad splits), the split criterion (eq. 23)

    d = (1 - mu) n p + (1 - r mu) n N        (split if d > 0)

and the optimal patch size (eq. 27) ``p* = N (r mu - 1) / (1 - mu)``, i.e. about ``V / p*``
clusters.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import scipy.sparse

from .cpca import energy_dimension, singular_values
from .eigentransport import _transport

#: energy fraction defining patch dimensionality (Mahajan 2007 Fig. 7)
PATCH_ENERGY = 0.9995


def patch_dimension(T_patch, energy: float = PATCH_ENERGY) -> int:
    """Number of singular values of ``T_patch`` (p, S) holding ``energy`` of its energy
    (no centring); 0 for an all-zero patch."""
    t = _transport(T_patch)
    return energy_dimension(singular_values(t), energy)


def _adjacency(edges, n_vertices: int) -> scipy.sparse.csr_matrix:
    if scipy.sparse.issparse(edges):
        A = scipy.sparse.csr_matrix(edges)
        if A.shape != (n_vertices, n_vertices):
            raise ValueError(f"adjacency must be ({n_vertices}, {n_vertices}), got {A.shape}")
        return A
    e = np.asarray(edges, dtype=np.int64)
    if e.ndim != 2 or e.shape[1] != 2:
        raise ValueError(f"edges must have shape (E, 2) (vertex index pairs), got {e.shape}")
    if e.size and (e.min() < 0 or e.max() >= n_vertices):
        raise ValueError(f"edge indices must lie in [0, {n_vertices})")
    data = np.ones(2 * e.shape[0])
    rows = np.concatenate([e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 1], e[:, 0]])
    return scipy.sparse.csr_matrix((data, (rows, cols)), shape=(n_vertices, n_vertices))


def graph_patch_order(edges, n_vertices: int, seed: int) -> np.ndarray:
    """Vertices in breadth-first order from ``seed`` (mesh graph distance, ties by index).

    The patch of size ``p`` grown around ``seed`` is ``order[:p]``. Only the seed's connected
    component is returned.

    Parameters
    ----------
    edges : array_like (E, 2) of int, or scipy.sparse matrix (V, V)
    n_vertices : int
    seed : int

    Returns
    -------
    order : ndarray (k,), int64, ``order[0] == seed``
    """
    A = _adjacency(edges, int(n_vertices))
    if not 0 <= int(seed) < n_vertices:
        raise ValueError(f"seed {seed} outside [0, {n_vertices})")
    seen = np.zeros(n_vertices, dtype=bool)
    seen[seed] = True
    order = [int(seed)]
    q = deque([int(seed)])
    while q:
        v = q.popleft()
        nb = np.sort(A.indices[A.indptr[v]:A.indptr[v + 1]])
        for u in nb:
            if not seen[u]:
                seen[u] = True
                order.append(int(u))
                q.append(int(u))
    return np.array(order, dtype=np.int64)


def grid_block(shape, center, half: int) -> np.ndarray:
    """Flat texel indices of the square block ``[cy-half, cy+half] x [cx-half, cx+half]``,
    clipped to the grid of ``shape = (H, W)`` (row-major texel order)."""
    H, W = int(shape[0]), int(shape[1])
    cy, cx = int(center[0]), int(center[1])
    if not (0 <= cy < H and 0 <= cx < W):
        raise ValueError(f"center {center} outside the grid {shape}")
    if int(half) < 0:
        raise ValueError(f"half must be >= 0, got {half}")
    ys = np.arange(max(cy - half, 0), min(cy + half + 1, H))
    xs = np.arange(max(cx - half, 0), min(cx + half + 1, W))
    return (ys[:, None] * W + xs[None, :]).ravel()


def dimensionality_curve(T, patches, energy: float = PATCH_ENERGY):
    """Patch sizes and dimensionalities for a sequence of patches.

    Parameters
    ----------
    T : array_like, shape (V, S)
    patches : iterable of index arrays
    energy : float

    Returns
    -------
    sizes : ndarray (k,), int64
    dims : ndarray (k,), int64
    """
    T = _transport(T)
    sizes, dims = [], []
    for idx in patches:
        idx = np.asarray(idx, dtype=np.int64)
        sizes.append(idx.size)
        dims.append(patch_dimension(T[idx], energy))
    return np.array(sizes, dtype=np.int64), np.array(dims, dtype=np.int64)


def graph_dimensionality_curve(T, edges, seed: int, sizes, energy: float = PATCH_ENERGY):
    """:func:`dimensionality_curve` for BFS patches of the given sizes around a mesh vertex
    (sizes larger than the seed's component are clipped to it)."""
    T = _transport(T)
    order = graph_patch_order(edges, T.shape[0], seed)
    sizes = sorted({min(int(p), order.size) for p in sizes if int(p) >= 1})
    return dimensionality_curve(T, [order[:p] for p in sizes], energy)


def grid_dimensionality_curve(T, shape, center, halves, energy: float = PATCH_ENERGY):
    """:func:`dimensionality_curve` for square texel blocks of half-widths ``halves``."""
    return dimensionality_curve(T, [grid_block(shape, center, h) for h in halves], energy)


def loglog_slope(sizes, dims) -> float:
    """Least-squares slope of ``log dims`` vs ``log sizes`` (points with dims == 0 ignored).

    Returns
    -------
    float
        NaN when fewer than two distinct usable sizes.
    """
    p = np.asarray(sizes, dtype=np.float64)
    n = np.asarray(dims, dtype=np.float64)
    ok = (p > 0) & (n > 0)
    if np.unique(p[ok]).size < 2:
        return float("nan")
    return float(np.polyfit(np.log(p[ok]), np.log(n[ok]), 1)[0])


def mu_from_slope(s: float, r: float = 2.0) -> float:
    """``mu = r^-s``: dimensionality ratio of a 1/r sub-patch."""
    if not r > 1:
        raise ValueError(f"r (sub-patches per split) must be > 1, got {r!r}")
    return float(r ** (-float(s)))


def split_gain(n, p, N, mu: float, r: float = 2.0):
    """Cost saved by splitting a patch into ``r`` parts (eq. 23):
    ``d = (1 - mu) n p + (1 - r mu) n N``; split when ``d > 0``."""
    return (1.0 - mu) * np.asarray(n, float) * np.asarray(p, float) \
        + (1.0 - r * mu) * np.asarray(n, float) * np.asarray(N, float)


def optimal_patch_size(N, mu: float, r: float = 2.0) -> float:
    """Optimal patch size ``p* = N (r mu - 1) / (1 - mu)`` (eq. 27).

    Returns 0.0 when ``r mu <= 1`` (linear regime: always split, down to the smallest patch)
    and ``inf`` when ``mu >= 1`` (never split).
    """
    if not mu > 0:
        raise ValueError(f"mu must be > 0, got {mu!r}")
    if not r > 1:
        raise ValueError(f"r must be > 1, got {r!r}")
    if N < 0:
        raise ValueError(f"N must be >= 0, got {N!r}")
    if mu >= 1.0:
        return float("inf")
    return max(0.0, float(N) * (r * mu - 1.0) / (1.0 - mu))


def recommended_clusters(n_vertices: int, p_star: float) -> int:
    """``round(V / p*)`` clipped to ``[1, V]`` (``p* = 0`` -> V, ``inf`` -> 1)."""
    V = int(n_vertices)
    if V < 1:
        raise ValueError(f"n_vertices must be >= 1, got {n_vertices}")
    if p_star <= 0:
        return V
    if not np.isfinite(p_star):
        return 1
    return int(min(max(round(V / p_star), 1), V))


def analyse(T, seeds, *, edges=None, grid_shape=None, sizes=None, halves=None,
            energy: float = PATCH_ENERGY, N: int | None = None, r: float = 2.0,
            min_size: int = 1, max_dims: int | None = None) -> dict:
    """Dimensionality report: curves around seeds, mean slope, mu, p*, cluster count.

    Parameters
    ----------
    T : array_like, shape (V, S)
    seeds : sequence
        Vertex indices (with ``edges``) or ``(row, col)`` texels (with ``grid_shape``).
    edges, sizes : mesh graph (E, 2) and patch sizes (vertices) for BFS patches.
    grid_shape, halves : ``(H, W)`` and block half-widths for texel blocks.
    energy : float
        Patch dimensionality threshold (default 99.95%).
    N : int, optional
        Global dimension; default :func:`.cpca.global_dimension`.
    r : float
        Sub-patches per split (2 for CPCA).
    min_size : int
        Only patches with at least this many vertices enter the slope fit (the paper's
        slopes are for large patches).
    max_dims : int, optional
        Patches with a dimensionality above this are left out of the fit too: near the
        dimensionality of the whole matrix (at most S) the curve saturates, which is a limit of
        the sampling, not of the transport's locality.

    Returns
    -------
    dict (JSON-safe)
        ``curves`` [{"seed", "sizes", "dims", "slope"}], ``slope`` (mean over seeds), ``mu``,
        ``N``, ``p_star``, ``recommended_clusters``.
    """
    from .cpca import global_dimension

    T = _transport(T)
    if (edges is None) == (grid_shape is None):
        raise ValueError("give exactly one of edges (mesh vertices) or grid_shape (texels)")
    curves = []
    for sd in seeds:
        if edges is not None:
            if sizes is None:
                raise ValueError("sizes are needed with edges")
            p, n = graph_dimensionality_curve(T, edges, int(sd), sizes, energy)
            seed_out = int(sd)
        else:
            if halves is None:
                raise ValueError("halves are needed with grid_shape")
            p, n = grid_dimensionality_curve(T, grid_shape, sd, halves, energy)
            seed_out = [int(sd[0]), int(sd[1])]
        keep = (p >= int(min_size)) & (n <= (np.inf if max_dims is None else int(max_dims)))
        curves.append({"seed": seed_out, "sizes": p.tolist(), "dims": n.tolist(),
                       "slope": loglog_slope(p[keep], n[keep])})
    slopes = [c["slope"] for c in curves if np.isfinite(c["slope"])]
    s = float(np.mean(slopes)) if slopes else float("nan")
    N = global_dimension(T) if N is None else int(N)
    out = {"curves": curves, "slope": s, "energy": float(energy), "r": float(r), "N": N}
    if np.isfinite(s):
        mu = mu_from_slope(s, r)
        ps = optimal_patch_size(N, mu, r)
        out.update(mu=mu, p_star=ps, recommended_clusters=recommended_clusters(T.shape[0], ps))
    else:
        out.update(mu=None, p_star=None, recommended_clusters=None)
    return out
