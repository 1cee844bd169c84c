"""Sampled closure normals (lt_addon/rays/normal_samples.py): the set's cosine is the mean of
the one-normal cosine (lt_addon/rays/shading.py, checked against Cycles' bake) over the samples,
for both bump terminator terms; subsets and sub-samples keep their texels' samples."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import normal_samples as ns
from relightable_textures.lt_addon.rays.footprint import TRIES
from relightable_textures.lt_addon.rays.shading import (ShadingPoints, cosine, cosine_at,
                                                        facing, facing_at)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _normals(R=8, K=22, seed=3):
    """(K, R, R, 3) normals (the centre's first): tilted up to ~80 degrees in a band (the
    'mortar'), flat with a slight tilt elsewhere; the texel (0, 0) uncovered (zeros)."""
    rng = np.random.default_rng(seed)
    n = np.zeros((K, R, R, 3))
    n[..., 2] = 1.0
    n[..., 0] = 0.05
    band = rng.random((K, R, R)) < 0.3
    band[:, :, : R // 2] = False
    n[band, 0] = rng.normal(0, 3.0, band.sum())
    n[band, 1] = rng.normal(0, 3.0, band.sum())
    n = _unit(n)
    n[:, 0, 0] = 0.0
    return n


def _sampler(stack):
    smp = ns.Sampler(len(stack))
    for img in stack:
        smp.add(img)
    K = len(stack)
    return smp.done(ns.offsets(ns.LATTICE if K == 22 else (K - 1, 3), 0.5))


@pytest.mark.parametrize("bump,corr", [("conty", True), ("conty", False), ("chiang", True)])
def test_the_sets_cosine_is_the_mean_of_the_one_normal_cosine(bump, corr):
    R, K = 8, 22
    stack = _normals(R, K)
    tn = _sampler(stack)
    assert tn.samples.dtype == np.float16 and tn.count == K
    texel = np.arange(1, R * R)                        # every covered texel, one point each
    P = len(texel)
    N = np.tile([0.0, 0.0, 1.0], (P, 1))
    correction = np.full(P, corr)
    pts = ShadingPoints(np.zeros((P, 3)), N, N, tn.mean.reshape(-1, 3)[texel], np.zeros((P, 3)),
                        np.zeros(P), bump, correction)
    pts.normal_set = tn.normal_set(texel, N, correction, bump)
    varying = np.isin(texel, tn.pixels)
    assert varying.any() and not varying.all()         # the band's texels, not the flat ones
    # the horizons' terminator edges reach past the mean's by the samples' spread alone
    from relightable_textures.lt_addon.rays.horizon import _spread

    spread = _spread(pts)
    assert np.all(spread[~varying] == 0) and np.all(spread[varying] > 0)
    # (the last: grazing a horizontal plane, where the masking term of a material without the
    # bump map correction is still 1)
    for L in _unit(np.array([[0.8, 0.3, 0.05], [0.3, -0.6, 0.7], [-0.1, 0.2, 0.97],
                             [0.6, 0.8, 0.0]])):
        got = cosine(pts, L)
        want = np.empty(P)
        for j, t in enumerate(texel):
            if varying[j]:     # the one-normal cosine (float16-stored normals) over the lattice
                sub = _unit(stack[1:, t // R, t % R].astype(np.float16).astype(np.float64))
                k = K - 1      # (all on the triangle: the centre does not count)
                one = ShadingPoints(np.zeros((k, 3)), np.tile(N[j], (k, 1)), np.tile(N[j], (k, 1)),
                                    sub, np.zeros((k, 3)), np.zeros(k), bump, np.full(k, corr))
                want[j] = cosine(one, L).mean()
            else:
                one = pts.subset([j])
                one.normal_set = None
                want[j] = cosine(one, L)[0]
        np.testing.assert_allclose(got, want, atol=2e-5)
        np.testing.assert_allclose(cosine(pts, L, slice(5, 40)), want[5:40], atol=2e-5)
        rows = np.array([40, 3, 17, 17, 60])
        np.testing.assert_allclose(cosine_at(pts, L, rows), want[rows], atol=2e-5)
        sub = pts.subset(rows)
        np.testing.assert_allclose(cosine(sub, L), want[rows], atol=2e-5)
        # the horizons' test of which directions count never leaves out a lit point
        assert np.all(facing(pts, L)[got > 0])
        assert np.array_equal(facing_at(pts, L, rows), facing(pts, L)[rows])
        # a few points asked of a new direction are made alone, the same values
        pts.normal_set.shared.cache.clear()
        np.testing.assert_allclose(cosine_at(pts, L, rows[:2]), want[rows[:2]], atol=2e-5)


def test_flat_texels_keep_their_mean_and_samples_past_an_island_take_the_centres():
    R, K = 4, 6
    stack = np.zeros((K, R, R, 3))
    stack[..., 2] = 1.0
    stack[:, 0, 0] = 0.0                               # uncovered
    stack[1:, 1, 1] = _unit(np.array([[0.3, 0, 1], [-0.3, 0, 1], [0, 0.3, 1], [0, -0.3, 1],
                                      [0, 0, 1.0]]))
    stack[0, 1, 1] = _unit(np.array([0.5, 0.5, 1.0]))  # the centre: not in the mean
    stack[3, 2, 2] = 0.0                               # one offset past the island's margin
    tn = _sampler(stack)
    assert list(tn.pixels) == [R + 1]                  # only (1, 1) varies
    np.testing.assert_allclose(tn.mean[1, 1], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(tn.mean[2, 2], [0, 0, 1], atol=1e-12)
    assert not tn.mean[0, 0].any()


def test_the_lattice_and_its_memory():
    off = ns.offsets(ns.LATTICE, 0.5)
    assert off.shape == (22, 2) and np.abs(off).max() < 0.25
    assert not off[0].any()                            # the centre first, then the lattice
    lat = off[1:]
    assert len(np.unique(lat[:, 0])) == 21 and len(np.unique(lat[:, 1])) == 21   # stratified
    np.testing.assert_allclose(lat.mean(axis=0), 0.0, atol=1e-12)
    assert ns.lattice_for(128 ** 2) == ns.LATTICE
    assert ns.lattice_for(4096 ** 2) == (1, 0)
    for texels in (512 ** 2, 1024 ** 2, 3 * 1024 ** 2, 2048 ** 2):
        n = ns.lattice_for(texels)[0]
        assert n == 1 or (n + 1) * texels * ns.NORMAL_BYTES <= ns.MEMORY
    assert ns.lattice_for(1024 ** 2) == ns.LATTICE and ns.lattice_for(2048 ** 2)[0] >= 8
    assert ns.offsets((1, 0), 1.0).tolist() == [[0.0, 0.0]]


def test_samples_off_the_centres_triangle_do_not_count():
    """A texel on a triangle's edge: Cycles' jitter stays on the centre's triangle (it keeps
    the centre after 10 misses), so the normals baked past the edge (the moved map reads the
    neighbour there) are left out."""
    off = np.array([[0.0, 0.0], [0.2, 0.0], [-0.2, 0.0]])  # texels; samples at centre - off
    tri = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])
    R = 10
    centre = np.array([[0.01, 0.5]])                        # 0.1 texel right of the edge u = 0
    W = ns.weights(tri, centre, off, R)
    assert (W > 0).tolist() == [[True, False, True]]        # u = 0.01 - 0.02 is off it
    n = np.array([[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.6, 0.8]]])   # centre, off, on
    N = np.array([[0.0, 0.0, 1.0]])
    shared = ns._Shared(n.astype(np.float16), N, None, "conty", lambda e: W[e])
    w0 = 0.5 ** TRIES                                       # half the lattice on: the centre
    np.testing.assert_allclose(shared.w, [[w0, 0.0, 1.0 - w0]], atol=1e-7)
    L = _unit(np.array([0.6, 0.0, 0.8]))
    want = w0 * 0.8 + (1 - w0) * 0.64 * ns._Shared(
        n[:, 2:].astype(np.float16), N, None, "conty").cosines(L)[0] / 0.64
    np.testing.assert_allclose(shared.cosines(L), [want], atol=1e-5)
    # none of the lattice on the triangle (a sliver): the centre alone
    none = ns._Shared(n.astype(np.float16), N, None, "conty",
                      lambda e: ns.weights(tri, np.array([[-0.05, 0.5]]), off, R)[e])
    np.testing.assert_allclose(none.w, [[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(none.mean, N, atol=1e-6)
