"""SteerableTexture: relighting math and EXR round trips per storage mode (no bpy)."""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.hemisphere import disk_to_hemisphere, direction_from_az_el
from relightable_textures.lt_addon.steerable.basis import steering_coefficients
from relightable_textures.lt_addon.steerable.texture import (
    SteerableTexture,
    build_from_sampled_bakes,
)


@pytest.fixture(scope="module")
def texture():
    rng = np.random.default_rng(0)
    stack = rng.uniform(0.0, 1.0, size=(25, 6, 6, 3)).astype(np.float32)
    return stack, build_from_sampled_bakes(stack, order=5, frame="tangent")


def test_sampled_light_reproduces_its_own_bake(texture):
    """Steering to a baked centre gives back that bake (the solve inverts C exactly)."""
    stack, tex = texture
    inside = [k for k, c in enumerate(tex.centres) if np.hypot(*c) < 0.95]
    assert len(inside) >= 9
    for k in inside:
        d = disk_to_hemisphere(tex.centres[k])
        c, gain = tex.steering_weights(d)
        got = tex.relight(d, clamp=False) / np.float32(gain)
        np.testing.assert_allclose(got, stack[k], rtol=2e-5, atol=2e-5)


def test_relight_is_linear_and_matches_an_explicit_sum(texture):
    _, tex = texture
    d = direction_from_az_el(40.0, 35.0)
    c, gain = tex.steering_weights(d)
    want = np.einsum("k,khwc->hwc", c, tex.basis_images.astype(np.float64)) * gain
    np.testing.assert_allclose(tex.relight(d, clamp=False), want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(tex.relight(d, intensity=3.0, clamp=False), 3 * want, rtol=1e-5, atol=1e-6)
    tinted = tex.relight(d, color=(1.0, 0.5, 0.0), clamp=False)
    np.testing.assert_allclose(tinted[..., 1], 0.5 * want[..., 1], rtol=1e-5, atol=1e-6)
    assert np.all(tinted[..., 2] == 0)
    assert tex.relight(d).min() >= 0.0  # clamped


def test_below_horizon_is_dark_and_coefficients_match_steering(texture):
    _, tex = texture
    assert np.all(tex.relight(direction_from_az_el(10.0, -5.0)) == 0)
    d = direction_from_az_el(10.0, 60.0)
    c, _ = tex.steering_weights(d)
    from relightable_textures.lt_addon.sphere.hemisphere import hemisphere_to_disk

    np.testing.assert_allclose(c, steering_coefficients(tex.basis, hemisphere_to_disk(d)))


@pytest.mark.parametrize("storage, tol", [("float", 0.0), ("half", 2.0 ** -11), ("u8", 1.0 / 255)])
def test_save_load_round_trip(tmp_path, texture, storage, tol):
    _, tex = texture
    path = str(tmp_path / f"t-{storage}.exr")
    nbytes = tex.save(path, storage)
    assert nbytes > 0
    back = SteerableTexture.load(path)
    assert (back.order, back.frame, back.calibration) == (tex.order, tex.frame, tex.calibration)
    np.testing.assert_array_equal(back.centres, tex.centres)
    span = np.ptp(tex.basis_images, axis=(1, 2), keepdims=True)
    err = np.abs(back.basis_images - tex.basis_images)
    if storage == "half":
        assert np.all(err <= tol * np.abs(tex.basis_images) + 1e-7)
    else:
        assert np.all(err <= tol * span / 2 + 1e-6)


def test_bad_shapes_and_files_are_refused(tmp_path, texture):
    _, tex = texture
    with pytest.raises(ValueError, match="shape"):
        SteerableTexture(tex.basis_images[:3], 5, 0.01, tex.centres)
    with pytest.raises(ValueError, match="storage"):
        tex.save(str(tmp_path / "x.exr"), "jpeg")
    from relightable_textures.lt_addon.io import exrio

    exrio.write_exr(str(tmp_path / "other.exr"), {"Y": np.zeros((2, 2))})
    with pytest.raises(ValueError, match="not a steerable texture"):
        SteerableTexture.load(str(tmp_path / "other.exr"))
