"""Stability at the extremes (bpy-free part): light at the zenith / horizon / below it, basis
order N1 = 2..12, HDR intensities 1e-6..1e6, half-float overflow and underflow on storage,
all-black and all-white textures and transport, degenerate vertex data.

Every case has a defined result checked against an independent expectation (a direct render of
the steered light with a linear toy renderer, a spherical quadrature, the scaled fit, closed
forms), or a refusal with a clear message that leaves files untouched.
"""

from __future__ import annotations

import functools
import os
import re

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.transport import cpca as CP
from relightable_textures.lt_addon.sphere import directions as D
from relightable_textures.lt_addon.transport import eigentransport as ET
from relightable_textures.lt_addon.sphere import hemisphere as hs
from relightable_textures.lt_addon.steerable import basis as sb
from relightable_textures.lt_addon.io import storage as sto
from relightable_textures.lt_addon.steerable.calibration import DEFAULT_FLOOR, make_calibration
from relightable_textures.lt_addon.steerable.sampled_basis import build_sampled_basis
from relightable_textures.lt_addon.steerable.texture import (SteerableTexture,
                                                             build_from_sampled_bakes)

FEW = settings(max_examples=20, deadline=None)
ORDERS = range(2, 13)
RES = 3  # texels per side of the toy textures


# ----------------------------------------------------------------------------------------------
# a toy linear "renderer" (rendering is linear in the light, which is all steering relies on)


@functools.lru_cache(maxsize=None)
def _renderer(order: int):
    """Positive random transport R (texels*3, dirs) over upper-hemisphere directions, and the
    SteerableTexture built from "bakes" of the K sampled lights through it."""
    rng = np.random.default_rng(order)
    dirs = rng.normal(size=(400, 3))
    dirs[:, 2] = np.abs(dirs[:, 2])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    R = rng.uniform(0.0, 1.0, (RES * RES * 3, len(dirs))) * dirs[:, 2] * (2 * np.pi / len(dirs))
    basis = sb.paper_basis(order)
    sampled = build_sampled_basis(basis)
    bakes = np.stack([R @ sb.evaluate_light(basis, dirs, c) for c in sampled.centres])
    tex = build_from_sampled_bakes(bakes.reshape(-1, RES, RES, 3).astype(np.float32), order)
    return dirs, R, tex


def _render(order, xy0):
    """Direct render of the steered light centred on disk point ``xy0``; (RES, RES, 3)."""
    dirs, R, tex = _renderer(order)
    return (R @ sb.evaluate_light(tex.basis, dirs, xy0)).reshape(RES, RES, 3)


def _rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


# ----------------------------------------------------------------------------------------------
# basis order N1 = 2..12


@FEW
@given(order=st.sampled_from(ORDERS), seed=st.integers(0, 10_000),
       big=st.floats(1.0, 1e6))
def test_every_order_has_finite_basis_values_bounded_by_the_amplitudes(order, seed, big):
    """|b_ij(x, y)| <= a_i a_j everywhere (|cos| <= 1), including far outside the disk."""
    basis = sb.paper_basis(order)
    rng = np.random.default_rng(seed)
    xy = np.concatenate([rng.uniform(-1, 1, (64, 2)),                      # the disk domain
                         np.array([[1.0, 0.0], [0.0, -1.0], [np.sqrt(0.5)] * 2]),  # horizon
                         rng.uniform(-big, big, (16, 2))])                 # far outside
    B = sb.basis_2d(basis, xy)
    bound = np.outer(basis.a, basis.a).ravel()
    assert B.shape == (len(xy), order * order) and np.all(np.isfinite(B))
    assert np.all(np.abs(B) <= bound * (1 + 1e-12))
    c = sb.steering_coefficients(basis, xy)
    assert np.all(np.isfinite(c)) and np.all(np.abs(c) <= bound * (1 + 1e-12))


@FEW
@given(order=st.sampled_from(ORDERS), az=st.floats(-180, 180), el=st.floats(0.5, 90),
       seed=st.integers(0, 1000))
def test_every_order_steers_to_the_render_of_the_projected_light(order, az, el, seed):
    """Steering the basis images of the sampled-light bakes to any direction equals a direct
    render of the steered light (sum_ij c_ij b_ij) there, times the calibration gain; and the
    steered light is the explicit sum over the N1^2 product functions."""
    d = hs.direction_from_az_el(az, el)
    xy0 = hs.hemisphere_to_disk(d)
    _, _, tex = _renderer(order)
    c, gain = tex.steering_weights(d)
    assert np.isfinite(gain) and gain > 0 and np.all(np.isfinite(c))
    want = gain * _render(order, xy0)
    got = tex.relight(d, clamp=False)
    assert _rel(got, want) < 2e-5  # float32 basis images and sum
    # the projected light itself: explicit sum over k = i * N1 + j vs the separable product
    xy = np.random.default_rng(seed).uniform(-1, 1, (32, 2))
    explicit = sb.basis_2d(tex.basis, xy) @ sb.steering_coefficients(tex.basis, xy0)
    np.testing.assert_allclose(explicit, sb.steered_light_disk(tex.basis, xy, xy0),
                               rtol=1e-10, atol=1e-12)


# ----------------------------------------------------------------------------------------------
# light at the zenith, on the horizon and below it


@pytest.mark.parametrize("order", ORDERS)
def test_zenith_gain_is_one_over_the_flat_plane_irradiance_by_spherical_quadrature(order):
    """At the zenith the steerable-cos gain is 1 / E(zenith); E is integrated here on a
    (theta, phi) midpoint grid over the hemisphere, independently of the disk-domain quadrature
    used by the calibration (Gauss-Legendre in theta, periodic trapezoid in phi)."""
    _, _, tex = _renderer(order)
    c, gain = tex.steering_weights([0.0, 0.0, 1.0])
    g, wg = np.polynomial.legendre.leggauss(200)
    t, wt = (g + 1) * np.pi / 4, wg * np.pi / 4
    n_p = 512
    p = np.arange(n_p) * (2 * np.pi / n_p)
    T, P = np.meshgrid(t, p, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    L = sb.evaluate_light(tex.basis, dirs, [0.0, 0.0])
    E = np.sum(wt[:, None] * L * np.cos(T) * np.sin(T)) * (2 * np.pi / n_p)
    assert gain == pytest.approx(1.0 / E, rel=1e-9)
    np.testing.assert_array_equal(c, sb.steering_coefficients(tex.basis, [0.0, 0.0]))
    relit = tex.relight([0.0, 0.0, 1.0], clamp=False)
    assert _rel(relit, _render(order, [0.0, 0.0]) / E) < 2e-5


@pytest.mark.parametrize("order", [2, 7, 12])
@pytest.mark.parametrize("az", [0.0, 37.0, -135.0])
def test_horizon_is_black_and_the_approach_is_continuous(order, az):
    """On the horizon the gain cos(theta0) / max(E, floor E_z) is 0: exactly black. Just above
    it the texture is linear in sin(elevation) with the slope of the horizon coefficients."""
    _, _, tex = _renderer(order)
    horizon = hs.direction_from_az_el(az, 0.0)
    assert np.all(tex.relight(horizon, intensity=1e6) == 0.0)
    cal = make_calibration(tex.basis)
    c_h = sb.steering_coefficients(tex.basis, hs.hemisphere_to_disk(horizon))
    steered = np.maximum(np.einsum("k,khwc->hwc", c_h, tex.basis_images.astype(np.float64)), 0)
    slope = steered / max(float(c_h @ cal.E), DEFAULT_FLOOR * cal.E_zenith)
    for el, tol in ((1e-9, 1e-5), (1e-6, 1e-5), (1e-3, 1e-2)):
        relit = tex.relight(hs.direction_from_az_el(az, el)).astype(np.float64)
        assert np.all(np.isfinite(relit)) and relit.min() >= 0.0
        np.testing.assert_allclose(relit / np.sin(np.radians(el)), slope,
                                   rtol=tol, atol=tol * slope.max())


@FEW
@given(order=st.sampled_from(ORDERS), az=st.floats(-180, 180),
       el=st.floats(-90, 0, exclude_max=True), intensity=st.floats(1e-6, 1e6))
def test_below_the_horizon_the_light_is_off_for_every_order(order, az, el, intensity):
    _, _, tex = _renderer(order)
    d = hs.direction_from_az_el(az, el)
    c, gain = tex.steering_weights(d)
    assert gain == 0.0
    if d[2] < 0:  # (el ~ -1e-323 deg underflows to z = -0.0: the horizon, where only gain = 0)
        assert np.all(c == 0.0)
    assert np.all(tex.relight(d, intensity=intensity) == 0.0)
    assert np.all(tex.relight(d, clamp=False) == 0.0)


def test_tiny_negative_z_is_below_and_bad_directions_are_refused():
    _, _, tex = _renderer(3)
    for z in (-1e-300, -1e-17, -1e-9):
        assert np.all(tex.relight([1.0, 0.0, z]) == 0.0)
    assert tex.relight([1.0, 0.0, 1e-17]).max() >= 0.0  # horizon side: finite, non-negative
    with pytest.raises(ValueError, match="NaN or inf"):
        tex.relight([np.nan, 0.0, 1.0])
    with pytest.raises(ValueError, match="zero-length vector"):
        tex.relight([0.0, 0.0, 0.0])


# ----------------------------------------------------------------------------------------------
# HDR intensities


@FEW
@given(order=st.sampled_from([2, 5, 7, 12]), log_i=st.floats(-6, 6), az=st.floats(-180, 180),
       el=st.floats(1, 90))
def test_relighting_is_linear_and_finite_from_1e_minus_6_to_1e6(order, log_i, az, el):
    _, _, tex = _renderer(order)
    d = hs.direction_from_az_el(az, el)
    intensity = 10.0 ** log_i
    base = tex.relight(d).astype(np.float64)
    got = tex.relight(d, intensity=intensity, color=(1.0, 0.5, 0.25))
    assert got.dtype == np.float32 and np.all(np.isfinite(got))
    want = base * intensity * np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=0)


def test_intensities_1e6_and_1e_minus_6_exactly_and_non_finite_ones_refused():
    _, _, tex = _renderer(7)
    d = hs.direction_from_az_el(20.0, 40.0)
    one = tex.relight(d).astype(np.float64)
    assert one.max() > 0
    for i in (1e6, 1e-6):
        np.testing.assert_allclose(tex.relight(d, intensity=i), i * one, rtol=1e-6, atol=0)
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError, match="intensity and color must be finite"):
            tex.relight(d, intensity=bad)
    with pytest.raises(ValueError, match="intensity and color must be finite"):
        tex.relight(d, color=(1.0, np.nan, 1.0))
    # beyond float32 the relit texture would be inf: refused, with the peak it would reach
    with pytest.raises(ValueError, match=r"beyond the float32 range"):
        tex.relight(d, intensity=1e39)


# ----------------------------------------------------------------------------------------------
# storage: half-float overflow / underflow, 8-bit, all-black and all-white textures


def _texture(images, order):
    return SteerableTexture(np.asarray(images, np.float32), order, 0.01,
                            build_sampled_basis(sb.paper_basis(order)).centres)


@pytest.mark.parametrize("value", [0.0, 1.0, 65504.0, 1e6, 1e-6])
def test_constant_textures_round_trip_in_every_storage_that_accepts_them(tmp_path, value):
    """All-black (0), all-white (1), the largest half (65504), HDR 1e6 and a dim 1e-6: float
    and u8 are exact for constant images; half is exact where representable, refuses 1e6
    without touching the file, and stores 1e-6 as a subnormal (abs error <= 2^-25)."""
    tex = _texture(np.full((9, 4, 4, 3), value), 3)
    for storage in ("float", "u8"):
        path = str(tmp_path / f"{storage}.exr")
        tex.save(path, storage)
        np.testing.assert_array_equal(SteerableTexture.load(path).basis_images,
                                      tex.basis_images)
    path = tmp_path / "half.exr"
    path.write_bytes(b"previous bake")
    if value > sto.HALF_MAX:
        with pytest.raises(ValueError, match=r"channel 'b00\.R' exceeds the half-float range "
                                             r"\(\|x\| > 65504\); store it as float"):
            tex.save(str(path), "half")
        assert path.read_bytes() == b"previous bake"
        assert sorted(os.listdir(tmp_path)) == ["float.exr", "half.exr", "u8.exr"]
        return
    tex.save(str(path), "half")
    back = SteerableTexture.load(str(path)).basis_images
    err = np.abs(back.astype(np.float64) - np.float32(value))
    assert np.all(err <= max(2.0 ** -11 * value, 2.0 ** -25))
    if value in (0.0, 1.0, 65504.0):
        assert np.all(err == 0)
    # relighting an all-black texture is black at any intensity; a constant one is analytic
    d = hs.direction_from_az_el(60.0, 50.0)
    c, gain = tex.steering_weights(d)
    want = max(float(np.sum(c)), 0.0) * gain * 1e6 * float(np.float32(value))
    np.testing.assert_allclose(tex.relight(d, intensity=1e6), want, rtol=1e-5, atol=0)


@FEW
@given(log_s=st.floats(-6, 6), seed=st.integers(0, 1000), per_channel=st.booleans())
def test_uint8_codec_is_scale_equivariant_and_keeps_its_bound(log_s, seed, per_channel):
    """8-bit with per-image min/max has no range limit: quantising s*x gives s times the codes'
    values (same codes), error <= s * span / 510 (+ float32 rounding of min/max)."""
    s = 10.0 ** log_s
    x = np.random.default_rng(seed).normal(size=(4, 5, 5, 3))
    a, b = sto.encode_uint8(x, per_channel), sto.encode_uint8(s * x, per_channel)
    moved = a.data.astype(int) - b.data  # same codes, but for rounding ties at q + 1/2
    assert np.abs(moved).max() <= 1 and np.mean(moved != 0) < 0.01
    dec = b.decode().astype(np.float64)
    axes = (1, 2) if per_channel else (1, 2, 3)
    span = np.ptp(s * x, axis=axes, keepdims=True)
    assert np.all(np.abs(dec - s * x) <= span / 510 * (1 + 1e-5) + 1e-6 * np.abs(s * x).max())


@FEW
@given(value=st.floats(-1e6, 1e6, allow_nan=False, width=32))
def test_half_codec_overflows_loudly_and_only_above_65504(value):
    x = np.full((2, 3, 3), value, dtype=np.float32)
    rounds_to_inf = abs(float(value)) >= 65520.0  # IEEE half: 65520 rounds to inf
    if rounds_to_inf:
        msg = (f"half-float overflow: max |value| = {abs(value):.6g} exceeds 65504; "
               "scale the images or use float32 storage")
        with pytest.raises(sto.HalfOverflowError, match=re.escape(msg)):
            sto.encode_half(x)
        fb = sto.encode_half(x, on_overflow="float32")
        assert fb.fell_back and np.array_equal(fb.decode(), x)
    else:
        dec = sto.encode_half(x).decode().astype(np.float64)
        assert np.all(np.isfinite(dec))
        assert np.all(np.abs(dec - value) <= max(2.0 ** -11 * abs(value), 2.0 ** -25))


@pytest.mark.parametrize("fill", [0.0, 1.0], ids=["all_black", "all_white"])
def test_codec_table_and_pca_of_black_and_white_stacks(fill):
    x = np.full((6, 4, 4, 3), fill)
    rows = {r["codec"]: r for r in sto.codec_table(x, pca_ks=(1, 6), steering=np.ones((2, 6)))}
    assert set(rows) == {"float32", "uint8", "uint8_per_channel", "half", "pca1", "pca6"}
    for r in rows.values():
        assert r["max_abs"] <= 1e-6 * fill and r["steered_max_abs"] <= 1e-5 * fill
    pca = sto.encode_pca(x, 1)
    assert pca.captured_energy == pytest.approx(1.0, abs=1e-12)  # 1 for all-zero, by definition
    assert fill or pca.captured_energy == 1.0
    np.testing.assert_allclose(pca.decode(), x, atol=1e-6)
    assert np.all(np.isfinite(pca.eigen_images)) and np.all(np.isfinite(pca.coefficients))


# ----------------------------------------------------------------------------------------------
# transport at the extremes: scale equivariance of eigentransport and CPCA


def _transport(kind, seed=0):
    rng = np.random.default_rng(seed)
    if kind == "zero":  # all black / fully occluded
        return np.zeros((40, 24))
    if kind == "constant":  # all white: every vertex sees the same
        return np.tile(rng.random(24), (40, 1))
    groups = [rng.random((20, 2)) @ rng.random((2, 24)) + 3 * g * rng.random(24)
              for g in range(2)]
    return np.vstack(groups) * (rng.random((40, 24)) > 0.25)  # shadows: exact zeros


@FEW
@given(kind=st.sampled_from(["zero", "constant", "shadowed"]), seed=st.integers(0, 500),
       scale=st.sampled_from([1e-6, 1e-3, 1e3, 1e6]), d=st.integers(0, 30))
def test_eigentransport_fit_is_scale_equivariant(kind, seed, scale, d):
    """fit(s T) = s fit(T): same rank and d, same eigentransports, s * coefficients and mean,
    s^2 * eigenvalues, s * shading; the same d from an energy target."""
    T = _transport(kind, seed)
    a, b = ET.fit_eigentransport(T, d=d), ET.fit_eigentransport(scale * T, d=d)
    assert (b.rank, b.d) == (a.rank, a.d)
    np.testing.assert_allclose(b.basis, a.basis, atol=1e-9)
    np.testing.assert_allclose(b.mean, scale * a.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(b.coefficients, scale * a.coefficients, rtol=1e-9,
                               atol=1e-9 * scale * max(np.abs(T).max(), 1e-300))
    np.testing.assert_allclose(b.eigenvalues, scale ** 2 * a.eigenvalues, rtol=1e-9)
    Lw = np.random.default_rng(seed + 1).random((24, 3))
    sa, sb_ = a.shade(Lw), b.shade(Lw)
    assert np.all(np.isfinite(sb_))
    np.testing.assert_allclose(sb_, scale * sa, rtol=1e-9, atol=1e-12 * scale * np.abs(sa).max())
    for energy in (0.9, 0.999):
        assert (ET.fit_eigentransport(scale * T, energy=energy).d
                == ET.fit_eigentransport(T, energy=energy).d)
    if kind != "shadowed":
        assert b.rank == 0 and b.captured_energy == 1.0
        np.testing.assert_allclose(b.reconstruct(), scale * T, rtol=1e-12, atol=0)


@pytest.mark.parametrize("kind", ["zero", "constant", "shadowed"])
@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_cpca_fits_are_scale_equivariant(kind, scale):
    """Same clusters, dimensions, N and cost; s * reconstruction; the adaptive split decisions
    (cost-based) do not depend on the scale either."""
    T = _transport(kind)
    for fit in (lambda X: CP.fit_cpca(X, 3, tol=1e-3, seed=1),
                lambda X: CP.fit_cpca(X, 3, dims=1, seed=1),
                lambda X: CP.adaptive_cpca(X, start_clusters=2, tol=1e-3, seed=1)):
        a, b = fit(T), fit(scale * T)
        np.testing.assert_array_equal(b.labels, a.labels)
        assert b.N == a.N and b.dims().tolist() == a.dims().tolist() and b.cost() == a.cost()
        np.testing.assert_allclose(b.reconstruct(), scale * a.reconstruct(), rtol=1e-9,
                                   atol=1e-9 * scale * max(np.abs(T).max(), 1e-300))
        lw = np.linspace(0.5, 2.0, T.shape[1])
        np.testing.assert_allclose(b.shade(lw), scale * a.shade(lw), rtol=1e-9,
                                   atol=1e-12 * scale * (np.abs(a.shade(lw)).max() + 1e-300))
    if kind == "zero":
        z = CP.fit_cpca(scale * T, 3, tol=1e-3)
        assert z.N == 0 and z.cost() == 0.0 and np.all(z.shade(lw) == 0.0)


# ----------------------------------------------------------------------------------------------
# degenerate vertex data (what a mesh with zero-area faces / duplicate vertices hands over)


def test_point_light_weights_for_duplicate_vertices_and_zero_normals():
    """Duplicate vertices get identical weights; a vertex of zero-area faces only (Blender gives
    it a zero normal) gets none; a single vertex / coplanar / duplicate-only point set spans no
    volume, so no light is 'inside the hull' and no warning is raised."""
    ds = D.parse_direction_spec("cube:4")
    pos = np.array([[0.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    nrm = np.array([[0.0, 0, 1], [0.0, 0, 1], [0.0, 0, 1], [0.0, 0, 0]])
    light = np.array([0.5, 0.0, 2.0])
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        W = ET.point_light_weights(pos, nrm, ds, light, 100.0)
    assert np.all(np.isfinite(W))
    np.testing.assert_array_equal(W[0], W[1])
    assert np.all(W[3] == 0.0)
    r2 = np.sum((light - pos[:3]) ** 2, axis=1)
    np.testing.assert_allclose(W[:3].sum(axis=1), 100.0 / (4 * np.pi) / r2, rtol=1e-12)
    for pts in (pos[:1], np.repeat(pos[:1], 5, axis=0),
                np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])):
        assert ET.inside_convex_hull(pts, [0.2, 0.2, 0.0]) is False
    with pytest.raises(ValueError, match="coincides with a vertex"):
        ET.point_light_weights(pos, nrm, ds, pos[2], 100.0)
