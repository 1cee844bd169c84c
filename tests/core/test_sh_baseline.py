"""Real spherical harmonics baseline: values, orthonormality, projection, shading."""

import numpy as np
import pytest
from scipy.special import sph_harm_y

from relightable_textures.lt_addon.sphere import directions as D
from relightable_textures.lt_addon.sphere import sh_baseline as SH


def _reference(d, order, bands=None):
    """Independent real SH from scipy's complex Y (Condon-Shortley phase removed)."""
    th, ph = np.arccos(np.clip(d[:, 2], -1, 1)), np.arctan2(d[:, 1], d[:, 0])
    out = np.zeros((d.shape[0], (order + 1) ** 2))
    for b in (range(order + 1) if bands is None else bands):
        for m in range(-b, b + 1):
            c = sph_harm_y(b, abs(m), th, ph) * (-1) ** abs(m)
            out[:, SH.sh_index(b, m)] = (c.real if m == 0 else
                                         np.sqrt(2) * (c.real if m > 0 else c.imag))
    return out


@pytest.mark.parametrize("order", [0, 3, 8, 30])
def test_values_match_scipy(order):
    d = np.random.default_rng(order).normal(size=(60, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), [[0, 0, 1], [0, 0, -1]]])
    Y = SH.real_sh(d, order)
    assert Y.shape == (62, (order + 1) ** 2)
    assert np.abs(Y - _reference(d, order)).max() < 1e-11
    # closed forms of the first bands
    assert np.allclose(Y[:, 0], 0.5 / np.sqrt(np.pi))
    if order >= 1:
        assert np.allclose(Y[:, SH.sh_index(1, 0)], np.sqrt(3 / (4 * np.pi)) * d[:, 2])
        assert np.allclose(Y[:, SH.sh_index(1, 1)], np.sqrt(3 / (4 * np.pi)) * d[:, 0])
        assert np.allclose(Y[:, SH.sh_index(1, -1)], np.sqrt(3 / (4 * np.pi)) * d[:, 1])


def test_high_order_recurrence_is_stable():
    d = D.halton_sphere(200).directions
    Y = SH.real_sh(d, 80)
    assert np.all(np.isfinite(Y))
    ref = _reference(d, 80, bands=[79, 80])
    assert np.abs(Y[:, 79 ** 2:] - ref[:, 79 ** 2:]).max() < 1e-9


def test_orthonormal_under_gauss_cube_quadrature():
    ds = D.cube_gauss(32)
    Y = SH.real_sh(ds.directions, 10)                        # 121 functions
    G = Y.T @ (Y * ds.solid_angles[:, None])
    assert np.abs(G - np.eye(121)).max() < 1e-10


def test_texel_centre_cubemap_is_only_second_order_accurate():
    """The midpoint rule on cubemap texels (exact texel solid angles) is not exact for SH:
    the Gram error falls as 1/n^2 (measured 2.3e-3 at n = 16, 1.5e-4 at n = 64 for order 6)."""
    errs = []
    for n in (16, 32):
        ds = D.cubemap(n)
        Y = SH.real_sh(ds.directions, 6)
        errs.append(np.abs(Y.T @ (Y * ds.solid_angles[:, None]) - np.eye(49)).max())
    assert errs[0] < 5e-3 and 3.5 < errs[0] / errs[1] < 4.5, errs


def test_projection_of_band_limited_transport_is_exact_with_lstsq():
    ds = D.cubemap(8)
    rng = np.random.default_rng(0)
    coef = rng.normal(size=(5, 16))
    T = SH.sh_reconstruct(coef, ds.directions)
    got = SH.sh_project(T, ds.directions, ds.solid_angles, 3, method="lstsq")
    assert np.allclose(got, coef, atol=1e-10)
    quad = SH.sh_project(T, ds.directions, ds.solid_angles, 3)      # midpoint quadrature
    assert np.abs(quad - coef).max() < 0.05 * np.abs(coef).max()
    with pytest.raises(ValueError, match="method"):
        SH.sh_project(T, ds.directions, ds.solid_angles, 3, method="x")


def test_clamped_cosine_coefficients():
    """Ramamoorthi & Hanrahan: max(0, cos theta) has c00 = sqrt(pi)/2, c10 = sqrt(pi/3), and
    c20 = sqrt(5 pi)/8."""
    ds = D.latlong(128, 8)              # azimuthally symmetric function: few columns suffice
    T = np.clip(ds.directions[:, 2], 0, None)[None]
    c = SH.sh_project(T, ds.directions, ds.solid_angles, 2)[0]
    assert c[0] == pytest.approx(np.sqrt(np.pi) / 2, rel=1e-4)
    assert c[SH.sh_index(1, 0)] == pytest.approx(np.sqrt(np.pi / 3), rel=1e-4)
    assert c[SH.sh_index(2, 0)] == pytest.approx(np.sqrt(5 * np.pi) / 8, rel=1e-3)
    assert np.abs(c[[1, 3, 4, 5, 7, 8]]).max() < 1e-12


def test_shading_from_coefficients_equals_shading_of_reconstruction():
    ds = D.halton_sphere(512)
    rng = np.random.default_rng(1)
    T = np.clip(rng.normal(size=(30, 3)) @ ds.directions.T, 0, None)
    Lw = rng.random((512, 3)) * ds.solid_angles[:, None]
    t = SH.sh_project(T, ds.directions, ds.solid_angles, 4)
    lc = SH.sh_project_lighting(Lw, ds.directions, 4)
    B = SH.sh_shade(t, lc, albedo=0.6)
    assert np.allclose(B, 0.6 / np.pi * SH.sh_reconstruct(t, ds.directions) @ Lw, rtol=1e-12)
    assert B.shape == (30, 3)


def test_counts_and_errors():
    assert [SH.sh_order_for_count(c) for c in (1, 3, 4, 8, 9, 48, 49, 50)] == \
        [0, 0, 1, 1, 2, 5, 6, 6]
    assert SH.sh_count(6) == 49 and SH.sh_index(2, -2) == 4
    with pytest.raises(ValueError, match="order"):
        SH.real_sh(np.eye(3), -1)
    with pytest.raises(ValueError, match="square"):
        SH.sh_reconstruct(np.ones((2, 5)), np.eye(3))
