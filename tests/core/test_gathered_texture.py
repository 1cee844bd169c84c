"""The gathered indirect term as stored (bpy-free): relighting against the brute-force sum over
directions, its file, and its viewport twin against the same sums."""

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError

from relightable_textures.lt_addon.transport import gathered_texture as gt
from relightable_textures.lt_addon.transport import texture as tt
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el


@pytest.fixture
def term():
    dset = tt.parse_directions("hemi:64:1.5")
    rng = np.random.default_rng(3)
    k, R = 5, 6
    images = rng.normal(0.0, 1.0, (k, R, R, 3)).astype(np.float32)
    images[0] = np.abs(images[0]) + 2.0          # a positive mean image, as a bake's
    V = rng.normal(0.0, 0.2, (dset.size, k)).astype(np.float32)
    V[:, 0] = 1.0 + rng.random(dset.size)
    return gt.GatheredIndirect(images, V, dset, {"rays_per_point": 8})


def brute(term, weights):
    """sum_s w_s I_s with each direction's whole image I_s = V[s] @ images, then the clamp."""
    full = np.einsum("sj,jyxc->syxc", term.coefficients.astype(np.float64),
                     term.basis_images.astype(np.float64))
    return np.maximum(np.einsum("s,syxc->yxc", weights, full), 0.0)


@pytest.mark.parametrize("angle", [0.0, 4.0])
def test_a_sun_relights_with_the_direct_lights_own_weights(term, angle):
    for az, el in ((30.0, 10.0), (200.0, 60.0)):
        d = direction_from_az_el(az, el)
        idx, w = tt.sun_weights(term.directions, d, angle)
        dense = np.zeros(term.directions.size)
        np.add.at(dense, idx, w)
        np.testing.assert_allclose(term.relight(d, angle), brute(term, dense), rtol=1e-5,
                                   atol=1e-5)
    assert not term.relight(direction_from_az_el(10.0, -5.0)).any()     # below the horizon


def test_an_environment_is_the_weighted_sum_of_every_direction(term):
    w = np.random.default_rng(0).random(term.directions.size)
    np.testing.assert_allclose(term.relight_dense(w), brute(term, w), rtol=1e-5, atol=1e-5)
    G = np.repeat(w[:, None], 3, 1).T @ term.direction_matrix(term.directions)
    want = np.maximum(np.einsum("cj,jyxc->yxc", G, term.basis_images), 0.0)
    np.testing.assert_allclose(tt.steer_environment(term, term.direction_matrix(), w), want,
                               rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="64 directions, not"):
        term.direction_matrix(tt.parse_directions("hemi:100"))


def test_the_file_keeps_it_to_half_float_precision(term, tmp_path):
    path = str(tmp_path / "o_indirect.npz")
    assert term.save(path, "half") > 0
    back = gt.GatheredIndirect.load(path, term.directions)
    np.testing.assert_allclose(back.basis_images, term.basis_images, rtol=2 ** -10, atol=1e-6)
    np.testing.assert_array_equal(back.coefficients, term.coefficients)
    assert back.settings == {"rays_per_point": 8}
    with pytest.raises(ValueError, match=r"coefficients.*shape"):
        gt.GatheredIndirect.load(path, tt.parse_directions("hemi:100"))
    np.savez(str(tmp_path / "other.npz"), header=np.frombuffer(b'{"format": "x"}', np.uint8))
    with pytest.raises(InputError, match="not a gathered indirect term"):
        gt.GatheredIndirect.load(str(tmp_path / "other.npz"), term.directions)


def test_the_viewport_twin_reads_the_sums_at_its_table_texels(term):
    """At a light direction whose disk point is a table texel's centre, the bilinear lookup
    reads that texel alone: the twin equals the kernel sum of the disk-texel direction
    (coefficient_tables) exactly; tables hold ceil(k / 3) tiles, the last one padded."""
    from relightable_textures.lt_addon.sphere.hemisphere import disk_to_hemisphere

    D = 16
    images, tiles = gt.preview_arrays(term, 4.0, D)
    assert tiles.shape == (2, D, D, 3) and not tiles[1, ..., 2].any()
    tab = tt.coefficient_tables(term.coefficients, term.directions, D, 4.0)
    for i, j in ((8, 8), (5, 11)):
        xy = np.array([(j + 0.5) / D * 2 - 1, (i + 0.5) / D * 2 - 1])
        d = disk_to_hemisphere(xy[None])[0]
        want = np.maximum(np.einsum("j,jyxc->yxc", tab[:, i, j].astype(np.float64),
                                    term.basis_images.astype(np.float64)), 0.0)
        np.testing.assert_allclose(gt.viewport_relight(images, tiles, d), want, rtol=1e-5,
                                   atol=1e-5)
