"""Negative-lobe offset fallback and the post-steering clamp."""

import numpy as np
import pytest

from relightable_textures.lt_addon.steerable import clamp
from relightable_textures.lt_addon.sphere import hemisphere as hs
from relightable_textures.lt_addon.steerable import sampled_basis as sbm
from relightable_textures.lt_addon.steerable import basis as sb


def test_offset_trick_recovers_the_negative_light_bake():
    """bake(L + cU) - c bake(U) == bake(L) for a linear renderer (a random positive matrix
    acting on the environment pixels), with the offset lights all non-negative."""
    S = sbm.build_sampled_basis()
    H = 16
    U = clamp.uniform_hemisphere_environment(H, row_order="top_first", dtype=np.float64)
    assert U[: H // 2].min() == 1 and U[H // 2:].max() == 0
    envs = np.stack([S.light_environment(k, H, row_order="top_first", dtype=np.float64)
                     for k in range(5)])
    c = clamp.positive_offsets(envs, U)
    assert np.all(c > 0)  # the steerable lights do have negative lobes
    shifted = np.stack([clamp.offset_environment(e, ck, U) for e, ck in zip(envs, c)])
    assert shifted.min() >= -1e-12
    rng = np.random.default_rng(0)
    R = rng.uniform(0, 1, (30, U.size))
    bake = lambda env: R @ env.ravel()  # noqa: E731
    rec = clamp.remove_offsets(np.stack([bake(e) for e in shifted]), bake(U), c)
    direct = np.stack([bake(e) for e in envs])
    assert np.allclose(rec, direct, rtol=1e-10, atol=1e-10 * np.abs(direct).max())


def test_offsets_single_and_margin():
    env = np.array([[-0.5, 1.0], [0.0, 0.0]])
    assert clamp.positive_offsets(env) == 0.5
    assert clamp.positive_offsets(env, margin=0.1) == pytest.approx(0.55)
    assert clamp.positive_offsets(np.ones((2, 2))) == 0.0


def test_offset_impossible_where_uniform_is_zero():
    with pytest.raises(ValueError, match="uniform light is zero"):
        clamp.positive_offsets(np.array([[-1.0, 0.0]]), np.array([[0.0, 1.0]]))


def test_clamp_steered():
    img = np.array([-1.0, 0.0, 2.5], dtype=np.float32)
    out = clamp.clamp_steered(img)
    assert out.dtype == np.float32 and np.array_equal(out, [0.0, 0.0, 2.5])


def test_steered_light_needs_clamp_somewhere():
    b = sb.paper_basis()
    d = hs.equirect_pixel_directions(32, 64, row_order="top_first")
    L = sb.evaluate_light(b, d, [0.2, -0.1])
    assert L.min() < 0 and clamp.clamp_steered(L).min() == 0
