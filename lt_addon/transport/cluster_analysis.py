"""How many clusters a transport matrix needs: Mahajan et al. 2007's analysis on real data.

Three measurements of one transport ``T`` (V, S), all in Mahajan's cost unit (multiply-adds
per lighting, ``c = sum_i n_i (p_i + N)``, reported per vertex ``c / V``):

* the dimensionality of growing patches and its log-log slope, giving ``mu``, the optimal patch
  size ``p*`` and the predicted cluster count ``V / p*`` (:mod:`.dimensionality`);
* the measured cost of fixed-count CPCA over a range of counts (the cost curve, whose minimum
  should sit near the prediction), and of adaptive subdivision;
* for benchmarks, the cost each method needs to reach one *shading* error: every method's
  (shading error, cost) curve over a tolerance sweep, interpolated in log-log at the target.

The shading error is the relative RMS difference between a model's shading and the full
transport's, ``T Lw``, under a set of test lightings (default: sun-and-sky environments), so
methods are compared on what a user sees rather than on the tolerance they were given.
"""

from __future__ import annotations

import time

import numpy as np

from . import cpca as cp
from . import dimensionality as dim
from .eigentransport import _transport, fit_eigentransport

#: fixed cluster counts of the paper comparison (Mahajan 2007 sec. 6; 5000 clips to V)
PAPER_COUNTS = (10, 50, 5000)


def patch_sizes(n_vertices: int, count: int = 12, smallest: int = 4) -> np.ndarray:
    """Geometric patch sizes from ``smallest`` to V (unique ints), shape (<= count,)."""
    V = int(n_vertices)
    if V < 1:
        raise ValueError(f"n_vertices must be >= 1, got {n_vertices}")
    return np.unique(np.geomspace(min(smallest, V), V, count).astype(np.int64))


def largest_component(edges, n_vertices: int) -> np.ndarray:
    """Vertex indices (sorted) of the largest connected component of the mesh graph.

    Dimensionality curves are grown there: a seed on a small loose part would stop growing
    before the patch sizes that the slope is fitted on."""
    import scipy.sparse
    import scipy.sparse.csgraph

    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    A = scipy.sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])),
                                shape=(int(n_vertices),) * 2)
    _, comp = scipy.sparse.csgraph.connected_components(A, directed=False)
    return np.flatnonzero(comp == np.bincount(comp).argmax())


def cluster_counts(n_vertices: int, extra=(), count: int = 9, largest: int = 1024) -> list:
    """Geometric cluster counts 1 .. min(V, largest) plus ``extra`` (clipped to [1, V]),
    sorted and unique."""
    V = int(n_vertices)
    top = max(1, min(V, int(largest)))
    ks = set(np.unique(np.geomspace(1, top, count).astype(np.int64)).tolist())
    ks |= {int(min(max(int(k), 1), V)) for k in extra if k is not None}
    return sorted(ks)


def cost_curve(T, counts, tol: float, N: int, seed: int = 0, n_iter: int = 10,
               progress=None) -> list:
    """Fixed-count CPCA at every count.

    Parameters
    ----------
    T : array_like (V, S)
    counts : iterable of int in [1, V]
    tol : float in [0, 1]
        Per-cluster unexplained energy fraction (see :mod:`.cpca`).
    N : int
        Global dimension for the cost.
    progress : callable(str), optional

    Returns
    -------
    list of dict
        ``clusters_requested``, ``clusters``, ``cost_per_vertex``, ``relative_rms_error`` (of
        the transport), ``seconds``.
    """
    T = _transport(T)
    rows = []
    for k in counts:
        t0 = time.perf_counter()
        m = cp.fit_cpca(T, int(k), tol=tol, N=N, seed=seed, n_iter=n_iter)
        rows.append({"clusters_requested": int(k), "clusters": m.n_clusters,
                     "cost_per_vertex": m.cost_per_vertex(),
                     "relative_rms_error": m.info["relative_rms_error"],
                     "seconds": round(time.perf_counter() - t0, 3)})
        if progress:
            progress(f"CPCA {k} clusters: {rows[-1]['cost_per_vertex']:.1f} per vertex")
    return rows


def mesh_dimensionality(T, edges, N: int, n_seeds: int = 8, seed: int = 0) -> dict:
    """:func:`.dimensionality.analyse` on BFS patches around random vertices of the mesh's
    largest component, slopes fitted over the larger two thirds of the patch sizes (the
    paper's slopes are for large patches) and below half the whole matrix's dimensionality
    (where the curves saturate at the direction count). Adds ``whole_matrix_dims``."""
    T = _transport(T)
    component = largest_component(edges, T.shape[0])
    rng = np.random.default_rng(seed)
    seeds = np.sort(rng.choice(component, min(int(n_seeds), component.size), replace=False))
    sizes = patch_sizes(component.size)
    full = dim.patch_dimension(T)
    out = dim.analyse(T, seeds, edges=edges, sizes=sizes, N=N,
                      min_size=int(sizes[len(sizes) // 3]), max_dims=max(full // 2, 2))
    out["whole_matrix_dims"] = full
    return out


def analyse_clusters(T, edges, *, tol: float = 1e-3, n_seeds: int = 8, seed: int = 0,
                     counts=None, start_clusters: int = 8, progress=None) -> dict:
    """Dimensionality analysis, cost curve and adaptive CPCA of a per-vertex transport.

    Parameters
    ----------
    T : array_like (V, S)
    edges : array_like (E, 2) of int
        Mesh edges (patches grow by graph distance).
    tol : float
        CPCA per-cluster tolerance (1e-3 = the paper's 99.9%).
    n_seeds : int
        Random seed vertices for the dimensionality curves.
    counts : iterable of int, optional
        Cluster counts of the cost curve; default :func:`cluster_counts` plus the prediction.
    start_clusters : int
        Initial count of the adaptive subdivision (paper: 5-10).

    Returns
    -------
    dict (JSON-safe)
        ``vertices``, ``samples``, ``N``, ``tol``, ``dimensionality`` (:func:`.dimensionality.
        analyse` output), ``predicted_clusters``, ``cost_curve`` (rows), ``optimum`` (the
        cheapest row), ``global_pca`` (the one-cluster row), ``adaptive`` (the paper's: from
        ``start_clusters``, binary splits) and ``auto`` (:func:`auto_cpca`), each with
        clusters, cost per vertex, error, splits and seconds.
    """
    T = _transport(T)
    V, S = T.shape
    say = progress or (lambda _msg: None)
    N = cp.global_dimension(T, seed=seed)
    say(f"dimensionality around {n_seeds} vertices")
    report_dim = mesh_dimensionality(T, edges, N, n_seeds, seed)
    predicted = report_dim["recommended_clusters"]
    ks = cluster_counts(V, extra=[predicted]) if counts is None else list(counts)
    curve = cost_curve(T, ks, tol, N, seed=seed, progress=say)
    t0 = time.perf_counter()
    say(f"adaptive CPCA from {start_clusters} clusters")
    ad = cp.adaptive_cpca(T, start_clusters=start_clusters, tol=tol, seed=seed, N=N)
    t1 = time.perf_counter()
    say("adaptive CPCA from the predicted count (--clusters auto)")
    au = auto_cpca(T, edges, tol=tol, seed=seed, N=N, predicted=predicted)
    best = min(curve, key=lambda r: r["cost_per_vertex"])
    one = next((r for r in curve if r["clusters"] == 1), None)
    return {"vertices": V, "samples": S, "N": N, "tol": tol, "dimensionality": report_dim,
            "predicted_clusters": predicted, "cost_curve": curve, "optimum": best,
            "global_pca": one, "adaptive": _summary(ad, t1 - t0),
            "auto": _summary(au, time.perf_counter() - t1)}


def _summary(model, seconds: float) -> dict:
    return {"clusters": model.n_clusters, "start_clusters": model.info["start_clusters"],
            "cost_per_vertex": model.cost_per_vertex(),
            "relative_rms_error": model.info["relative_rms_error"],
            "splits_kept": model.info["splits_kept"], "splits_tried": model.info["splits_tried"],
            "seconds": round(seconds, 3)}


def auto_cpca(T, edges, tol: float = 1e-3, seed: int = 0, N: int | None = None,
              n_seeds: int = 8, min_start: int = 8, predicted: int | None = None):
    """``--clusters auto``: adaptive CPCA started from the cluster count the dimensionality
    analysis predicts (``V / p*``, at least ``min_start``), splitting in two or, when halving
    does not pay, in four.

    Measured at equal shading error (benchmarks/bench_cpca.py, docs/bench/cpca.json) this is
    22-24 % cheaper than the paper's start from 8 clusters with binary splits on the statue and
    3-6 % on the room: greedy halving from a few large clusters stops where a cluster's halves
    each still need most of its basis.

    Parameters
    ----------
    T : array_like (V, S)
    edges : array_like (E, 2) of int
        Mesh edges for the dimensionality patches.
    tol : float
        Per-cluster tolerance (see :mod:`.cpca`).
    predicted : int, optional
        The predicted count when already known (skips the dimensionality analysis).

    Returns
    -------
    CPCA
        ``info`` adds ``start_from`` ("predicted" or "minimum") and ``predicted_clusters``.
    """
    T = _transport(T)
    V = T.shape[0]
    N = cp.global_dimension(T, seed=seed) if N is None else int(N)
    if predicted is None:
        predicted = mesh_dimensionality(T, edges, N, n_seeds, seed)["recommended_clusters"]
    start = max(int(min_start), predicted or 0)
    model = cp.adaptive_cpca(T, start_clusters=min(start, V), tol=tol, seed=seed, N=N,
                             ways=(2, 4))
    model.info.update(start_from="predicted" if predicted and predicted >= min_start
                      else "minimum", predicted_clusters=predicted)
    return model


# ----------------------------------------------------------------------------------------------
# equal-error comparison


def shading_error(T, shade, lightings) -> float:
    """Relative RMS error of a model's shading vs the full transport's over test lightings.

    Parameters
    ----------
    T : ndarray (V, S)
        The full transport (reference).
    shade : callable(Lw (S, C)) -> (V, C)
        The model's plain product ``T_model Lw``.
    lightings : ndarray (L, S, C)
        Weighted lightings (radiance x solid angle).

    Returns
    -------
    float
        ``||B_model - B||_F / ||B||_F`` over all lightings, vertices and channels.
    """
    num = den = 0.0
    for lw in lightings:
        ref = T @ lw
        num += float(np.sum((shade(lw) - ref) ** 2))
        den += float(np.sum(ref ** 2))
    return float(np.sqrt(num / den)) if den > 0 else (0.0 if num == 0 else float("inf"))


def cost_at_error(errors, costs, target: float) -> float | None:
    """Cost at ``target`` shading error by log-log interpolation along a method's curve.

    Parameters
    ----------
    errors, costs : array_like (n,)
        One method's measured (error, cost) points, any order.
    target : float > 0

    Returns
    -------
    float or None
        Interpolated between the cheapest point meeting the target (error <= target) and, among
        the cheaper points that miss it, the most accurate one; the cheapest meeting point when
        no cheaper point exists; None when no point reaches the target in the range tried.
    """
    e = np.asarray(errors, dtype=np.float64)
    c = np.asarray(costs, dtype=np.float64)
    ok = np.isfinite(e) & np.isfinite(c) & (c > 0)
    e, c = e[ok], c[ok]
    below = e <= target
    if not below.any():
        return None
    c_below = float(c[below].min())
    above = (e > target) & (c < c_below)
    if not above.any():
        return c_below
    # the bracketing pair: the cheapest point meeting the target and, among the cheaper points
    # missing it, the most accurate one
    i_lo = int(np.flatnonzero(below)[np.argmin(c[below])])
    cand = np.flatnonzero(above)
    i_hi = int(cand[np.argmin(e[cand])])
    e0, e1 = max(e[i_lo], 1e-300), e[i_hi]
    if e1 <= e0:
        return c_below
    t = (np.log(target) - np.log(e0)) / (np.log(e1) - np.log(e0))
    return float(np.exp(np.log(c[i_lo]) + t * (np.log(c[i_hi]) - np.log(c[i_lo]))))


def global_pca_curve(T, lightings, N: int, ds=None) -> list:
    """Global PCA (one cluster, mean counted) at every d: shading error and Mahajan cost
    ``(d + 1)(V + N) / V`` per vertex. ``ds`` default: 1..min(V, S) geometric (~24 values)."""
    T = _transport(T)
    V, S = T.shape
    model = fit_eigentransport(T, d=min(V, S))
    if ds is None:
        ds = np.unique(np.geomspace(1, model.d, 24).astype(np.int64))
    rows = []
    for d in ds:
        m = model.truncate(int(d))
        rows.append({"d": int(d), "cost_per_vertex": (int(d) + 1) * (V + N) / V,
                     "shading_error": shading_error(T, lambda lw: m.shade(lw, albedo=np.pi),
                                                    lightings)})
    return rows


def method_curve(T, lightings, fit, tols) -> list:
    """(shading error, cost per vertex) of ``fit(tol) -> CPCA`` over a tolerance sweep."""
    rows = []
    for tol in tols:
        t0 = time.perf_counter()
        m = fit(float(tol))
        rows.append({"tol": float(tol), "clusters": m.n_clusters,
                     "cost_per_vertex": m.cost_per_vertex(),
                     "shading_error": shading_error(T, lambda lw: m.shade(lw, albedo=np.pi),
                                                    lightings),
                     "seconds": round(time.perf_counter() - t0, 3)})
    return rows
