"""T's directions under the horizon (lt_addon/sphere/under_horizon.py): the set's band above it
mirrored, the relight's interpolation across the horizon, and nothing else changed.

The reference is the disc average of the unshadowed cosine (4,000 hard suns spread over the disc,
the relight's own sunflower): a wall facing the sun takes light from the disc's part under the
horizon, a floor none. Measured 2026-12-07: a wall under a 10-degree Sun 1 / 3 / 8 degrees high
0.18 / 0.18 / 0.20 % from it with the directions under the horizon (38 / 18 / 0.2 % dark
without them); a floor's light does not move."""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
from relightable_textures.lt_addon.sphere.under_horizon import (UNDER_DEG, depth_for,
                                                                under_count, with_under)
from relightable_textures.lt_addon.transport import texture as tt


def test_the_band_above_the_horizon_is_mirrored_first():
    base = parse_direction_spec("hemi:400:1.5")
    d = with_under(base, 5.0)
    n = under_count(d)
    band = (base.directions[:, 2] > 0) & (base.directions[:, 2] < np.sin(np.radians(5.0)))
    assert n == band.sum() == d.params["under_directions"] == 79
    assert d.size == 400 + n and (d.directions[:n, 2] < 0).all() and (d.directions[n:, 2] > 0).all()
    np.testing.assert_allclose(d.directions[:n], base.directions[band] * [1, 1, -1], atol=1e-12)
    np.testing.assert_allclose(d.directions[n:], base.directions, atol=1e-15)
    np.testing.assert_array_equal(d.solid_angles[:n], base.solid_angles[band])
    assert d.params["base"] == "hemi:400:1.5" and d.params["under_horizon_deg"] == 5.0
    assert with_under(base, 0.0) is base and with_under(d, 5.0) is d   # none, or already there
    assert depth_for(0.526) == depth_for(2.0) == UNDER_DEG == 5.0
    assert depth_for(16.0) == 8.0 and depth_for(30.0) == 10.0 and depth_for(30.0, 0.0) == 0.0
    assert depth_for(2.0, 3.0) == 3.0


def _disc_truth(normal, d, size):
    pts = tt._disc_points(d, np.radians(size) / 2, 4000)
    return float(np.maximum(pts @ normal, 0.0).mean())


@pytest.mark.parametrize("el", [1.0, 3.0, 8.0])
def test_a_wall_is_lit_by_the_disc_under_the_horizon_and_a_floor_is_not(el):
    base = parse_direction_spec("hemi:400:1.5")
    under = with_under(base, 5.0)
    d = direction_from_az_el(0.0, el)
    wall, floor = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    got = {}
    for name, dset in (("base", base), ("under", under)):
        idx, w = tt.sun_weights(dset, d, 10.0)
        T = np.maximum(dset.directions[idx] @ np.stack([wall, floor], 1), 0.0)    # (K, 2)
        got[name] = w @ T
    truth = _disc_truth(wall, d, 10.0)
    assert abs(got["under"][0] - truth) < 0.006 * truth, (el, got, truth)
    # a floor: dark from every direction under the horizon, and the disc's part there takes
    # the weights of its mirror above the horizon, moved onto the mirrored rows: unchanged
    assert abs(got["under"][1] - got["base"][1]) < 1e-9 * _disc_truth(floor, d, 10.0), got
    missing = 1.0 - got["base"][0] / _disc_truth(wall, d, 10.0)
    # the disc's part under the horizon, dark without them: a quarter at 1 degree (3 under)
    assert missing > {1.0: 0.3, 3.0: 0.15, 8.0: -1}[el], missing


def test_an_environment_weighs_the_sky_above_the_horizon_only():
    base = parse_direction_spec("hemi:400:1.5")
    under = with_under(base, 5.0)
    env = np.ones((32, 64), np.float32)
    wb = tt.environment_weights(base, env, row_order="top_first")
    wu = tt.environment_weights(under, env, row_order="top_first")
    n = under_count(under)
    assert (wu[:n] == 0).all()
    np.testing.assert_allclose(wu[n:], wb, rtol=1e-12)
    assert wu.sum() == pytest.approx(2 * np.pi, rel=1e-9)


def test_a_sun_above_the_horizon_is_interpolated_as_without_the_band():
    """A disc wholly above the horizon takes the weights the set without the band gives it:
    near the horizon a hemi set's directions are tens of degrees apart in azimuth, and a hull
    over both bands would blend a sun 1 degree high with directions under the horizon (the
    gallery's fence at 1 degree under a 0.526-degree Sun: 0.025 -> 0.063 from Cycles that way)."""
    base = parse_direction_spec("hemi:400:1.5")
    under = with_under(base, 5.0)
    n = under_count(under)
    for az, el, size in ((37.0, 1.0, 0.526), (37.0, 1.0, 2.0), (90.0, 3.0, 2.0), (200, 30, 10)):
        d = direction_from_az_el(az, el)
        ib, wb = tt.sun_weights(base, d, size)
        iu, wu = tt.sun_weights(under, d, size)
        assert (iu >= n).all()
        np.testing.assert_array_equal(iu - n, ib)
        np.testing.assert_allclose(wu, wb, rtol=1e-12)


def test_a_point_under_the_horizon_weighs_the_mirrors_of_its_mirror():
    """A disc point just under the horizon weighs the mirrors of the rows its mirror just above
    weighs (sun_weights' rule), so the weights are continuous across the horizon: folded back
    onto the rows above, the weights at -1e-7 rad equal those at +1e-7 rad at every azimuth (a
    hull over both bands stepped there by up to 2 in L1). Checks the mirror table the rule reads
    against the band with_under mirrored."""
    under = with_under(parse_direction_spec("hemi:400:1.5"), 5.0)
    n, S = under_count(under), under.size
    fold = np.arange(S + 1)                    # an under row -> the row above it mirrors
    fold[:n] = n + np.flatnonzero((under.directions[n:, 2] > 0)
                                  & (under.directions[n:, 2] < np.sin(np.radians(5.0))))
    up = tt._hull(under, upper=True)
    assert (up.mirror[fold[:n]] == np.arange(n)).all()
    for az in np.radians(np.linspace(0.0, 360.0, 37)):
        w = []
        for z in (1e-7, -1e-7):
            q = np.array([[np.cos(az), np.sin(az), z]])
            tri, wt = up.weights(q * [1, 1, np.sign(z)])
            if z < 0:
                tri = up.mirror[tri]
            acc = np.zeros(S + 1)
            np.add.at(acc, fold[tri].ravel(), wt.ravel())
            w.append(acc)
        assert np.abs(w[0] - w[1]).sum() < 1e-12, np.degrees(az)
