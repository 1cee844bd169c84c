"""Patch dimensionality vs size and Mahajan 2007's cost formulas, against hand computations."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.transport import dimensionality as DM

FEW = settings(max_examples=25, deadline=None)


def _grid_edges(H, W):
    idx = np.arange(H * W).reshape(H, W)
    return np.vstack([np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()],
                      np.c_[idx[:-1].ravel(), idx[1:].ravel()]])


def test_bfs_order_is_graph_distance():
    H = W = 7
    order = DM.graph_patch_order(_grid_edges(H, W), H * W, 24)     # centre (3, 3)
    assert order[0] == 24 and order.size == 49
    y, x = np.divmod(order, W)
    dist = np.abs(y - 3) + np.abs(x - 3)                          # grid graph = L1 distance
    assert np.all(np.diff(dist) >= 0)
    # a disconnected vertex is not reached
    e = _grid_edges(H, W)
    order2 = DM.graph_patch_order(e, H * W + 1, 0)
    assert H * W not in order2


def test_grid_block_clips():
    b = DM.grid_block((10, 12), (0, 11), 2)
    y, x = np.divmod(b, 12)
    assert set(y) == {0, 1, 2} and set(x) == {9, 10, 11}
    assert DM.grid_block((5, 5), (2, 2), 0).tolist() == [12]
    with pytest.raises(ValueError, match="outside the grid"):
        DM.grid_block((5, 5), (5, 0), 1)


def test_identity_transport_has_slope_one():
    # every vertex its own light direction: patch dimensionality = patch size exactly
    V = 64
    T = np.eye(V)
    p, n = DM.graph_dimensionality_curve(T, _grid_edges(8, 8), 0, [1, 2, 4, 8, 16, 32, 64])
    assert n.tolist() == p.tolist()
    assert DM.loglog_slope(p, n) == pytest.approx(1.0)


def test_rows_depending_on_x_only_give_half_slope():
    # transport that depends only on the column: dims = block width = sqrt(area)
    H = W = 33
    xs = np.tile(np.arange(W), H)
    T = np.eye(W)[xs]
    p, n = DM.grid_dimensionality_curve(T, (H, W), (16, 16), [1, 2, 4, 8, 16])
    assert n.tolist() == [3, 5, 9, 17, 33]
    assert DM.loglog_slope(p, n) == pytest.approx(0.5, abs=0.01)


def test_patch_dimension_energy_by_hand():
    T = np.diag([3.0, 2.0, 1.0, 0.0])
    e = np.cumsum([9, 4, 1]) / 14
    assert DM.patch_dimension(T, 0.5) == 1
    assert DM.patch_dimension(T, e[1]) == 2
    assert DM.patch_dimension(T, 0.9995) == 3
    assert DM.patch_dimension(np.zeros((3, 3))) == 0


@FEW
@given(st.floats(0.05, 0.99), st.integers(1, 1000), st.floats(1, 5000), st.floats(1, 1e5))
def test_split_gain_is_cost_difference(mu, n, N, p):
    r = 2.0
    c = n * (p + N)                                 # eq. 19
    c_split = r * (mu * n) * (p / r + N)            # eq. 20 with sum n_j = r mu n
    assert DM.split_gain(n, p, N, mu, r) == pytest.approx(c - c_split, rel=1e-9, abs=1e-6)
    ps = DM.optimal_patch_size(N, mu, r)
    if r * mu > 1:
        assert DM.split_gain(n, ps, N, mu, r) == pytest.approx(0.0, abs=1e-6 * n * (ps + N))
        assert DM.split_gain(n, 2 * ps, N, mu, r) > 0 > DM.split_gain(n, ps / 2, N, mu, r)
    else:
        assert ps == 0.0


def test_paper_numbers():
    # sec. 4.3: mu = 0.68, r = 2, N = 150 -> p* = 150 * 0.36 / 0.32 = 168.75 (paper: ~170)
    assert DM.optimal_patch_size(150, 0.68) == pytest.approx(168.75)
    assert DM.mu_from_slope(1.0) == 0.5 and DM.mu_from_slope(0.5) == pytest.approx(2 ** -0.5)
    assert DM.mu_from_slope(0.5, r=4) == 0.5
    assert DM.optimal_patch_size(500, 1.0) == float("inf")
    assert DM.optimal_patch_size(500, 0.4) == 0.0
    assert DM.recommended_clusters(38000, 168.75) == 225        # paper: ~220
    assert DM.recommended_clusters(10, 0.0) == 10
    assert DM.recommended_clusters(10, float("inf")) == 1
    with pytest.raises(ValueError, match="mu must be > 0"):
        DM.optimal_patch_size(10, 0.0)


def test_analyse_report():
    H = W = 17
    xs = np.tile(np.arange(W), H)
    T = np.eye(W)[xs]
    rep = DM.analyse(T, [(8, 8), (4, 12)], grid_shape=(H, W), halves=[1, 2, 4], N=17)
    assert rep["slope"] == pytest.approx(0.5, abs=0.05)
    assert rep["mu"] == pytest.approx(2 ** -rep["slope"])
    assert rep["p_star"] == pytest.approx(DM.optimal_patch_size(17, rep["mu"]))
    rep2 = DM.analyse(np.eye(16), [0], edges=_grid_edges(4, 4), sizes=[1, 4, 16], N=16)
    # p* is 0 up to rounding (7e-15 on some CPUs' SIMD paths)
    assert rep2["slope"] == pytest.approx(1.0) and rep2["p_star"] == pytest.approx(0.0, abs=1e-9)
    assert rep2["recommended_clusters"] == 16
    with pytest.raises(ValueError, match="exactly one of edges"):
        DM.analyse(T, [0])
    with pytest.raises(ValueError, match=r"edges must have shape \(E, 2\)"):
        DM.graph_patch_order([1, 2, 3], 4, 0)


def test_saturated_points_are_left_out_of_the_slope_fit():
    """Rows e_(v mod 8) on a path graph: a BFS patch of p vertices has dimensionality
    min(p, 8), slope 1 until it saturates at S = 8. With max_dims = 4 the fit sees only the
    growing part (slope 1); without it the saturated points pull the slope down."""
    V = 64
    T = np.eye(8)[np.arange(V) % 8]
    edges = np.stack([np.arange(V - 1), np.arange(1, V)], 1)
    sizes = [2, 4, 8, 16, 32, 64]
    kept = DM.analyse(T, [0], edges=edges, sizes=sizes, N=8, max_dims=4)
    assert kept["curves"][0]["dims"] == [2, 4, 8, 8, 8, 8]
    assert kept["slope"] == pytest.approx(1.0)
    assert DM.analyse(T, [0], edges=edges, sizes=sizes, N=8)["slope"] < 0.5
