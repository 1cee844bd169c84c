"""Sec. 7.3 linear-interpolation baseline."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.steerable import interp_baseline as ib
from relightable_textures.lt_addon.steerable import sampled_basis as sbm
from relightable_textures.lt_addon.steerable import basis as sb

FAST = settings(max_examples=60, deadline=None)
G = np.linspace(-0.81, 0.81, 7)


@FAST
@given(x=st.floats(-1.2, 1.2), y=st.floats(-1.2, 1.2))
def test_weights_convex_and_local(x, y):
    w = ib.bilinear_weights([x, y], G, G)
    assert w.shape == (49,)
    assert np.all(w >= -1e-15) and np.isclose(w.sum(), 1.0)
    assert np.count_nonzero(w > 1e-15) <= 4


@FAST
@given(x=st.floats(-0.81, 0.81), y=st.floats(-0.81, 0.81))
def test_bilinear_reproduces_bilinear_functions(x, y):
    cen = sbm.default_centres(7, 0.81)
    f = lambda p: 0.3 + 1.2 * p[..., 0] - 0.7 * p[..., 1] + 0.9 * p[..., 0] * p[..., 1]  # noqa
    w = ib.bilinear_weights([x, y], G, G)
    assert np.isclose(w @ f(cen), f(np.array([x, y])), atol=1e-12)


def test_grid_nodes_one_hot_and_order():
    cen = sbm.default_centres(7, 0.81)
    W = ib.bilinear_weights(cen, G, G)
    assert np.allclose(W, np.eye(49), atol=1e-12)  # same flattening as default_centres


def test_gaussian_width_matches_steerable_main_lobe():
    # FWHM of exp(-29 r^2) = 2 sqrt(ln 2 / 29) = 0.309; steerable light: 0.336
    x = np.linspace(-1, 1, 20001)
    L = ib.gaussian_light_disk(np.stack([x, np.zeros_like(x)], -1), [0.0, 0.0])
    above = x[L >= 0.5]
    fwhm = above[-1] - above[0]
    assert np.isclose(fwhm, 2 * np.sqrt(np.log(2) / 29), atol=2e-4)
    steer = sb.light_profile_1d(sb.paper_basis(), 0.0)["fwhm"]
    assert abs(fwhm - steer) / steer < 0.15


def test_environment_and_interpolation():
    env = ib.gaussian_environment([0.0, 0.0], 16, row_order="top_first")
    assert env.shape == (16, 32) and np.all(env[8:] == 0)
    # top row centre: theta = pi / 32, r^2 = 1 - cos(theta) on the disk
    assert np.allclose(env[0], np.exp(-29 * (1 - np.cos(np.pi / 32))), rtol=1e-6)
    imgs = np.arange(49, dtype=np.float64)[:, None] * np.ones((49, 3))
    w = ib.bilinear_weights([0.0, 0.0], G, G)
    assert np.allclose(ib.interpolate_images(imgs, w), 24.0)
    with pytest.raises(ValueError, match="NaN or inf"):
        ib.bilinear_weights([np.nan, 0.0], G, G)
