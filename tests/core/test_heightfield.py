"""The paper patches' height fields: periodic, analytic cap heights, deterministic noise."""

import numpy as np
import pytest

from relightable_textures.lt_addon.geometry import heightfield


def test_bumps_cap_heights_match_sphere_geometry():
    cells, radius, depth = 4, 0.35, 0.8
    h = 1.0 / cells
    # Centre of cell (0, 0) is a bump, cell (1, 0) a dent (checkerboard).
    z = heightfield.bumps_and_dents(np.array([0.5 * h, 1.5 * h]), np.array([0.5 * h, 0.5 * h]),
                                    cells, radius, depth)
    np.testing.assert_allclose(z, [depth * radius * h, -depth * radius * h], rtol=1e-12)
    # Outside every footprint the surface is flat.
    assert heightfield.bumps_and_dents(np.array([0.0]), np.array([0.0]), cells, radius, depth)[0] == 0
    # Half-way out along the radius the sag follows the sphere through rim and apex.
    a, cap = radius * h, depth * radius * h
    R = (a * a + cap * cap) / (2 * cap)
    r = 0.5 * a
    expected = np.sqrt(R * R - r * r) - (R - cap)
    got = heightfield.bumps_and_dents(np.array([0.5 * h + r]), np.array([0.5 * h]), cells, radius, depth)
    np.testing.assert_allclose(got, [expected], rtol=1e-12)


@pytest.mark.parametrize("field", [
    lambda u, v: heightfield.bumps_and_dents(u, v),
    lambda u, v: heightfield.perlin_noise(u, v, period=3, octaves=3, seed=7),
])
def test_fields_tile_with_period_one(field):
    rng = np.random.default_rng(1)
    u, v = rng.uniform(0, 1, 500), rng.uniform(0, 1, 500)
    base = field(u, v)
    for du, dv in [(1, 0), (0, 1), (-2, 3)]:
        np.testing.assert_allclose(field(u + du, v + dv), base, atol=1e-12)


def test_perlin_is_zero_on_lattice_and_deterministic():
    u, v = heightfield.grid(8)
    z = heightfield.perlin_noise(u, v, period=4, octaves=1, seed=3)
    np.testing.assert_allclose(z[::2, ::2], 0.0, atol=1e-12)  # gradient noise vanishes at nodes
    np.testing.assert_array_equal(z, heightfield.perlin_noise(u, v, period=4, octaves=1, seed=3))
    assert np.abs(z).max() > 0.01
    assert not np.array_equal(z, heightfield.perlin_noise(u, v, period=4, octaves=1, seed=4))


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="finite"):
        heightfield.bumps_and_dents(np.array([np.nan]), np.array([0.0]))
    with pytest.raises(ValueError, match="same shape"):
        heightfield.perlin_noise(np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="radius"):
        heightfield.bumps_and_dents(np.zeros(1), np.zeros(1), radius=0.6)
