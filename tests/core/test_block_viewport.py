"""The block (CPCA) viewport: fit, cell layout, tables and the node group's NumPy twin, against
brute-force relights of a synthetic T (bpy-free)."""

import numpy as np
import pytest

from relightable_textures.lt_addon.transport import block_viewport as bv
from relightable_textures.lt_addon.transport import texture as tt
from relightable_textures.lt_addon.sphere.directions import hemisphere_fibonacci
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el, disk_to_hemisphere

from test_transport_texture import _store


def rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _shadowed(dset, R, seed=0):
    """A plane under random box-shaped casters: cos * binary visibility, so T has cast shadows
    that move with the light (full rank over the texture, low rank in small blocks)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:R, 0:R] + 0.5
    T = np.repeat(dset.directions[:, 2:3], R * R, 1) / np.pi
    for _ in range(4):
        cx, cy, h = rng.uniform(0, R), rng.uniform(0, R), rng.uniform(0.5, 2.0)
        for s, d in enumerate(dset.directions):
            t = h / max(d[2], 0.05)            # shadow offset of a caster of height h
            sx, sy = x + d[0] * t, y + d[1] * t
            T[s][((np.abs(sx - cx) < 1.5) & (np.abs(sy - cy) < 1.5)).ravel()] = 0.0
    return T.reshape(dset.size, R, R).astype(np.float32)


@pytest.fixture
def store(tmp_path):
    dset = hemisphere_fibonacci(48, 1.5)
    return _store(tmp_path, _shadowed(dset, 16), dset, 16)


def test_exact_at_full_rank_per_block(store):
    """Every block keeps its full rank (4 x 4 texels: 16 <= 48 directions): the relight equals
    T's own to the loadings' half-float precision (2^-11 relative per value; the GPU's tables
    are half floats too), and the exact SVD is the one used."""
    view = bv.fit(store, block=4, k=16)
    assert view.method == "exact" and view.residual < 1e-6
    for az, el, a in ((30, 20, 0.0), (200, 65, 3.0), (111, 6, 2.0)):
        idx, w = tt.sun_weights(store.directions, direction_from_az_el(az, el), a)
        assert rel(view.relight_weights(idx, w), store.relight(idx, w)) < 1e-3


def test_rings_hold_the_neighbours_in_each_blocks_basis(store):
    view = bv.fit(store, block=8, k=6)
    T = np.asarray(store.array, np.float64).reshape(-1, 16, 16)
    src = bv.cell_sources(16, 8)
    assert list(src[:10]) == [0, 0, 1, 2, 3, 4, 5, 6, 7, 8]      # cell 0: ring clamped, then 8
    assert list(src[10:20]) == [7, 8, 9, 10, 11, 12, 13, 14, 15, 15]
    # block (by=1, bx=0): its ring row below is texel row 7, projected on that block's basis
    b = 1 * 2 + 0
    ring = T[:, 7, :][:, src[:10]]                                 # (S, 10)
    want = view.V[b].astype(np.float64).T @ ring
    np.testing.assert_allclose(view.eigen[:, 10, :10], want, rtol=2e-3, atol=2e-4)
    np.testing.assert_array_equal(bv.cell_interior(bv.to_cells(T[0], 8)[None], 8)[0], T[0])


def test_randomised_fit_is_close_to_the_exact_svd_and_reports_its_residual(tmp_path):
    """16 x 16 blocks (256 texels, 96 directions) at 6 components: the range finder's residual is
    within 2 % of the exact SVD's, and the residual it reports is the model's true error."""
    dset = hemisphere_fibonacci(96, 1.5)
    st = _store(tmp_path, _shadowed(dset, 32, seed=3), dset, 32)
    exact = bv.fit(st, block=16, k=6, oversample=200)
    fast = bv.fit(st, block=16, k=6)
    assert exact.method == "exact" and fast.method.startswith("randomised")
    assert exact.residual <= fast.residual <= 1.02 * exact.residual
    T = np.asarray(st.array, np.float64)
    E = bv.cell_interior(fast.eigen, 16).reshape(6, -1)           # (K, P)
    recon = np.zeros_like(T)
    for by in range(2):
        for bx in range(2):
            m = np.zeros((32, 32), bool)
            m[by * 16:(by + 1) * 16, bx * 16:(bx + 1) * 16] = True
            recon[:, m.ravel()] = fast.V[by * 2 + bx].astype(np.float64) @ E[:, m.ravel()]
    assert rel(recon, T) == pytest.approx(fast.residual, rel=1e-3)
    # a tolerance keeps fewer components where a block is simple, never more than k
    tol = bv.fit(st, block=16, k=12, tol=0.2)
    assert tol.dims.max() <= 12 and tol.dims.min() < 12 and tol.residual <= 0.2


def test_twin_at_a_table_texel_centre_is_the_kernel_relight(store):
    """The tables sampled at a disk texel centre hold the sun kernel applied to every block's
    loadings; the twin there equals the model's relight times the albedo, and below the
    horizon it is black."""
    view = bv.fit(store, block=4, k=16)
    D = 16
    tab = bv.tables(view, store.directions, D, 3.0)
    assert tab.shape == (16, 4 * D, 4 * D)
    rng = np.random.default_rng(1)
    albedo = rng.uniform(0.2, 0.9, (16, 16, 3))
    d = disk_to_hemisphere(tt.disk_grid(D)[11, 5][None])[0]
    idx, w = tt.sun_weights(store.directions, d, 3.0)
    want = store.relight(idx, w)[..., None] * albedo
    got = bv.viewport_relight(view.eigen, tab, bv.to_cells(albedo, 4), d, 4, 16, D)
    assert rel(got, want) < 1e-3
    assert np.all(bv.viewport_relight(view.eigen, tab, bv.to_cells(albedo, 4),
                                      [0.3, 0.2, -0.1], 4, 16, D) == 0)
    # the coefficients agree with the global tables of each block's loadings
    b = 5
    ref = tt.coefficient_tables(view.V[b], store.directions, D, 3.0)
    np.testing.assert_allclose(tab[:, 1 * D:2 * D, 1 * D:2 * D], ref, rtol=1e-5, atol=1e-6)


def test_budget_sets_the_components():
    g = bv.gpu_bytes(2048, 64, 12, 32)
    # eigen: 4 + 1 tiles of 32 * 66 = 2112 texels in a 3 x 2 grid with borders
    assert g["eigen_bytes"] == 3 * 2114 * 2 * 2114 * 8
    assert g["table_bytes"] == 2 * 1026 * 2 * 1026 * 8
    k = bv.largest_k(2048, 64, 32, 512 << 20)
    assert k % 3 == 0 and bv.gpu_bytes(2048, 64, k, 32)["total_bytes"] <= 512 << 20
    assert bv.gpu_bytes(2048, 64, k + 3, 32)["total_bytes"] > 512 << 20
    assert bv.largest_k(2048, 64, 32, 1 << 20) == 0
    assert bv.lookups_per_pixel(12) == 9


def test_table_weights_are_the_tables_bilinear_lookup(store):
    """Sparse weights standing for a bilinear table lookup: the global tables and the block
    tables read at any light equal the loadings under those weights (what the bench uses to
    score what the viewport shows without tabulating it)."""
    view = bv.fit(store, block=4, k=16)
    D = 16
    tab = bv.tables(view, store.directions, D, 2.0)
    for az, el in ((37, 10), (161, 30), (283, 55), (59, 80)):
        d = direction_from_az_el(az, el)
        idx, w = tt.table_weights(store.directions, d, D, 2.0)
        np.testing.assert_allclose(bv.table_coefficients(tab, d, D).transpose(1, 2, 0)
                                   .reshape(-1, 16),
                                   np.einsum("s,bsk->bk", w, view.V[:, idx].astype(np.float64)),
                                   rtol=1e-4, atol=1e-6)
        gt = tt.coefficient_tables(view.V[3], store.directions, D, 2.0)
        np.testing.assert_allclose(tt.table_lookup(gt, d), w @ view.V[3][idx], rtol=1e-4,
                                   atol=1e-6)
    assert len(tt.table_weights(store.directions, [1, 0, -0.2], D)[0]) == 0


def test_the_file_keeps_no_loadings_and_they_come_back_from_T(store, tmp_path):
    """The loadings are T's projection on the eigen images: recovered from the store they relight
    as the fitted ones to the eigen images' half-float precision; the file is the eigen images
    and figures only, and refuses another T."""
    view = bv.fit(store, block=4, k=6)
    path = str(tmp_path / "v.npz")
    bv.save(path, view)
    back = bv.load(path, store)
    assert back.k == 6 and back.block == 4 and np.array_equal(back.dims, view.dims)
    import zipfile

    assert "V.npy" not in zipfile.ZipFile(path).namelist()
    for az, el in ((37, 10), (283, 55)):
        idx, w = tt.sun_weights(store.directions, direction_from_az_el(az, el), 2.0)
        assert rel(back.relight_weights(idx, w), view.relight_weights(idx, w)) < 2e-3
    other = _store(tmp_path / "o", _shadowed(hemisphere_fibonacci(40, 1.5), 16),
                   hemisphere_fibonacci(40, 1.5), 16) if (tmp_path / "o").mkdir() is None else None
    with pytest.raises(ValueError, match="another T"):
        bv.load(path, other)
