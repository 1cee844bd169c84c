"""Cluster-count analysis on synthetic transport: cost curve, prediction, equal-error costs."""

import numpy as np
import pytest

from relightable_textures.lt_addon.transport import cluster_analysis as CA
from relightable_textures.lt_addon.transport import cpca as CP


def _strip(n_vertices=120, S=48, seed=0):
    """Vertices on a line, each lit by a cosine lobe about its own direction plus a shadow edge
    that sweeps along the line: low-dimensional locally, higher globally."""
    x = np.linspace(0, 1, n_vertices)[:, None]
    s = np.linspace(0, 1, S)[None, :]
    T = np.maximum(0.0, np.cos(3.0 * (s - x))) * (s > 0.5 * x)
    edges = np.stack([np.arange(n_vertices - 1), np.arange(1, n_vertices)], 1)
    return T + 1e-3 * np.random.default_rng(seed).random(T.shape), edges


def test_cost_at_error_interpolates_in_log_log_and_refuses_unreached_targets():
    errors, costs = [0.1, 0.01, 0.001], [10.0, 100.0, 1000.0]  # cost = 1 / error
    assert CA.cost_at_error(errors, costs, 0.01) == pytest.approx(100.0)
    assert CA.cost_at_error(errors, costs, 10 ** -2.5) == pytest.approx(10 ** 2.5, rel=1e-9)
    assert CA.cost_at_error(errors, costs, 1.0) == pytest.approx(10.0)   # cheapest meeting it
    assert CA.cost_at_error(errors, costs, 1e-4) is None
    # a dominated, more expensive point never raises the answer
    assert CA.cost_at_error(errors + [0.005], costs + [5000.0], 0.01) == pytest.approx(100.0)


def test_shading_error_is_zero_for_the_transport_and_relative_otherwise():
    rng = np.random.default_rng(1)
    T = rng.random((20, 6))
    L = rng.random((3, 6, 3))
    assert CA.shading_error(T, lambda lw: T @ lw, L) == 0.0
    assert CA.shading_error(T, lambda lw: 1.1 * (T @ lw), L) == pytest.approx(0.1)


def test_global_pca_curve_matches_a_one_cluster_cpca():
    T, _ = _strip()
    L = np.random.default_rng(2).random((2, T.shape[1], 3))
    rows = CA.global_pca_curve(T, L, N=10, ds=[3])
    m = CP.fit_cpca(T, 1, dims=3, N=10)
    assert rows[0]["cost_per_vertex"] == pytest.approx(m.cost_per_vertex())
    assert rows[0]["shading_error"] == pytest.approx(
        CA.shading_error(T, lambda lw: m.shade(lw, albedo=np.pi), L), rel=1e-9)


def test_analysis_finds_a_cost_minimum_below_global_pca_and_reports_the_prediction():
    T, edges = _strip()
    rep = CA.analyse_clusters(T, edges, tol=1e-3, n_seeds=4, counts=[1, 2, 4, 8, 16, 32])
    costs = {r["clusters"]: r["cost_per_vertex"] for r in rep["cost_curve"]}
    assert rep["global_pca"]["clusters"] == 1
    assert rep["optimum"]["cost_per_vertex"] == min(costs.values()) < costs[1]
    assert rep["adaptive"]["cost_per_vertex"] < costs[1]
    assert rep["dimensionality"]["slope"] > 0 and rep["predicted_clusters"] >= 1
    assert all(r["relative_rms_error"] <= np.sqrt(1e-3) + 1e-9 for r in rep["cost_curve"])


def test_counts_and_sizes_are_clipped_and_unique():
    assert CA.cluster_counts(5, extra=[3, 99, None]) == [1, 2, 3, 4, 5]
    assert CA.patch_sizes(3).tolist() == [3]
    with pytest.raises(ValueError):
        CA.patch_sizes(0)


def test_seeds_come_from_the_largest_component():
    edges = np.array([[0, 1], [1, 2], [2, 3], [5, 6]])
    assert CA.largest_component(edges, 8).tolist() == [0, 1, 2, 3]


def test_auto_cpca_starts_from_the_prediction_and_meets_the_tolerance():
    T, edges = _strip()
    m = CA.auto_cpca(T, edges, tol=1e-3, predicted=12)
    assert m.info["start_clusters"] == 12 and m.info["start_from"] == "predicted"
    assert m.info["ways"] == [2, 4] and m.cost() <= m.info["initial_cost"]
    assert m.info["relative_rms_error"] <= np.sqrt(1e-3) + 1e-9
    low = CA.auto_cpca(T, edges, tol=1e-3, predicted=3)
    assert low.info["start_clusters"] == 8 and low.info["start_from"] == "minimum"
    measured = CA.auto_cpca(T, edges, tol=1e-3)     # runs the dimensionality analysis itself
    assert measured.info["predicted_clusters"] >= 1
