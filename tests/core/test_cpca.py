"""CPCA (Sloan 2003) with Mahajan 2007's cost model: fits, exact shading, cost, adaptive
subdivision and degenerate input, checked against independent computations."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.transport import cpca as CP
from relightable_textures.lt_addon.transport import eigentransport as ET

FEW = settings(max_examples=10, deadline=None)


def _two_subspaces(V=120, S=40, seed=0):
    """Rows from two different rank-2 affine subspaces (a clustering problem with an answer)."""
    rng = np.random.default_rng(seed)
    a = rng.random((V // 2, 2)) @ rng.random((2, S)) + rng.random(S)
    b = rng.random((V - V // 2, 2)) @ rng.random((2, S)) + 3 * rng.random(S)
    return np.vstack([a, b])


def _decaying(V=200, S=50, seed=1):
    rng = np.random.default_rng(seed)
    return rng.random((V, S)) @ np.diag(np.linspace(1, 0, S) ** 3) + 0.1


def test_one_cluster_equals_global_pca():
    T = _decaying()
    for d in (0, 3, 10):
        m = CP.fit_cpca(T, 1, dims=d, N=7)
        ref = ET.fit_eigentransport(T, d=d)
        assert np.all(m.labels == 0)
        assert np.allclose(m.reconstruct(), ref.reconstruct(), atol=1e-12)
        assert np.allclose(m.clusters[0].mean, ref.mean)


def test_shading_exact_vs_brute_force():
    T = _decaying()
    rng = np.random.default_rng(3)
    m = CP.fit_cpca(T, 5, tol=1e-2, N=9)
    R = m.reconstruct()
    for lw in (rng.random(T.shape[1]), rng.random((T.shape[1], 3))):
        brute = R @ lw / np.pi
        assert np.max(np.abs(m.shade(lw) - brute)) <= 1e-10 * np.max(np.abs(brute))
        # per-cluster formula by hand: m_i . Lw + C[x] . (E_i Lw)
        hand = np.empty_like(brute)
        for i, c in enumerate(m.clusters):
            hand[m.labels == i] = c.mean @ lw + c.coefficients @ (c.basis @ lw)
        assert np.allclose(m.shade(lw, albedo=np.pi), hand, rtol=0, atol=1e-12)


def test_recovers_two_subspaces_exactly():
    T = _two_subspaces()
    m = CP.fit_cpca(T, 2, dims=2, N=5)
    assert set(m.labels[:60]) != set(m.labels[60:])
    assert len(set(m.labels[:60])) == 1 and len(set(m.labels[60:])) == 1
    assert ET.relative_rms_error(T, m.reconstruct()) < 1e-10


def test_cost_formula_by_hand():
    T = _two_subspaces(V=10, S=6)
    m = CP.fit_cpca(T, 2, dims=2, N=4, labels=[0] * 5 + [1] * 5)
    # each cluster: mean (non-zero) + 2 basis vectors = 3, p = 5, N = 4
    assert m.dims().tolist() == [3, 3]
    assert m.cost() == 3 * (5 + 4) + 3 * (5 + 4) == 54
    assert m.cost(count_mean=False) == 2 * 9 * 2
    assert m.cost_per_vertex() == pytest.approx(5.4)


@FEW
@given(st.floats(1e-4, 0.5), st.integers(1, 6), st.integers(0, 10))
def test_tolerance_is_honoured(tol, k, seed):
    T = _decaying(V=60, S=20, seed=seed)
    m = CP.fit_cpca(T, k, tol=tol, N=5, seed=seed)
    for i, c in enumerate(m.clusters):
        Ti = T[m.labels == i]
        resid = np.sum((Ti - c.reconstruct()) ** 2)
        assert resid <= tol * np.sum(Ti ** 2) * (1 + 1e-9) + 1e-12
        if c.d:   # one fewer component would break the tolerance
            fewer = c.truncate(c.d - 1)
            assert np.sum((Ti - fewer.reconstruct()) ** 2) > tol * np.sum(Ti ** 2)
    assert ET.relative_rms_error(T, m.reconstruct()) <= np.sqrt(tol) + 1e-12


def test_tol_extremes():
    T = _decaying(V=50, S=12)
    exact = CP.fit_cpca(T, 3, tol=0.0, N=4)
    assert ET.relative_rms_error(T, exact.reconstruct()) < 1e-10
    means = CP.fit_cpca(T, 3, tol=1.0, N=4)
    assert all(c.d == 0 for c in means.clusters)
    for i, c in enumerate(means.clusters):
        assert np.allclose(means.reconstruct()[means.labels == i], T[means.labels == i].mean(0))


def test_global_dimension_by_hand():
    rng = np.random.default_rng(0)
    U, _ = np.linalg.qr(rng.standard_normal((30, 30)))
    W, _ = np.linalg.qr(rng.standard_normal((20, 20)))
    s = np.array([10.0, 3.0, 1.0, 0.1] + [0.0] * 16)
    T = U[:, :20] @ np.diag(s) @ W
    e = np.cumsum(s ** 2) / np.sum(s ** 2)
    for energy in (0.5, 0.9, 0.99, 0.999, 0.99999, 1.0):
        assert CP.global_dimension(T, energy, subset=None) == int(np.argmax(e >= energy - 1e-12)) + 1
    assert CP.global_dimension(np.zeros((5, 4))) == 0
    assert CP.global_dimension(T, 0.999, subset=25, seed=1) <= 4


def test_assignment_never_worse_than_kmeans_start():
    T = _decaying(V=150, S=30, seed=4)
    start = CP.fit_cpca(T, 6, dims=2, n_iter=0, N=5, seed=2)
    fitted = CP.fit_cpca(T, 6, dims=2, n_iter=10, N=5, seed=2)
    e0 = ET.relative_rms_error(T, start.reconstruct())
    e1 = ET.relative_rms_error(T, fitted.reconstruct())
    assert e1 <= e0 + 1e-12


def test_arrays_round_trip():
    T = _decaying(V=80, S=16)
    m = CP.fit_cpca(T, 4, tol=1e-2, N=6)
    arrays = m.to_arrays()
    assert all(np.asarray(v).dtype != object for v in arrays.values())
    back = CP.CPCA.from_arrays(arrays)
    assert np.array_equal(back.labels, m.labels) and back.N == 6
    assert back.dims().tolist() == m.dims().tolist()
    assert np.allclose(back.reconstruct(), m.reconstruct(), atol=1e-5)
    lw = np.linspace(0, 1, 16)
    assert np.allclose(back.shade(lw), m.shade(lw), atol=1e-5)
    with pytest.raises(ValueError, match="not a CPCA sidecar"):
        CP.CPCA.from_arrays({"metadata": np.array('{"format": "x"}')})


@FEW
@given(st.integers(0, 20), st.integers(1, 5))
def test_adaptive_never_increases_cost(seed, k):
    T = _decaying(V=90, S=24, seed=seed)
    m = CP.adaptive_cpca(T, start_clusters=k, tol=1e-3, N=8, seed=seed, n_iter=3)
    assert m.info["cost"] <= m.info["initial_cost"]
    assert m.cost() == pytest.approx(m.info["cost"])
    assert ET.relative_rms_error(T, m.reconstruct()) <= np.sqrt(1e-3) + 1e-12
    tree = m.info["tree"]
    leaves = [n for n in tree if n["leaf"] is not None]
    assert len(leaves) == m.n_clusters
    assert sum(n["size"] for n in leaves) == T.shape[0]
    for n in tree:
        if n["split"]:
            assert n["split_cost"] < n["cost"] and len(n["children"]) == 2
            assert sum(tree[c]["size"] for c in n["children"]) == n["size"]


def test_adaptive_splits_a_mixture_and_stops():
    # 4 different rank-1 groups: 1 start cluster must split (cost falls) down to ~4 leaves
    rng = np.random.default_rng(0)
    S = 200
    T = np.vstack([rng.random((50, 1)) @ rng.random((1, S)) + rng.random(S) for _ in range(4)])
    m = CP.adaptive_cpca(T, start_clusters=1, tol=1e-9, N=20)
    assert m.info["splits_kept"] >= 3
    assert m.n_clusters <= 8
    assert m.cost() < m.info["initial_cost"]


def test_degenerate_inputs():
    T = _decaying(V=5, S=4)
    with pytest.raises(ValueError, match="exceeds the number of vertices"):
        CP.fit_cpca(T, 6, tol=0.1)
    with pytest.raises(ValueError, match="exactly one of tol"):
        CP.fit_cpca(T, 2)
    with pytest.raises(ValueError, match="exactly one of tol"):
        CP.fit_cpca(T, 2, tol=0.1, dims=1)
    with pytest.raises(ValueError, match=r"tol must lie in \[0, 1\]"):
        CP.fit_cpca(T, 2, tol=1.5)
    with pytest.raises(ValueError, match="n_clusters must be a positive integer"):
        CP.fit_cpca(T, 0, tol=0.1)
    with pytest.raises(ValueError, match="non-finite"):
        CP.fit_cpca(np.full((3, 3), np.nan), 1, tol=0.1)
    # identical rows: k-means finds one cluster; empty ones are dropped and recorded
    same = np.tile(np.arange(6.0), (10, 1))
    m = CP.fit_cpca(same, 4, tol=1e-3)
    assert m.n_clusters == 1 and m.info["empty_dropped"] == 3
    assert m.N == 1 and m.dims().tolist() == [1]          # the mean only
    assert np.allclose(m.reconstruct(), same)
    # zero energy: N = 0, zero cost, shading 0
    z = CP.fit_cpca(np.zeros((8, 5)), 2, tol=1e-3)
    assert z.N == 0 and z.cost() == 0.0 and np.all(z.shade(np.ones(5)) == 0)
    za = CP.adaptive_cpca(np.zeros((8, 5)), start_clusters=3, tol=1e-3)
    assert za.cost() == 0.0 and za.info["splits_kept"] == 0
    # one vertex per cluster is allowed
    one = CP.fit_cpca(T, 5, dims=3, N=2)
    assert one.n_clusters == 5 and np.allclose(one.reconstruct(), T)
    # adaptive with more start clusters than vertices clips to V
    a = CP.adaptive_cpca(T, start_clusters=50, tol=1e-3)
    assert a.n_clusters <= 5


@pytest.mark.parametrize("shape", [(30, 7), (7, 30), (1, 5), (12, 12)])
def test_gram_singular_values_match_svd(shape):
    X = np.random.default_rng(2).standard_normal(shape)
    import scipy.linalg
    ref = scipy.linalg.svdvals(X)
    assert np.allclose(CP.singular_values(X)[:ref.size], ref, rtol=1e-9, atol=1e-12)


@FEW
@given(st.integers(2, 40), st.integers(1, 12), st.integers(1, 6), st.integers(0, 99),
       st.booleans())
def test_shading_property(V, S, k, seed, use_tol):
    rng = np.random.default_rng(seed)
    T = rng.random((V, S)) ** 3
    k = min(k, V)
    m = (CP.fit_cpca(T, k, tol=0.05, N=3, seed=seed) if use_tol
         else CP.fit_cpca(T, k, dims=1, N=3, seed=seed))
    lw = rng.random((S, 3))
    albedo = rng.random((1, 3))  # one per channel, explicit (a (3,) albedo is ambiguous at V = 3)
    ref = m.reconstruct() @ lw * albedo / np.pi
    assert np.allclose(m.shade(lw, albedo), ref, rtol=1e-10, atol=1e-12)
    for i in range(m.n_clusters):
        assert np.array_equal(m.members(i), np.flatnonzero(m.labels == i))


@pytest.mark.parametrize("T", [np.zeros((6, 4)), np.random.default_rng(0).random((9, 4))])
def test_npz_round_trip_means_only(T, tmp_path):
    # clusters with no basis vectors (zero transport, tol = 1) must survive an .npz file
    m = CP.fit_cpca(T, 3, tol=1.0)
    np.savez(tmp_path / "c.npz", **m.to_arrays())
    back = CP.CPCA.from_arrays(np.load(tmp_path / "c.npz", allow_pickle=False))
    assert np.allclose(back.reconstruct(), m.reconstruct(), atol=1e-6)
    assert back.cost() == m.cost()


# -- runtime helpers: local lights, storage, sidecar dispatch, cluster colours -------------------


def test_shade_local_equals_per_vertex_dot_products_of_the_reconstruction():
    rng = np.random.default_rng(5)
    T = rng.random((40, 12))
    m = CP.fit_cpca(T, 4, dims=3, N=6)
    W = rng.random((40, 12))
    expected = np.einsum("vs,vs->v", m.reconstruct(), W) / np.pi * 0.5
    np.testing.assert_allclose(m.shade_local(W, albedo=0.5), expected, rtol=1e-12, atol=1e-14)
    import scipy.sparse

    np.testing.assert_allclose(m.shade_local(scipy.sparse.csr_matrix(W), albedo=0.5), expected,
                               rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match=r"shape \(40, 12\)"):
        m.shade_local(W[:, :5])


def test_storage_bytes_count_the_stored_arrays():
    rng = np.random.default_rng(6)
    T = rng.random((30, 8))
    m = CP.fit_cpca(T, 3, dims=2, N=4)
    b = m.storage_bytes()
    arrays = m.to_arrays()
    assert b["coefficients"] == arrays["coefficients"].nbytes
    assert b["basis"] == arrays["basis"].nbytes
    assert b["mean"] == arrays["mean"].nbytes
    assert b["labels"] == arrays["labels"].nbytes
    assert b["coefficients_packed"] == 4 * 30 * 2
    assert b["runtime"] == 4 * sum(2 * (p + 1) for p in m.sizes())


def test_model_from_arrays_dispatches_on_the_format():
    from relightable_textures.lt_addon.transport.eigentransport import Eigentransport, fit_eigentransport

    T = np.random.default_rng(7).random((20, 6))
    assert isinstance(CP.model_from_arrays(CP.fit_cpca(T, 2, dims=1, N=3).to_arrays()), CP.CPCA)
    assert isinstance(CP.model_from_arrays(fit_eigentransport(T, d=2).to_arrays()),
                      Eigentransport)
    with pytest.raises(ValueError, match="no 'metadata'"):
        CP.model_from_arrays({})


def test_cluster_colors_are_deterministic_distinct_and_in_range():
    c = CP.cluster_colors(np.arange(64))
    assert c.shape == (64, 3) and c.min() >= 0.0 and c.max() <= 1.0
    np.testing.assert_array_equal(CP.cluster_colors([5, 5, 2]), c[[5, 5, 2]])
    # every pair of the first 64 labels differs visibly: >= 0.045 in some display (sRGB-ish)
    # channel, i.e. >= 11 of 255 levels
    d = c ** (1 / 2.2)
    diff = np.abs(d[:, None, :] - d[None, :, :]).max(axis=2) + np.eye(64)
    assert diff.min() >= 0.045
    with pytest.raises(ValueError):
        CP.cluster_colors([-1])


def test_one_cluster_per_vertex_is_exact_and_merges_identical_rows():
    rng = np.random.default_rng(8)
    T = rng.random((12, 5))
    T[7] = T[3]                                        # two identical rows: one cluster
    m = CP.fit_cpca(T, 12, tol=1e-3, N=4)
    assert m.n_clusters == 11 and m.info["empty_dropped"] == 1
    assert m.labels[7] == m.labels[3]
    np.testing.assert_allclose(m.reconstruct(), T, rtol=0, atol=1e-12)
    assert m.cost() == 11 * 4 + 12                     # n_i = 1 (the mean): sum (p_i + N)


def test_adaptive_lookahead_never_costs_more_than_its_start_and_records_the_arities():
    rng = np.random.default_rng(11)
    T = np.concatenate([np.outer(rng.random(15), rng.random(10)) + 0.01 * rng.random((15, 10))
                        for _ in range(6)])
    binary = CP.adaptive_cpca(T, start_clusters=2, tol=1e-3, N=6, seed=1)
    look = CP.adaptive_cpca(T, start_clusters=2, tol=1e-3, N=6, seed=1, ways=(2, 4))
    assert look.info["ways"] == [2, 4] and binary.info["ways"] == [2]
    for m in (binary, look):
        assert m.cost() <= m.info["initial_cost"]
        assert m.info["relative_rms_error"] <= np.sqrt(1e-3) + 1e-12
    with pytest.raises(ValueError, match="arities >= 2"):
        CP.adaptive_cpca(T, ways=(1,))


def test_batched_assignment_errors_equal_the_centred_projection_per_cluster():
    """_assignment_errors expands ||x - m||^2 - ||E (x - m)||^2 into two matrix products for
    all clusters; it must agree with the direct per-cluster computation to rounding at the
    scale of ||x||^2, including clusters with no basis vectors (mean only)."""
    rng = np.random.default_rng(7)
    T = np.maximum(rng.normal(size=(300, 5)) @ rng.normal(size=(5, 48)), 0.0) + 0.3
    model = CP.fit_cpca(T, 9, tol=1e-2, n_iter=0)
    clusters = list(model.clusters) + [model.clusters[0].truncate(0)]   # a mean-only cluster
    got = CP._assignment_errors(T, clusters)
    for j, c in enumerate(clusters):
        Y = T - c.mean
        P = Y @ c.basis.T
        want = np.sum(Y * Y, axis=1) - np.sum(P * P, axis=1)
        np.testing.assert_allclose(got[:, j], want, rtol=0,
                                   atol=1e-12 * np.max(np.sum(T * T, axis=1)))


def test_kmeans_returns_a_lloyd_fixed_point_with_every_label_used():
    """After convergence every row is nearest to the mean of its own cluster (the centroid
    update is batched; this checks it against the definition)."""
    rng = np.random.default_rng(2)
    X = np.concatenate([rng.normal(loc=c, scale=0.3, size=(50, 4)) for c in (0.0, 3.0, 6.0)])
    labels = CP.kmeans(X, 3, n_iter=50, seed=1)
    assert sorted(np.unique(labels)) == [0, 1, 2]
    means = np.stack([X[labels == j].mean(axis=0) for j in range(3)])
    d = ((X[:, None, :] - means[None]) ** 2).sum(axis=2)
    assert np.array_equal(d.argmin(axis=1), labels)
