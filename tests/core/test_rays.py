"""The bpy-free ray core (lt_addon/rays) against independent computations: texel sample points
against the UV point they must reproduce, occlusion against analytic shadows, Cycles' terminator
lift against the sphere it approximates, and the direct transport against cos/pi."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import engine
from relightable_textures.lt_addon.rays.direct import direct_rows
from relightable_textures.lt_addon.rays.shading import (bump_correction, shading_points,
                                                        shadow_origins, smooth_surface_lift)
from relightable_textures.lt_addon.rays.texels import NUDGE, extend_margin, texel_samples

needs_engine = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")


def test_texel_points_are_the_nudged_texel_centres():
    rng = np.random.default_rng(3)
    tris = rng.random((40, 3, 2))
    R = 24
    smp = texel_samples(tris, R)
    assert smp.size > 100
    row, col = np.divmod(smp.texel, R)
    want = np.stack([(col + 0.5 + NUDGE[0]) / R, (row + 0.5 + NUDGE[1]) / R], axis=1)
    got = np.einsum("pk,pkj->pj", smp.bary, tris[smp.triangle])
    assert np.abs(got - want).max() < 1e-12
    assert (smp.bary >= -1e-12).all() and np.allclose(smp.bary.sum(1), 1)
    # brute force: every texel centre inside some triangle is covered, by the last such one
    for t in range(R * R):
        r, c = divmod(t, R)
        p = np.array([(c + 0.5 + NUDGE[0]) / R, (r + 0.5 + NUDGE[1]) / R])
        inside = []
        for f, (a, b, cc) in enumerate(tris):
            m = np.column_stack([b - a, cc - a])
            if abs(np.linalg.det(m)) < 1e-14:
                continue
            u, v = np.linalg.solve(m, p - a)
            if u >= -1e-12 and v >= -1e-12 and u + v <= 1 + 1e-12:
                inside.append(f)
        if inside:
            k = np.searchsorted(smp.texel, t)
            assert smp.texel[k] == t and smp.triangle[k] == inside[-1]
        else:
            assert t not in set(smp.texel.tolist())


def test_texel_batches_give_the_same_answer(monkeypatch):
    from relightable_textures.lt_addon.rays import texels

    rng = np.random.default_rng(4)
    tris = rng.random((60, 3, 2))
    whole = texel_samples(tris, 32)
    monkeypatch.setattr(texels, "CANDIDATES", 50)
    parts = texel_samples(tris, 32)
    assert np.array_equal(whole.texel, parts.texel)
    assert np.array_equal(whole.triangle, parts.triangle)


def _extend_reference(img, covered, passes):
    """Blender's IMB_filter_extend, pixel by pixel (the C loop, transcribed)."""
    img = img.copy()
    mask = covered.copy()
    H, W = img.shape
    w = {(-1, -1): 1, (-1, 0): 2, (-1, 1): 1, (0, -1): 2, (0, 1): 2, (1, -1): 1, (1, 0): 2,
         (1, 1): 1}
    for _ in range(passes):
        out, newmask = img.copy(), mask.copy()
        for y in range(H):
            for x in range(W):
                if mask[y, x]:
                    continue
                if not any(0 <= y + dy < H and 0 <= x + dx < W and mask[y + dy, x + dx]
                           for dy, dx in ((0, -1), (0, 1), (-1, 0), (1, 0))):
                    continue
                acc = tot = 0.0
                for (dy, dx), wt in w.items():
                    if 0 <= y + dy < H and 0 <= x + dx < W and mask[y + dy, x + dx]:
                        acc += wt * img[y + dy, x + dx]
                        tot += wt
                out[y, x], newmask[y, x] = acc / tot, True
        img, mask = out, newmask
    return img, mask


def test_extend_margin_is_blenders_filter_extend():
    rng = np.random.default_rng(6)
    covered = np.zeros((14, 15), bool)
    covered[3:7, 2:6] = True
    covered[9:12, 8:14] = True
    covered[0, 14] = True                                 # at the image's corner
    img = np.where(covered, rng.random(covered.shape), 0.0)
    want, mask = _extend_reference(img, covered, 3)
    dst, op = extend_margin(covered, 3)
    assert np.array_equal(np.sort(dst), np.nonzero((mask & ~covered).ravel())[0])
    got = op @ img.ravel()[np.nonzero(covered.ravel())[0]]
    assert np.abs(got - want.ravel()[dst]).max() < 1e-12


@needs_engine
def test_occluder_casts_the_analytic_shadow_of_a_square():
    # a 1 m square at z = 1 over points on z = 0; sun from elevation 45 degrees along +x
    V = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    occ = engine.Occluder(V, [[0, 1, 2], [0, 2, 3]], threads=2)
    xs = np.linspace(-1.5, 1.5, 61) + 0.0123
    P = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)
    O = np.column_stack([P, np.zeros(len(P))])
    L = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    hit = occ.occluded(O, L)
    # the shadow is the square shifted by -1 m in x (height 1, 45 degrees)
    want = (P[:, 0] > -1) & (P[:, 0] < 0) & (P[:, 1] > 0) & (P[:, 1] < 1)
    assert np.array_equal(hit, want)
    assert occ.rays == len(O)


@needs_engine
def test_nearest_finds_the_first_of_two_stacked_squares():
    """Rays up from z = 0 through two unit squares (z = 1, triangles 0-1; z = 2.5, triangles
    2-3) meet the lower one first at distance 1/cos; rays aimed past both meet nothing. Analytic
    triangle and distance, on a batch large enough to be split over threads, and with one
    direction for all rays."""
    V = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
                  [0, 0, 2.5], [1, 0, 2.5], [1, 1, 2.5], [0, 1, 2.5]], float)
    T = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]
    occ = engine.Occluder(V, T, threads=2)
    rng = np.random.default_rng(3)
    P = rng.uniform(-0.5, 1.5, (5000, 2))
    O = np.column_stack([P, np.zeros(len(P))])
    L = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
    tri, dist = occ.nearest(O, np.broadcast_to(L, O.shape))
    at1 = P + L[:2] / L[2] * 1.0          # where each ray crosses z = 1 and z = 2.5
    at2 = P + L[:2] / L[2] * 2.5
    inside = lambda q: (q[:, 0] > 0) & (q[:, 0] < 1) & (q[:, 1] > 0) & (q[:, 1] < 1)
    lower, upper = inside(at1), inside(at2) & ~inside(at1)
    lower_tri = np.where(at1[:, 0] > at1[:, 1], 0, 1)     # the diagonal splits the square
    upper_tri = np.where(at2[:, 0] > at2[:, 1], 2, 3)
    away = np.abs(at1[:, 0] - at1[:, 1]) > 1e-4   # not on a diagonal (either triangle)
    assert np.array_equal(tri[lower & away], lower_tri[lower & away])
    assert np.array_equal(tri[upper & away], upper_tri[upper & away])
    assert np.all(tri[~lower & ~upper] == -1) and np.all(dist[tri < 0] == 0)
    np.testing.assert_allclose(dist[lower], 1.0 / L[2], rtol=1e-6)
    np.testing.assert_allclose(dist[upper], 2.5 / L[2], rtol=1e-6)
    one = occ.nearest(O, L)                # one direction for all: the same answer
    assert np.array_equal(one[0], tri) and np.array_equal(one[1], dist)
    assert lower.sum() > 1000 and upper.sum() > 200   # both cases are exercised


def test_available_says_why_without_embree(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "embreex", None)
    ok, why = engine.available()
    assert not ok and "embreex cannot be imported" in why


def _sphere_patch():
    """A triangle on the unit sphere with its vertex normals (the positions)."""
    V = np.array([[0.2, 0.1, 0.0], [-0.1, 0.25, 0.0], [0.0, -0.2, 0.0]])
    V[:, 2] = np.sqrt(1 - (V[:, :2] ** 2).sum(1))
    return V, V.copy()


def test_terminator_lift_moves_a_flat_point_towards_the_smooth_surface():
    V, N = _sphere_patch()
    w = np.array([[1 / 3, 1 / 3, 1 / 3], [0.6, 0.2, 0.2], [0.1, 0.45, 0.45]])
    P = w @ V
    n = w @ N
    Ng = np.cross(V[1] - V[0], V[2] - V[0])
    Ng /= np.linalg.norm(Ng)
    lift = smooth_surface_lift(np.repeat(V[None], 3, 0), np.repeat(N[None], 3, 0), w, n,
                               np.repeat(Ng[None], 3, 0))
    before = np.abs(np.linalg.norm(P, axis=1) - 1)
    after = np.abs(np.linalg.norm(P + lift, axis=1) - 1)
    assert (before > 1e-3).all() and (after < before).all()
    assert (np.einsum("pj,pj->p", lift, n) > 0).all()        # outwards, along the normal
    # a flat triangle (normals = Ng) is not lifted
    flat = smooth_surface_lift(np.repeat(V[None], 3, 0), np.repeat(np.tile(Ng, (3, 1))[None], 3, 0),
                               w, np.tile(Ng, (3, 1)), np.repeat(Ng[None], 3, 0))
    assert np.abs(flat).max() < 1e-12


def test_shadow_origins_follow_cycles_rules():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    tilted = np.array([[0.3, 0, 1], [0, 0.3, 1], [-0.2, -0.2, 1]], float)
    tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
    pts = shading_points(V, [[0, 1, 2]], tilted[None], [True], np.zeros(2, int),
                         [[0.5, 0.25, 0.25], [0.2, 0.4, 0.4]], cutoff=0.1)
    high = np.array([0.0, 0.0, 1.0])                   # far from the terminator: no lift
    o = shadow_origins(pts, high)
    assert np.allclose(o[:, :2], pts.P[:, :2], atol=1e-6) and (o[:, 2] > 0).all()
    assert (o[:, 2] < 1e-4).all()
    grazing = np.array([np.cos(np.radians(2)), 0.0, np.sin(np.radians(2))])
    og = shadow_origins(pts, grazing)                  # near the terminator: lifted along n
    assert (og[:, 2] - pts.P[:, 2] > 1e-3).all()
    flat = shading_points(V, [[0, 1, 2]], tilted[None], [False], np.zeros(2, int),
                          [[0.5, 0.25, 0.25], [0.2, 0.4, 0.4]], cutoff=0.1)
    assert (shadow_origins(flat, grazing)[:, 2] < 1e-4).all()   # flat faces: never lifted


def test_a_points_origin_does_not_depend_on_the_points_asked_with_it():
    """Chunking points (horizons, ray budgets) and asking only the lit ones must not move any
    origin by a bit: a BLAS matrix-vector product rounds a row by its vector lane, and with it
    2 of 3 random subsets of the statue's points differed in the last bit."""
    rng = np.random.default_rng(5)
    V = rng.normal(size=(300, 3))
    tris = rng.integers(0, 300, (400, 3))
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2])
                & (tris[:, 0] != tris[:, 2])]
    corner = rng.normal(size=(len(tris), 3, 3))
    corner /= np.linalg.norm(corner, axis=2, keepdims=True)
    P = 4000
    tri, bary = rng.integers(0, len(tris), P), rng.dirichlet(np.ones(3), P)
    smooth = rng.random(len(tris)) < 0.7                 # smooth and flat faces mixed
    pts = shading_points(V, tris, corner, smooth, tri, bary, cutoff=0.1)
    for t in range(20):
        L = rng.normal(size=3)
        L[2] *= 0.05 if t % 2 else 1.0                   # half of them near the terminators
        L /= np.linalg.norm(L)
        full = shadow_origins(pts, L)
        idx = np.sort(rng.choice(P, int(rng.integers(1, P)), replace=False))
        a = int(rng.integers(0, P - 1))
        b = int(rng.integers(a + 1, P + 1))
        assert np.array_equal(shadow_origins(pts, L, idx), full[idx])
        assert np.array_equal(shadow_origins(pts, L, slice(a, b)), full[a:b])
        assert np.array_equal(shadow_origins(pts, np.tile(L, (len(idx), 1)), idx), full[idx])


def test_shading_points_by_steps_are_the_whole_set_bit_for_bit(monkeypatch):
    """shading_points works by steps of POINTS_STEP points (its float64 temporaries were the
    peak of a 4096^2 bake); every point is computed alone, so the steps change no bit."""
    from relightable_textures.lt_addon.rays import shading

    rng = np.random.default_rng(9)
    V = rng.normal(size=(200, 3))
    tris = np.array([t for t in rng.integers(0, 200, (300, 3)) if len(set(t)) == 3])
    corner = rng.normal(size=(len(tris), 3, 3))
    corner /= np.linalg.norm(corner, axis=2, keepdims=True)
    tri, bary = rng.integers(0, len(tris), 1000), rng.dirichlet(np.ones(3), 1000)
    smooth = rng.random(len(tris)) < 0.6
    Ns = rng.normal(size=(1000, 3))
    corr = rng.random(len(tris)) < 0.5
    whole = shading_points(V, tris, corner, smooth, tri, bary, cutoff=0.1, Ns=Ns,
                           correction=corr)
    monkeypatch.setattr(shading, "POINTS_STEP", 77)
    steps = shading_points(V, tris, corner, smooth, tri, bary, cutoff=0.1, Ns=Ns,
                           correction=corr)
    for f in ("P", "Ng", "N", "Ns", "lift", "cutoff", "correction"):
        assert np.array_equal(getattr(steps, f), getattr(whole, f)), f
    assert steps.size == 1000 and steps.bump == whole.bump and np.any(whole.lift != 0)
    plain = shading_points(V, tris, corner, smooth, tri, bary, cutoff=0.1)
    assert plain.Ns is plain.N and np.array_equal(plain.N, whole.N)


def test_backfacing_points_flip_both_normals():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)   # winding: Ng = +z
    down = np.tile([0.0, 0.0, -1.0], (3, 1))                 # smooth normals point down
    pts = shading_points(V, [[0, 1, 2]], down[None], [True], [0], [[0.4, 0.3, 0.3]])
    # Cycles views a bake's point along its smooth normal: here from below, so the point is
    # backfacing and both normals flip (a sun from above then falls on the back: cosine 0)
    assert np.allclose(pts.Ng[0], [0, 0, -1]) and np.allclose(pts.N[0], [0, 0, 1])


def test_bump_correction_limits():
    N = np.array([[0.0, 0.0, 1.0]])
    Ns = np.array([[np.sin(0.3), 0.0, np.cos(0.3)]])
    L_up = np.array([0.0, 0.0, 1.0])
    assert bump_correction(N, Ns, L_up, np.array([True]))[0] == pytest.approx(1.0, abs=1e-9)
    below = np.array([1.0, 0.0, -0.05]) / np.linalg.norm([1.0, 0.0, -0.05])   # above Ns only
    assert bump_correction(N, Ns, below, np.array([True]))[0] == 0.0   # other side of N
    grazing = np.array([np.cos(0.05), 0.0, np.sin(0.05)])
    g = bump_correction(N, Ns, grazing, np.array([True]))[0]
    assert 0.0 < g < 1.0
    assert bump_correction(N, Ns, grazing, np.array([False]))[0] == 1.0   # correction off


@needs_engine
def test_direct_rows_are_cos_over_pi_with_the_square_shadow():
    # a floor of two triangles under a square roof
    floor = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    roof = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    V = np.concatenate([floor, roof])
    T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    occ = engine.Occluder(V, T)
    rng = np.random.default_rng(5)
    P = np.column_stack([rng.uniform(-1.9, 1.9, (400, 2)), np.zeros(400)])
    # barycentrics of P in the floor's first triangle where it lies, else the second
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    tri = np.where(P[:, 0] >= P[:, 1], 0, 1)
    bary = np.zeros((400, 3))
    for i, (p, t) in enumerate(zip(P, tri)):
        a, b, c = floor[T[t]]
        u, v = np.linalg.solve(np.column_stack([b - a, c - a])[:2], (p - a)[:2])
        bary[i] = [1 - u - v, u, v]
    pts = shading_points(V, T[:2], np.repeat(up[None, :3], 2, 0), [False, False], tri, bary)
    D = np.array([[0.0, 0.0, 1.0], [np.cos(np.radians(30)), 0.0, np.sin(np.radians(30))]])
    rows = direct_rows(occ, pts, D)
    cos = D[:, 2] / np.pi
    shift = 1.0 / np.tan(np.radians(30))
    for s, dx in enumerate((0.0, shift)):
        shadow = ((P[:, 0] + dx > 0) & (P[:, 0] + dx < 1) & (P[:, 1] > 0) & (P[:, 1] < 1))
        want = np.where(shadow, 0.0, cos[s])
        assert np.abs(rows[s] - want).max() < 1e-6
        assert shadow.sum() > 5
    # by blocks of points, into a reused buffer holding other values: the same bits
    from relightable_textures.lt_addon.rays import direct as direct_mod

    old_block = direct_mod.POINT_BLOCK
    try:
        direct_mod.POINT_BLOCK = 64
        buf = np.full((3, 400), 7.0, np.float32)
        blocked = direct_rows(occ, pts, D, buf)
    finally:
        direct_mod.POINT_BLOCK = old_block
    assert blocked.base is buf and np.array_equal(blocked, rows) and np.all(buf[2] == 7.0)
    # with closure normals (a normal map) on some points: their bump terms, block by block
    Ns = np.tile([0.0, 0.0, 1.0], (400, 1))
    Ns[::3] = [0.3, -0.2, 0.93]
    mapped = shading_points(V, T[:2], np.repeat(up[None, :3], 2, 0), [False, False], tri,
                            bary, Ns=Ns)
    assert mapped.mapped() is not None and len(mapped.mapped()) > 100
    whole = direct_rows(occ, mapped, D)
    try:
        direct_mod.POINT_BLOCK = 64
        assert np.array_equal(direct_rows(occ, mapped, D), whole)
    finally:
        direct_mod.POINT_BLOCK = old_block
    assert not np.array_equal(whole, rows)
    # cast while the next rays are set up (occluded_async) or each call waited for: the same
    # rows, also by blocks (several calls in flight one after the other)
    class Waiting:
        occluded = occ.occluded
    assert np.array_equal(direct_rows(Waiting(), mapped, D), whole)
    try:
        direct_mod.POINT_BLOCK = 64
        assert np.array_equal(direct_rows(Waiting(), pts, D), rows)
    finally:
        direct_mod.POINT_BLOCK = old_block


def test_rays_cast_from_the_dispatcher_use_the_worker_threads_from_the_first_call():
    """A fresh engine whose first rays come through occluded_async (the direct rows' pipeline)
    starts its worker pool on the dispatcher's thread and keeps both for the next calls
    (stopping the dispatcher there broke the second direction); the rows are the waited
    calls' bit for bit, with calls big enough to be shared among the workers."""
    floor = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    roof = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    V = np.concatenate([floor, roof])
    n = 5000
    rng = np.random.default_rng(9)
    u, v = rng.uniform(0, 1, (2, n))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    bary = np.column_stack([1 - u - v, u, v])
    up = np.tile([0.0, 0.0, 1.0], (2, 3, 1))
    pts = shading_points(V, T[:2], up, [False, False], np.zeros(n, int), bary)
    D = np.array([[np.cos(np.radians(a)), 0.3, np.sin(np.radians(a))] for a in (20, 35, 50)])
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    fresh = engine.Occluder(V, T, threads=2)
    first = direct_rows(fresh, pts, D)
    again = direct_rows(fresh, pts, D)

    class Waiting:
        occluded = engine.Occluder(V, T, threads=2).occluded
    assert np.array_equal(first, again) and np.array_equal(first, direct_rows(Waiting(), pts, D))
    assert (first == 0).sum() > 50 and fresh.rays >= 2 * 3 * n * 0.9
    fresh.close()
    assert np.array_equal(direct_rows(fresh, pts, D), first)     # started again after close


def test_extend_margin_stays_sparse_at_1024():
    """The margin operator of a 1024^2 texture is built sparse (a row assignment that
    densified it asked for 38.6 GiB on the statue at 1024^2 and ended the bake): each margin
    texel reads at most the 8-neighbourhoods of its margin passes."""
    R = 1024
    y, x = np.mgrid[0:R, 0:R]
    cov = ((x - 300) ** 2 + (y - 500) ** 2 < 250 ** 2) | ((x > 600) & (x < 1000) & (y > 100)
                                                        & (y < 900))
    dst, op = extend_margin(cov, 4)
    assert op.shape == (dst.size, int(cov.sum())) and dst.size > 10000
    assert op.nnz < 10 * dst.size
    np.testing.assert_allclose(np.asarray(op.sum(axis=1)).ravel(), 1.0, rtol=1e-12)
