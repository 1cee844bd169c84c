"""Haar wavelets on cubemap faces: transform, reconstruction, non-linear approximation."""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere import directions as D
from relightable_textures.lt_addon.sphere import haar_baseline as H
from relightable_textures.lt_addon.transport import error as TE


def test_hand_computed_transform():
    x = np.arange(16.0).reshape(4, 4)
    # level 1 block [[0, 1], [4, 5]]: avg 5, horizontal -1, vertical -4, diagonal 0;
    # level 2 on the averages [[5, 9], [21, 25]]: 30, -4, -16, 0
    want = np.array([[30, -4, -1, -1], [-16, 0, -1, -1], [-4, -4, 0, 0], [-4, -4, 0, 0]])
    assert np.array_equal(H.haar2d_forward(x), want)
    assert np.allclose(H.haar2d_inverse(want), x)
    assert np.array_equal(H.haar2d_forward([[7.0]]), [[7.0]])


def test_transform_is_orthonormal_and_invertible():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3, 6, 16, 16))
    c = H.haar2d_forward(x)
    assert np.allclose(H.haar2d_inverse(c), x, atol=1e-12)
    assert np.allclose(np.sum(c ** 2, axis=(-2, -1)), np.sum(x ** 2, axis=(-2, -1)))
    y = rng.normal(size=(16, 16))
    assert np.sum(H.haar2d_forward(y) * c[0, 0]) == pytest.approx(np.sum(y * x[0, 0]))


def test_perfect_reconstruction_and_exact_shading_with_all_coefficients():
    ds = D.cubemap(8)
    T = TE.synthetic_shadowed_transport(ds, 100, 5, seed=2)["T"]
    c = H.haar_project(T, ds)
    assert np.allclose(H.haar_reconstruct(c, ds), T, atol=1e-12)
    assert np.allclose(H.haar_approximate(T, ds, ds.size), T, atol=1e-12)
    # Parseval with solid-angle weights: sum c^2 = sum T^2 dw
    assert np.allclose(np.sum(c ** 2, 1), np.sum(T ** 2 * ds.solid_angles, 1), rtol=1e-12)
    Lw = np.random.default_rng(3).random((ds.size, 3)) * ds.solid_angles[:, None]
    lc = H.haar_project_lighting(Lw, ds)
    assert np.allclose(H.haar_shade(c, lc, albedo=0.5), 0.5 / np.pi * T @ Lw, rtol=1e-12)
    assert np.allclose(H.haar_project_lighting(Lw[:, 1], ds), lc[:, 1])


def test_keep_largest_matches_sorting():
    rng = np.random.default_rng(4)
    c = rng.normal(size=(20, 50))
    for d in (0, 1, 7, 50, 80):
        kept = H.keep_largest(c, d)
        assert np.all(np.count_nonzero(kept, axis=1) == min(d, 50))
        thresh = -np.sort(-np.abs(c), axis=1)[:, min(d, 50) - 1] if d else np.inf
        if d:
            assert np.array_equal(kept != 0, np.abs(c) >= thresh[:, None])
        assert np.array_equal(kept[kept != 0], c[kept != 0])


def test_error_falls_monotonically_with_d_and_equals_dropped_energy():
    ds = D.cubemap(8)
    T = TE.synthetic_shadowed_transport(ds, 150, 6, seed=0)["T"]
    c = H.haar_project(T, ds)
    w = ds.solid_angles
    errs = []
    for d in (0, 1, 2, 4, 9, 16, 25, 36, 49, 100, 200, 384):
        err = np.sum((H.haar_approximate(T, ds, d) - T) ** 2 * w)
        dropped = np.sum(c ** 2 - H.keep_largest(c, d) ** 2)
        assert err == pytest.approx(dropped, rel=1e-9, abs=1e-12)
        errs.append(err)
    assert np.all(np.diff(errs) <= 1e-12) and errs[-1] < 1e-20
    # shading error of the d-term approximation (transport truncated, lighting exact)
    Lw = np.full(ds.size, 1.0) * w
    s = [H.haar_shading_error(T, ds, d, Lw) for d in (1, 49, 384)]
    assert s[2] < 1e-12 and s[1] < s[0]


def test_errors():
    with pytest.raises(ValueError, match="power-of-two"):
        H.haar2d_forward(np.ones((6, 6)))
    with pytest.raises(ValueError, match="cube:n"):
        H.haar_project(np.ones((2, 64)), D.halton_sphere(64))
    with pytest.raises(ValueError, match="power-of-two"):
        H.haar_project(np.ones((2, 6 * 36)), D.cubemap(6))
    with pytest.raises(ValueError, match=r"\(V, 384\)"):
        H.haar_project(np.ones((2, 10)), D.cubemap(8))
