"""Sampled basis (paper sec. 3 eq. 3, sec. 6.1): centres, cond(C), transform and steering."""


import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.sphere import hemisphere as hs
from relightable_textures.lt_addon.steerable import sampled_basis as sbm
from relightable_textures.lt_addon.steerable import basis as sb

FAST = settings(max_examples=25, deadline=None)


def _renderer(basis, n_dirs=400, n_pix=60, seed=0):
    """A toy linear 'renderer': image = R @ (light sampled on n_dirs hemisphere directions).

    Rendering is linear in the light (paper eq. 2), which is all the sampled basis relies on."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n_dirs, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    R = rng.uniform(0, 1, (n_pix, n_dirs)) * d[:, 2] / n_dirs  # cosine-weighted, positive

    def render(xy0):
        return R @ sb.evaluate_light(basis, d, xy0)

    def render_basis():
        return (R @ sb.evaluate_basis_on_hemisphere(basis, d)).T  # (N, n_pix)

    return render, render_basis


@pytest.mark.parametrize("order", range(2, 13))
def test_default_centres_all_orders(order):
    b = sb.paper_basis(order)
    S = sbm.build_sampled_basis(b)
    assert S.centres.shape == (order * order, 2)
    assert S.condition_number < 2.0  # reported; 1.02 (N1=2) .. 1.72 (N1=12)
    assert np.isclose(S.condition_number, np.linalg.cond(S.matrix))
    rng = np.random.default_rng(order)
    imgs = rng.normal(size=(order * order, 6, 5, 3))
    B, res = S.to_basis_images(imgs, return_residual=True)
    assert res < 1e-8
    # independent residual
    recon = np.einsum("kn,n...->k...", S.matrix, B)
    assert np.linalg.norm(recon - imgs) / np.linalg.norm(imgs) < 1e-8


def test_default_extent_for_seven_and_design_note():
    b = sb.paper_basis()
    assert sbm.default_grid_extent(b) == pytest.approx(0.81)
    # the design note's grid at +-0.85 has cond ~1.5; cond(C) = cond(C1)^2 (Kronecker)
    C = sbm.coefficient_matrix(b, sbm.default_centres(7, 0.85, b))
    assert 1.4 < np.linalg.cond(C) < 1.6
    g = np.linspace(-0.85, 0.85, 7)
    assert np.isclose(np.linalg.cond(C), np.linalg.cond(b.steering_coefficients(g)) ** 2)
    # corner centres lie outside the unit disk: valid lights anyway
    assert np.max(np.hypot(*sbm.default_centres(7).T)) > 1.0


def test_ring_set_is_singular_and_offset_is_not():
    b = sb.paper_basis()
    ring = sbm.ring_centres(8, 6, phase_deg=0.0)
    assert ring.shape == (49, 2)
    assert np.linalg.cond(sbm.coefficient_matrix(b, ring)) > 1e12
    with pytest.raises(ValueError, match="near-singular"):
        sbm.build_sampled_basis(b, ring)
    with pytest.warns(sbm.SingularCentreSetWarning, match="badly conditioned"):
        S = sbm.build_sampled_basis(b, sbm.ring_centres(8, 6, phase_deg=60.0))
    assert 1e3 < S.condition_number < 1e5


def test_too_few_centres_and_nan():
    b = sb.paper_basis()
    with pytest.raises(ValueError, match="at least N = 49"):
        sbm.build_sampled_basis(b, sbm.default_centres(7)[:40])
    bad = sbm.default_centres(7).copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        sbm.build_sampled_basis(b, bad)


def test_steering_reproduces_renders_of_any_light():
    """Bake the sampled lights with a linear renderer, transform, steer: the result equals a
    direct render of the steered light, at the centres (1e-6) and anywhere else."""
    b = sb.paper_basis()
    S = sbm.build_sampled_basis(b)
    render, render_basis = _renderer(b)
    samples = np.stack([render(c) for c in S.centres])  # (49, n_pix)
    B = S.to_basis_images(samples)
    assert np.allclose(B, render_basis(), atol=1e-10 * np.abs(B).max())
    scale = np.abs(samples).max()
    for k in range(S.n_lights):
        assert np.max(np.abs(S.steer(B, S.centres[k]) - samples[k])) <= 1e-6 * scale
    rng = np.random.default_rng(5)
    for xy0 in rng.uniform(-0.9, 0.9, (10, 2)):
        assert np.allclose(S.steer(B, xy0), render(xy0), atol=1e-10 * scale)
        # eq. 3: steering straight from the sampled images
        assert np.allclose(S.sampled_weights(xy0) @ samples, render(xy0), atol=1e-10 * scale)


@FAST
@given(a=st.floats(-5, 5), c=st.floats(-5, 5), seed=st.integers(0, 10_000),
       x0=st.floats(-1, 1), y0=st.floats(-1, 1))
def test_transform_and_steering_are_linear(a, c, seed, x0, y0):
    S = sbm.build_sampled_basis()
    rng = np.random.default_rng(seed)
    s1, s2 = rng.normal(size=(2, 49, 3, 4))
    B12 = S.to_basis_images(a * s1 + c * s2)
    B1, B2 = S.to_basis_images(s1), S.to_basis_images(s2)
    assert np.allclose(B12, a * B1 + c * B2, atol=1e-9)
    st12 = S.steer(B12, [x0, y0])
    assert np.allclose(st12, a * S.steer(B1, [x0, y0]) + c * S.steer(B2, [x0, y0]), atol=1e-9)
    assert np.allclose(S.to_sampled_images(B1), s1, atol=1e-10)


def test_chunked_transform_float32_output(monkeypatch):
    monkeypatch.setattr(sbm, "_CHUNK", 7)  # many chunks, one of them partial
    S = sbm.build_sampled_basis()
    rng = np.random.default_rng(1)
    imgs = rng.normal(size=(49, 10, 5)).astype(np.float32)
    B = S.to_basis_images(imgs, dtype=np.float32)
    assert B.dtype == np.float32 and B.shape == (49, 10, 5)
    ref = np.linalg.solve(S.matrix, imgs.reshape(49, -1).astype(np.float64)).reshape(B.shape)
    assert np.allclose(B, ref, rtol=1e-5, atol=1e-6)


def test_more_lights_than_basis_least_squares():
    b = sb.paper_basis()
    cen = np.vstack([sbm.default_centres(7), [[0.1, 0.2], [-0.5, 0.3]]])
    S = sbm.build_sampled_basis(b, cen)
    render, render_basis = _renderer(b, seed=3)
    samples = np.stack([render(c) for c in cen])
    B, res = S.to_basis_images(samples, return_residual=True)
    assert res < 1e-10  # consistent (noise-free) data
    assert np.allclose(B, render_basis(), atol=1e-9 * np.abs(B).max())


def test_light_environment_outside_disk_centre():
    S = sbm.build_sampled_basis()
    corner = int(np.argmax(np.hypot(*S.centres.T)))
    env = S.light_environment(corner, 32, row_order="bottom_first")
    assert env.shape == (32, 64) and np.all(np.isfinite(env))
    assert np.all(env[:16] == 0)  # bottom-first: the first half of the rows is below the horizon
    assert np.max(np.abs(env[16:])) > 0.05  # its lobe still reaches the hemisphere
    dirs = hs.equirect_pixel_directions(32, 64, row_order="bottom_first")
    assert np.allclose(env, sb.evaluate_light(S.basis, dirs, S.centres[corner]), atol=1e-6)


def test_to_dict_is_json():
    import json
    d = json.loads(json.dumps(sbm.build_sampled_basis().to_dict()))
    assert len(d["centres"]) == 49 and d["condition_number"] < 2
