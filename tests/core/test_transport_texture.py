"""Direction-sampled transport textures: kernels, store, models (bpy-free, synthetic T)."""

import numpy as np
import pytest

from relightable_textures.lt_addon.transport import texture as tt
from relightable_textures.lt_addon.sphere.directions import hemisphere_fibonacci, parse_direction_spec
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el


def test_hemisphere_set_covers_the_upper_hemisphere():
    for p in (1.0, 1.5, 2.0):
        d = hemisphere_fibonacci(400, p)
        assert np.all(d.directions[:, 2] > 0)
        assert d.solid_angles.sum() == pytest.approx(2 * np.pi, rel=1e-12)
        # quadrature of cos over the hemisphere = pi (the flat-plane irradiance of L = 1)
        assert np.sum(d.directions[:, 2] * d.solid_angles) == pytest.approx(np.pi, rel=0.01)
    lo, hi = hemisphere_fibonacci(400, 1.0), hemisphere_fibonacci(400, 2.0)
    assert np.sum(hi.directions[:, 2] < 0.2) > 1.5 * np.sum(lo.directions[:, 2] < 0.2)
    assert parse_direction_spec("hemi:400:1.5").spec == "hemi:400:1.5"
    assert parse_direction_spec("hemi:64").size == 64
    with pytest.raises(ValueError, match="horizon power"):
        parse_direction_spec("hemi:64:9")


@pytest.mark.parametrize("kernel", tt.KERNELS)
def test_sun_weights_normalised_and_off_below_horizon(kernel):
    d = hemisphere_fibonacci(200, 1.5)
    for el in (2.0, 10.0, 45.0, 89.0):
        for a in (0.0, 2.0, 10.0, 30.0):
            idx, w = tt.sun_weights(d, direction_from_az_el(33.0, el), a, kernel)
            assert np.all(w >= 0) and w.sum() <= 1.0 + 1e-9
            if el - a / 2 > 1.0 or kernel == "gauss":
                # the part of a sun disc below the horizon is off (occluded by the ground)
                assert w.sum() == pytest.approx(1.0, abs=1e-9)
    idx, w = tt.sun_weights(d, direction_from_az_el(0.0, -5.0), 2.0, kernel)
    assert len(idx) == 0


def test_linear_kernel_is_exact_at_a_sample_direction_for_a_point_sun():
    d = hemisphere_fibonacci(300, 1.5)
    for s in (0, 17, 150, 299):
        idx, w = tt.sun_weights(d, d.directions[s], 0.0, "linear")
        full = np.zeros(d.size)
        full[idx] = w
        assert full[s] == pytest.approx(1.0, abs=1e-9)


def _store(tmp_path, T, dset, R):
    st = tt.TransportStore.create(str(tmp_path / "t.npy"), dset, R, {"object": "x"})
    for s in range(dset.size):
        st.write(s, T[s])
    st.finish().commit()
    return tt.TransportStore.open(str(tmp_path / "t.npy"))


def _synthetic(dset, R, seed=0):
    """A cosine-weighted, randomly occluded transport with some low-rank structure."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(R * R, 3)) * [0.3, 0.3, 0] + [0, 0, 1]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    cos = np.clip(dset.directions @ n.T, 0, None)
    vis = (rng.random((dset.size, R * R)) > 0.2)
    return (cos * vis / np.pi).astype(np.float16).astype(np.float32)


def test_store_round_trip_and_relight(tmp_path):
    d = hemisphere_fibonacci(64, 1.0)
    R = 8
    T = _synthetic(d, R)
    st = _store(tmp_path, T, d, R)
    assert st.array.shape == (64, 64) and st.array.dtype == np.float16
    assert not list(tmp_path.glob(".*tmp*"))
    np.testing.assert_array_equal(st.array, T.astype(np.float16))
    assert st.meta["object"] == "x" and st.directions.spec == "hemi:64"
    idx, w = tt.sun_weights(d, d.directions[5], 0.0, "linear")
    np.testing.assert_allclose(st.sun(d.directions[5]).ravel(), T[5], atol=1e-7)
    dense = np.zeros(64)
    dense[[3, 9]] = [0.25, 0.75]
    np.testing.assert_allclose(st.relight_dense(dense).ravel(), 0.25 * T[3] + 0.75 * T[9],
                               atol=1e-6)


def test_store_abort_leaves_nothing(tmp_path):
    d = hemisphere_fibonacci(8)
    st = tt.TransportStore.create(str(tmp_path / "t.npy"), d, 4)
    st.write(0, np.ones(16))
    st.abort()
    assert list(tmp_path.iterdir()) == []
    st = tt.TransportStore.create(str(tmp_path / "t.npy"), d, 4)
    for s in range(d.size):
        st.write(s, np.ones(16))
    reader = st.finish()                 # finished but not committed: still temporary
    assert reader.sun([0, 0, 1]).shape == (4, 4)
    assert not (tmp_path / "t.npy").exists()
    reader.abort()
    assert list(tmp_path.iterdir()) == []


def test_pca_and_block_pca_are_exact_at_full_rank(tmp_path):
    d = hemisphere_fibonacci(40, 1.5)
    R = 8
    T = _synthetic(d, R, seed=3)
    st = _store(tmp_path, T, d, R)
    idx, w = tt.sun_weights(d, direction_from_az_el(40.0, 25.0), 5.0, "linear")
    ref = st.relight(idx, w)
    pca = tt.fit_texture_pca(st, k=40)
    np.testing.assert_allclose(pca.relight(idx, w), ref, atol=2e-5)
    assert pca.residual < 1e-6
    blk = tt.fit_block_pca(st, block=4, tol=1e-7)
    np.testing.assert_allclose(blk.relight(idx, w), ref, atol=2e-5)
    # truncated: the reported residual is the Frobenius residual of T
    p8 = tt.fit_texture_pca(st, k=8)
    rec = p8.V.astype(np.float64) @ p8.U.astype(np.float64)
    Tf = st.array.astype(np.float64)
    assert np.linalg.norm(rec - Tf) / np.linalg.norm(Tf) == pytest.approx(p8.residual, rel=1e-4)
    assert tt.fit_texture_pca(st, tol=p8.residual + 1e-9).k <= 8


def test_model_files_round_trip_through_one_protocol(tmp_path):
    """Both PCA models save and load through ``kind`` (no isinstance dispatch); the reloaded
    model relights like the fitted one within the half-float storage of its eigen-textures
    (relative 2^-11 per value, so 1e-3 of the image's scale covers sums of a few dozen)."""
    d = hemisphere_fibonacci(40, 1.5)
    R = 8
    st = _store(tmp_path, _synthetic(d, R, seed=4), d, R)
    idx, w = tt.sun_weights(d, direction_from_az_el(120.0, 30.0), 5.0, "linear")
    for model in (tt.fit_texture_pca(st, k=6), tt.fit_block_pca(st, block=4, tol=0.05)):
        path = str(tmp_path / f"{model.kind}.npz")
        tt.save_model(path, model, d.spec)
        back = tt.load_model(path)
        assert type(back) is type(model) and back.summary(40) == model.summary(40)
        ref = model.relight(idx, w)
        np.testing.assert_allclose(back.relight(idx, w), ref, atol=1e-3 * np.abs(ref).max())
        assert str(np.load(path)["directions_spec"]) == d.spec
    assert tt.MODEL_KINDS["pca"].live_preview and not tt.MODEL_KINDS["blocks"].live_preview
    np.savez(str(tmp_path / "odd.npz"), kind=np.array("wavelet"))
    with pytest.raises(ValueError, match="unknown model kind 'wavelet'"):
        tt.load_model(str(tmp_path / "odd.npz"))


def test_coefficient_tables_match_direct_weights_at_texel_centres():
    d = hemisphere_fibonacci(120, 1.5)
    V = np.random.default_rng(1).normal(size=(120, 3))
    D = 16
    tab = tt.coefficient_tables(V, d, D, 4.0)
    xy = tt.disk_grid(D)
    from relightable_textures.lt_addon.sphere.hemisphere import disk_to_hemisphere
    i, j = 9, 7       # a texel well inside the disk
    w_dir = disk_to_hemisphere(xy[i, j][None])[0]
    idx, w = tt.sun_weights(d, w_dir, 4.0)
    np.testing.assert_allclose(tab[:, i, j], w @ V[idx], atol=1e-5)
    np.testing.assert_allclose(tt.table_lookup(tab, w_dir), tab[:, i, j], atol=1e-5)
    assert np.all(tt.table_lookup(tab, [1, 0, -0.1]) == 0)


def test_environment_weights_integrate_a_constant_sky():
    d = hemisphere_fibonacci(500, 1.0)
    env = np.ones((32, 64))
    w = tt.environment_weights(d, env, row_order="top_first", rotation_deg=30.0)
    assert w.sum() == pytest.approx(2 * np.pi, rel=1e-3)


def test_fit_streams_with_a_bounded_working_set(tmp_path, monkeypatch):
    """The PCA fit never holds T in memory: with 4 MiB chunks, the numpy memory it allocates
    (tracemalloc; the store's memmap is page cache, not allocations) peaks far below T's 32 MiB."""
    import tracemalloc

    d = hemisphere_fibonacci(256)
    R = 256
    st = tt.TransportStore.create(str(tmp_path / "big.npy"), d, R)
    rng = np.random.default_rng(0)
    base = rng.random((8, R * R)).astype(np.float32)
    for s in range(d.size):
        st.write(s, rng.random(8).astype(np.float32) @ base / (8 * np.pi))   # in [0, 1/pi]
    st.finish().commit()
    st = tt.TransportStore.open(str(tmp_path / "big.npy"))
    T_bytes = st.array.nbytes
    assert T_bytes == 32 * 2 ** 20
    monkeypatch.setattr(tt, "CHUNK_BYTES", 4 << 20)
    tracemalloc.start()
    try:
        model = tt.fit_texture_pca(st, k=8)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert model.residual < 1e-3          # rank 8 by construction (half-float rounding left)
    assert peak < 0.5 * T_bytes, peak / 2 ** 20


def test_smoothing_keeps_constants_and_ignores_uncovered_texels():
    rng = np.random.default_rng(2)
    cov = np.zeros((32, 32), bool)
    cov[4:20, 6:28] = True
    img = np.where(cov[..., None], 0.5, 9.0) * np.ones((32, 32, 3))
    out = tt.smooth_in_coverage(img, cov, 2.0)
    np.testing.assert_allclose(out[cov], 0.5, rtol=1e-6)        # no bleeding from outside
    np.testing.assert_array_equal(out[~cov], img[~cov])
    noisy = 0.5 + 0.1 * rng.normal(size=(32, 32, 3))
    sm = tt.smooth_in_coverage(noisy, cov, 1.5)
    assert np.std(sm[cov] - 0.5) < 0.35 * np.std(noisy[cov] - 0.5)
    assert np.mean(sm[cov]) == pytest.approx(np.mean(noisy[cov]), abs=0.01)
