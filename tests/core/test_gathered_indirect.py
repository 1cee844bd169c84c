"""The texture bake's gathered indirect light (lt_addon/transport/gathered_indirect.py) against
exact answers: a closed box's furnace (every ray meets a lit inner wall, so one bounce is
albedo x T and two are albedo^2 x T, with no noise), the view factor of a square seen from
below (analytic), and the hit-to-texel mapping."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import engine
from relightable_textures.lt_addon.rays.shading import shading_points
from relightable_textures.lt_addon.rays.texels import texel_samples
from relightable_textures.lt_addon.transport import gathered_indirect as gi

needs_engine = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")


def _quad(corners, tile):
    """Two triangles of a quad (4 corners, counter-clockwise seen from its front) with the UV
    rectangle ``tile`` = (u0, v0, u1, v1)."""
    u0, v0, u1, v1 = tile
    uv = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]])
    return np.asarray(corners, np.float64), [(0, 1, 2), (0, 2, 3)], uv


def _mesh(quads):
    V, T, UV = [], [], []
    for corners, tris, uv in quads:
        base = len(V)
        V.extend(corners)
        for t in tris:
            T.append([base + i for i in t])
            UV.append(uv[list(t)])
    return np.array(V), np.array(T), np.array(UV)


def _box():
    """The inside of the unit cube: six faces whose fronts look inwards, each on its own tile
    of a 3 x 2 UV atlas (every texel of every side divisible by 6 covered)."""
    c = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    quads = []
    for i, f in enumerate(faces):
        u, v = i % 3, i // 3
        quads.append(_quad(c[list(f[::-1])], (u / 3, v / 2, (u + 1) / 3, (v + 1) / 2)))
    return _mesh(quads)


def _points(V, T, UV, side):
    smp = texel_samples(UV, side)
    n = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pts = shading_points(V, T, np.repeat(n[:, None], 3, axis=1), np.zeros(len(T), bool),
                         smp.triangle, smp.bary, cutoff=0.0)
    return smp, pts


def _gather(V, T, UV, receiver, pts, smp, t_side, g_side, rays, seed=1):
    occ = engine.Occluder(V, T)
    gmap = np.full(g_side * g_side, -1, np.int64)
    gmap[smp.texel] = np.arange(smp.size)
    return gi.gather(occ.nearest, pts.P + 1e-6 * pts.Ng, pts.N, pts.Ng, rays, seed, V, T,
                     receiver, UV, t_side, [0], g_side, [gmap])


@needs_engine
def test_a_closed_box_is_a_furnace_one_and_two_bounces_exactly():
    V, T, UV = _box()
    G_SIDE, T_SIDE = 6, 12
    smp, pts = _points(V, T, UV, G_SIDE)
    assert smp.size == G_SIDE * G_SIDE            # every gather texel covered
    g = _gather(V, T, UV, np.zeros(len(T), np.int64), pts, smp, T_SIDE, G_SIDE, rays=64)
    # every ray met an inner wall's front side, on a covered texel of both grids
    assert g.missed == g.other == g.back == 0 and len(g.point) == 64 * smp.size
    assert (g.target >= 0).all()
    t = np.array([0.3, 1.0, 0.05])                # three directions' (uniform) direct light
    Trows = np.repeat(t[:, None], T_SIDE * T_SIDE, axis=1).astype(np.float32)
    rho = np.array([0.2, 0.5, 0.8])
    alb = np.tile(rho, (T_SIDE * T_SIDE, 1))
    one = gi.indirect(g, Trows, alb, bounces=1)
    two = gi.indirect(g, Trows, alb, bounces=2)
    assert one.shape == (3, 3, smp.size)
    want1 = rho[:, None, None] * t[None, :, None]
    np.testing.assert_allclose(one, np.broadcast_to(want1, one.shape), rtol=1e-5)
    np.testing.assert_allclose(two, np.broadcast_to(want1 * (1 + rho[:, None, None]),
                                                    two.shape), rtol=1e-5)


def _corner_factor(a, b, c):
    """View factor from a point to an a x b rectangle parallel to its plane at height c, the
    point below one corner (the differential-area-to-rectangle formula)."""
    A, B = a / c, b / c
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


@needs_engine
@pytest.mark.parametrize("ceiling_receives", [True, False])
def test_a_lit_square_overhead_gives_its_view_factor(ceiling_receives):
    """A floor point under the centre of a 2 x 2 ceiling 1 above: one bounce is albedo x T x F,
    F the analytic view factor (0.5541); a ceiling that is not a receiver adds nothing and is
    counted as another object."""
    floor = _quad([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], (0, 0, 0.5, 1))
    ceiling = _quad([[-1, -1, 1], [-1, 1, 1], [1, 1, 1], [1, -1, 1]], (0.5, 0, 1, 1))
    V, T, UV = _mesh([floor, ceiling])
    F = 4 * _corner_factor(1.0, 1.0, 1.0)
    assert abs(F - 0.5541) < 1e-4
    K = 4096
    point = np.array([[0.0, 0.0, 0.0]])
    up = np.array([[0.0, 0.0, 1.0]])
    receiver = np.array([0, 0, 0, 0]) if ceiling_receives else np.array([0, 0, -1, -1])
    occ = engine.Occluder(V, T)
    g = gi.gather(occ.nearest, point + 1e-6 * up, up, up, K, 3, V, T, receiver, UV, 8, [0], 8,
                  [np.full(64, -1, np.int64)])
    rows = np.zeros((1, 64), np.float32)
    rows[0, np.arange(64) % 8 >= 4] = 0.7          # the ceiling's half of the atlas is lit
    alb = np.full((64, 3), 0.5)
    got = gi.indirect(g, rows, alb, bounces=2)[:, 0, 0]
    # binomial noise of K rays bounds the error; the Fibonacci lattice does better
    tol = 3 * np.sqrt(F * (1 - F) / K)
    if ceiling_receives:
        np.testing.assert_allclose(got, 0.5 * 0.7 * F, atol=0.5 * 0.7 * tol)
        assert g.other == 0 and abs(len(g.point) / K - F) < tol
    else:
        assert np.all(got == 0) and abs(g.other / K - F) < tol and len(g.point) == 0
    assert g.missed + g.other + g.back + len(g.point) == K


def test_hits_read_the_texel_under_their_uv():
    V = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float)
    T = np.array([[0, 1, 2]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    # the point (0.5, 1.0) of the triangle: barycentrics (0.25, 0.25, 0.5), uv (0.25, 0.5)
    o = np.array([[0.5, 1.0, 1.0]])
    d = np.array([[0.0, 0.0, -1.0]])
    bary = gi.hit_barycentrics(V, T, np.array([0]), o, d, np.array([1.0]))
    np.testing.assert_allclose(bary, [[0.25, 0.25, 0.5]], atol=1e-12)
    at = np.einsum("mc,mcj->mj", bary, uv[None])
    # on a 4 x 4 grid: column 1 (u 0.25..0.5), row 2 (v 0.5..0.75): 2 * 4 + 1
    assert gi.uv_texel(at, 4)[0] == 9
    assert gi.uv_texel(np.array([[1.0, 1.0], [-0.1, 0.0]]), 4).tolist() == [15, 0]


class _Columns:
    """T behind ``columns(lo, hi)`` only (as the bake's stacked stores are read)."""

    def __init__(self, a):
        self.a, self.shape = a, a.shape

    def columns(self, lo, hi):
        return self.a[:, lo:hi]

    def __getitem__(self, key):
        raise AssertionError("the PCA reads T by windows of columns")


@needs_engine
def test_the_randomised_pca_is_the_exact_one_without_forming_the_term(monkeypatch):
    """On the furnace box with T varying over texels and directions: at full rank the
    randomised factors rebuild ``indirect`` exactly; at rank k they keep what an exact SVD of
    the formed term keeps (to 1e-6 of its energy), and say how much."""
    V, T, UV = _box()
    smp, pts = _points(V, T, UV, 6)
    g = _gather(V, T, UV, np.zeros(len(T), np.int64), pts, smp, 12, 6, rays=16)
    rng = np.random.default_rng(5)
    S = 40
    # a few smooth patterns over directions, so a low rank holds most of the term
    basis = rng.random((4, 144))
    Trows = (rng.random((S, 4)) @ basis + 0.01 * rng.random((S, 144))).astype(np.float16)
    alb = rng.uniform(0.2, 0.9, (144, 3))
    full = gi.indirect(g, Trows, alb, bounces=2).astype(np.float64)       # (3, S, P)
    M = full.transpose(1, 0, 2).reshape(S, -1)
    Vk, Uk, kept = gi.indirect_pca(g, Trows, alb, bounces=2, components=S, oversample=0,
                                   chunk=7, measure=True, window=7)    # T read by 21 windows
    rebuilt = Vk.astype(np.float64) @ Uk.reshape(len(Uk), -1).astype(np.float64)
    assert np.abs(rebuilt - M).max() < 1e-5 * np.abs(M).max() and abs(kept - 1) < 1e-6
    sv = np.linalg.svd(M, compute_uv=False)
    exact = float(np.sum(sv[:4] ** 2) / np.sum(sv ** 2))
    Vk, Uk, kept = gi.indirect_pca(g, Trows, alb, bounces=2, components=4, chunk=7,
                                   measure=True)
    # read by windows of texel columns (a stacked reader's columns()), their products gathered
    # a few texels at a time, or whole: the same
    monkeypatch.setattr(gi, "FLUSH_TEXELS", 5)
    Vw, Uw, _ = gi.indirect_pca(g, _Columns(Trows), alb, bounces=2, components=4, window=10)
    np.testing.assert_allclose(Vw @ Uw.reshape(4, -1), Vk @ Uk.reshape(4, -1),
                               atol=1e-5 * np.abs(M).max())
    rebuilt = Vk.astype(np.float64) @ Uk.reshape(4, -1).astype(np.float64)
    got = 1 - np.sum((rebuilt - M) ** 2) / np.sum(M ** 2)
    assert exact > 0.99 and abs(got - exact) < 1e-6 and abs(kept - exact) < 1e-6
    assert gi.indirect_pca(g, Trows, alb, components=4)[2] is None


@needs_engine
def test_the_component_count_grows_to_the_fewest_whose_tail_is_within_the_bound():
    """A term of rank 12 over 40 directions with a spread spectrum: asked for 2 components
    with a 5 % tail, the PCA sketches 2, 4, 8 and 16, and keeps the fewest whose tail in the
    exact SVD of the formed term is within 5 % (the sketch at full rank finds the same
    values); without ``tail`` it keeps the 2 asked; ``most`` caps it."""
    V, T, UV = _box()
    smp, pts = _points(V, T, UV, 6)
    g = _gather(V, T, UV, np.zeros(len(T), np.int64), pts, smp, 12, 6, rays=16)
    rng = np.random.default_rng(7)
    S = 40
    # orthogonal patterns over texels and directions, each 0.7 of the one before (signed: a
    # positive T's mean pattern would hold nearly all of it)
    basis = np.linalg.qr(rng.standard_normal((144, 12)))[0].T
    dirs = np.linalg.qr(rng.standard_normal((S, 12)))[0]
    Trows = (4 * (dirs * 0.7 ** np.arange(12)) @ basis).astype(np.float16)
    alb = rng.uniform(0.2, 0.9, (144, 3))
    M = gi.indirect(g, Trows, alb, bounces=2).astype(np.float64).transpose(1, 0, 2).reshape(S, -1)
    e = np.linalg.svd(M, compute_uv=False) ** 2
    tails = np.sqrt(np.cumsum(e[::-1])[::-1] / e.sum())
    want = int(np.argmax(tails <= 0.05))
    assert 8 < want < 12                           # met only by the fourth sketch (16)
    fig = {}
    Vk, Uk, _ = gi.indirect_pca(g, Trows, alb, bounces=2, components=2, tail=0.05, most=32,
                                figures=fig, oversample=24)
    assert fig["sketches"] == [2, 4, 8, 16] and fig["components"] == want == Vk.shape[1] \
        == Uk.shape[0]
    assert fig["tail"] == pytest.approx(tails[want], abs=2e-3) and fig["tail"] <= 0.05
    assert gi.indirect_pca(g, Trows, alb, bounces=2, components=2)[0].shape[1] == 2
    fig = {}
    gi.indirect_pca(g, Trows, alb, bounces=2, components=2, tail=0.05, most=4, figures=fig)
    assert fig["sketches"] == [2, 4] and fig["components"] == 4 and fig["tail"] > 0.05
    # a grid of 4 points holds a term of rank 3 x 4 at most: the sketches stop there (they
    # raised on reshaping the images' QR, 3 P < m, before they were capped by it)
    smp2, pts2 = _points(V, T, UV, 2)
    g2 = _gather(V, T, UV, np.zeros(len(T), np.int64), pts2, smp2, 12, 2, rays=16)
    P = int(g2.points)
    assert 3 * P < 16 + 8
    fig = {}
    Vs, Us, _ = gi.indirect_pca(g2, Trows, alb, bounces=2, components=16, tail=1e-9, most=64,
                                figures=fig)
    assert Vs.shape[1] == Us.shape[0] == fig["components"] <= 3 * P
