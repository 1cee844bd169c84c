"""Disk map of eq. 7, az/el helpers and the Cycles equirectangular convention."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.sphere import hemisphere as hs

FAST = settings(max_examples=60, deadline=None)

finite = st.floats(-1.0, 1.0, allow_nan=False)


@FAST
@given(r=st.floats(0.0, 1.0), phi=st.floats(0.0, 2 * np.pi))
def test_disk_roundtrip_and_unit_length(r, phi):
    xy = np.array([r * np.cos(phi), r * np.sin(phi)])
    d = hs.disk_to_hemisphere(xy)
    assert abs(np.linalg.norm(d) - 1.0) < 1e-12
    assert d[2] >= 0.0
    assert abs(d[2] - (1.0 - r * r)) < 1e-12  # cos(theta) = 1 - r^2
    assert np.allclose(hs.hemisphere_to_disk(d), xy, atol=1e-12)


@FAST
@given(az=st.floats(-180, 180), el=st.floats(0, 90))
def test_hemisphere_roundtrip(az, el):
    d = hs.direction_from_az_el(az, el)
    back = hs.disk_to_hemisphere(hs.hemisphere_to_disk(d))
    assert np.allclose(back, d, atol=1e-12)
    az2, el2 = hs.az_el_from_direction(d)
    assert abs(el2 - el) < 1e-9
    if el < 89.999:
        assert abs(((az2 - az + 180) % 360) - 180) < 1e-7


def test_zenith_and_horizon_exact():
    assert np.array_equal(hs.hemisphere_to_disk([0.0, 0.0, 1.0]), [0.0, 0.0])
    assert np.allclose(hs.disk_to_hemisphere([0.0, 0.0]), [0, 0, 1])
    h = hs.hemisphere_to_disk([[1, 0, 0], [0, -1, 0], [np.sqrt(0.5), np.sqrt(0.5), 0]])
    assert np.allclose(np.hypot(h[:, 0], h[:, 1]), 1.0, atol=1e-15)
    assert np.allclose(hs.disk_to_hemisphere([1.0, 0.0]), [1, 0, 0])
    # a rounding error outside the disk is snapped, a real one is refused
    assert np.allclose(hs.disk_to_hemisphere([1.0 + 1e-12, 0.0]), [1, 0, 0])
    with pytest.raises(ValueError, match="outside the unit disk"):
        hs.disk_to_hemisphere([1.01, 0.0])


def test_solid_angle_jacobian_is_two():
    """Independent check of dOmega = 2 dA: finite-difference Jacobian of the inverse map."""
    rng = np.random.default_rng(1)
    r = np.sqrt(rng.uniform(0, 0.95 ** 2, 200))
    phi = rng.uniform(0, 2 * np.pi, 200)
    xy = np.stack([r * np.cos(phi), r * np.sin(phi)], -1)
    h = 1e-6
    dx = (hs.disk_to_hemisphere(xy + [h, 0]) - hs.disk_to_hemisphere(xy - [h, 0])) / (2 * h)
    dy = (hs.disk_to_hemisphere(xy + [0, h]) - hs.disk_to_hemisphere(xy - [0, h])) / (2 * h)
    jac = np.linalg.norm(np.cross(dx, dy), axis=-1)
    assert np.allclose(jac, hs.SOLID_ANGLE_PER_DISK_AREA, rtol=1e-7)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_rejected(bad):
    with pytest.raises(ValueError, match="NaN or inf"):
        hs.hemisphere_to_disk([0.0, bad, 1.0])
    with pytest.raises(ValueError, match="NaN or inf"):
        hs.disk_to_hemisphere([bad, 0.0])
    with pytest.raises(ValueError, match="NaN or inf"):
        hs.direction_from_az_el(bad, 10.0)
    with pytest.raises(ValueError, match="NaN or inf"):
        hs.direction_to_equirect_uv([bad, 0.0, 0.0])


def test_invalid_shapes_and_zero_vector():
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        hs.hemisphere_to_disk([1.0, 0.0])
    with pytest.raises(ValueError, match="zero-length"):
        hs.hemisphere_to_disk([0.0, 0.0, 0.0])


@FAST
@given(az=st.floats(-180, 180), el=st.floats(-90, -1e-6))
def test_below_horizon_refused_by_disk_map(az, el):
    d = hs.direction_from_az_el(az, el)
    if d[2] >= -1e-9:  # within the snapping tolerance counts as the horizon
        return
    assert not hs.is_upper_hemisphere(d)
    with pytest.raises(ValueError, match="below the horizon"):
        hs.hemisphere_to_disk(d)


def test_az_el_axes():
    assert np.allclose(hs.direction_from_az_el(0, 0), [1, 0, 0])
    assert np.allclose(hs.direction_from_az_el(90, 0), [0, 1, 0])
    assert np.allclose(hs.direction_from_az_el(123, 90), [0, 0, 1])


def _cycles_uv(d):
    """Independent transcription of Cycles' direction_to_equirectangular_range with the
    default range (-2 pi, pi, -pi, pi)."""
    rx, ry, rz, rw = -2 * np.pi, np.pi, -np.pi, np.pi
    u = (np.arctan2(d[..., 1], d[..., 0]) - ry) / rx
    v = (np.arccos(d[..., 2] / np.linalg.norm(d, axis=-1)) - rw) / rz
    return np.stack([u, v], -1)


def test_equirect_matches_cycles_formula():
    rng = np.random.default_rng(2)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    ours = hs.direction_to_equirect_uv(d)
    ref = _cycles_uv(d)
    du = (ours[:, 0] - ref[:, 0] + 0.5) % 1.0 - 0.5  # u wraps
    assert np.max(np.abs(du)) < 1e-12
    assert np.allclose(ours[:, 1], ref[:, 1], atol=1e-12)
    assert np.allclose(hs.equirect_uv_to_direction(ours), d, atol=1e-12)
    # landmarks: +x at the centre column, +y at u = 0.25, zenith v = 1, horizon v = 0.5
    assert np.allclose(hs.direction_to_equirect_uv([1, 0, 0]), [0.5, 0.5])
    assert np.allclose(hs.direction_to_equirect_uv([0, 1, 0]), [0.25, 0.5])
    assert np.isclose(hs.direction_to_equirect_uv([0, 0, 1])[1], 1.0)


def test_pixel_directions_row_order():
    top = hs.equirect_pixel_directions(8, 16, row_order="top_first")
    bot = hs.equirect_pixel_directions(8, 16, row_order="bottom_first")
    assert top.shape == (8, 16, 3)
    assert np.array_equal(top, bot[::-1])
    assert top[0, 0, 2] > 0.9 and bot[0, 0, 2] < -0.9
    # column 8 of 16 has u = 8.5/16 just past the centre -> direction close to +x
    assert top[4, 8, 0] > 0.9
    with pytest.raises(ValueError, match="row_order"):
        hs.equirect_pixel_directions(8, 16, row_order="up")
