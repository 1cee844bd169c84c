"""Sparse kernel tables and the 8-bit T atlas of the transport viewport (bpy-free, synthetic T).

Independent references: the kernel of :func:`texture.sun_weights` itself (brute force at each
table texel), a float64 relight of the unquantised T, and the bilinear factors of a GPU sampler
written out by hand."""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el, disk_to_hemisphere
from relightable_textures.lt_addon.transport import sparse_tables as sp
from relightable_textures.lt_addon.transport import texture as tt


@pytest.fixture(scope="module")
def dset():
    return parse_direction_spec("hemi:120:1.5")


def _smooth_T(dset, R=12, seed=0):
    """A T whose texels are clamped cosines of random normals (a Lambertian patch)."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(R * R, 3))
    n[:, 2] = np.abs(n[:, 2]) + 0.5
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.maximum(dset.directions @ n.T, 0.0) / np.pi        # (S, P), irradiance / pi


def test_point_sun_needs_three_taps_and_keeps_its_kernel_at_texel_centres(dset):
    idx, w, kept = sp.sparse_weight_tables(dset, 16, 0.0, "linear", 3)
    assert kept == pytest.approx(1.0, abs=1e-12)   # barycentric: at most three directions
    grid = tt.disk_grid(16)
    for i, j in ((8, 8), (3, 11), (12, 2)):
        d = disk_to_hemisphere(grid[i, j][None] * min(1.0, 0.999 / np.hypot(*grid[i, j])))[0]
        ii, ww = tt.sun_weights(dset, d, 0.0, "linear")
        got = dict(zip(idx[i, j].tolist(), w[i, j].tolist()))
        for s, x in zip(ii, ww):
            assert got[int(s)] == pytest.approx(x, abs=1e-6)
        # the bilinear lookup at that texel's centre is that texel alone
        ii2, ww2 = sp.sparse_weights_at(idx, w, d)
        assert dict(zip(ii2.tolist(), ww2.tolist())) == pytest.approx(
            {int(s): float(x) for s, x in zip(idx[i, j], w[i, j]) if x}, abs=1e-6)


def test_truncation_keeps_the_kernel_mass_and_reports_what_it_dropped(dset):
    _, w3, kept3 = sp.sparse_weight_tables(dset, 8, 20.0, "linear", 3)
    _, w6, kept6 = sp.sparse_weight_tables(dset, 8, 20.0, "linear", 6)
    assert kept3 < kept6 <= 1.0 and kept3 < 0.9     # a 20-degree disc spans many directions
    inside = np.hypot(*np.moveaxis(tt.disk_grid(8), -1, 0)) < 0.7
    assert np.allclose(w3.sum(-1)[inside], 1.0, atol=1e-6)
    assert np.allclose(w6.sum(-1)[inside], 1.0, atol=1e-6)
    with pytest.raises(ValueError, match="taps"):
        sp.sparse_weight_tables(dset, 8, 0.0, "linear", 4)


def test_corners_are_a_gpu_samplers_bilinear_factors():
    D = 16
    for az, el in ((10.0, 70.0), (200.0, 12.0), (300.0, 1.0)):
        c = sp.corners(D, direction_from_az_el(az, el))
        assert len(c) == 4 and sum(f for *_, f in c) == pytest.approx(1.0)
        assert all(0 <= r < D and 0 <= q < D and f >= -1e-12 for r, q, f in c)
    assert sp.corners(D, direction_from_az_el(0.0, -5.0)) == []


def test_quantised_atlas_relights_within_half_a_step_of_each_directions_maximum(dset):
    T = _smooth_T(dset)
    tiles, scales = sp.quantize_directions(T)
    assert tiles.dtype == np.uint8 and tiles.shape == (40, 12, 12, 3)
    assert np.allclose(scales, T.max(1))
    back = np.stack([tiles[s // 3, :, :, s % 3] for s in range(len(T))]).reshape(len(T), -1)
    step = back / 255.0 * scales[:, None] - T
    assert np.all(np.abs(step) <= scales[:, None] / 510.0 + 1e-15)
    # the twin's relight from the 8-bit tiles with scaled weights vs float64 T
    idx, w, _ = sp.sparse_weight_tables(dset, 32, 2.0, "linear", 3)
    ws = sp.scaled_weights(idx, w, scales)
    for az, el in ((37.0, 10.0), (161.0, 30.0), (59.0, 80.0)):
        d = direction_from_az_el(az, el)
        got = sp.viewport_relight(tiles, idx, ws, d, 1.0 / 255.0)
        ii, ww = sp.sparse_weights_at(idx, w, d)
        want = (ww @ T[ii]).reshape(12, 12)
        assert np.abs(got - want).max() <= scales.max() / 510.0 + 1e-12
        assert np.linalg.norm(got - want) / np.linalg.norm(want) < 4e-3
    with pytest.raises(ValueError, match="negative"):
        sp.quantize_directions(-T)


def test_all_zero_directions_keep_a_unit_scale(dset):
    T = _smooth_T(dset)
    T[5] = 0.0
    tiles, scales = sp.quantize_directions(T)
    assert scales[5] == 1.0 and not tiles[1, :, :, 2].any()


def test_auto_viewport_follows_the_atlas_memory():
    # 8-bit RGBA atlas: 400 directions at 256^2 are 37 MiB, 1600 at 512^2 are 556 MiB
    assert sp.atlas_layout_bytes(400, 256) == (3096, 3096 * 3096 * 4)
    assert sp.choose_viewport("auto", 400, 256)[0] == "transport"
    assert sp.choose_viewport("auto", 1600, 256)[0] == "transport"
    kind, why = sp.choose_viewport("auto", 1600, 512)
    assert kind == "blocks" and "556 MiB" in why and "512" in why
    # the budget decides: 600 MiB take T's 556 MiB atlas; 1 MiB hold no block viewport at 512^2
    assert sp.choose_viewport("auto", 1600, 512, budget_mib=600)[0] == "transport"
    kind, why = sp.choose_viewport("auto", 1600, 512, budget_mib=1)
    assert kind == "pca" and "over 1" in why
    with pytest.raises(ValueError, match="does not fit 1 MiB"):
        sp.choose_viewport("blocks", 1600, 512, budget_mib=1)
    assert sp.choose_viewport("blocks", 48, 16)[0] == "blocks"
    assert sp.choose_viewport("transport", 1600, 512)[0] == "transport"
    assert sp.choose_viewport("pca", 48, 16)[0] == "pca"
    with pytest.raises(ValueError, match="texels across"):
        sp.choose_viewport("transport", 20000, 512)
    with pytest.raises(ValueError, match="viewport must be"):
        sp.choose_viewport("fast", 48, 16)


def test_taps_grow_with_the_sun_until_they_hold_the_kernel(dset):
    idx, w, kept = sp.choose_taps(dset, 16, 0.0, "linear")
    assert idx.shape[-1] == 3 and kept == pytest.approx(1.0, abs=1e-12)
    taps = []
    for a in (2.0, 10.0, 20.0):
        idx, w, kept = sp.choose_taps(dset, 16, a, "linear")
        taps.append(idx.shape[-1])
        assert kept >= sp.MIN_KEPT or idx.shape[-1] == sp.TAPS[-1]
        # the choice is the fewest taps that hold MIN_KEPT: one fewer part would not
        if idx.shape[-1] > 3:
            assert sp.sparse_weight_tables(dset, 16, a, "linear", idx.shape[-1] - 3)[2] < \
                sp.MIN_KEPT
        # and equals the plain tables of that many taps
        same = sp.sparse_weight_tables(dset, 16, a, "linear", idx.shape[-1])
        assert np.array_equal(same[0], idx) and np.allclose(same[1], w)
    assert taps == sorted(taps) and taps[-1] > 3
