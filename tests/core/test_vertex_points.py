"""Cycles' vertex-bake shading points (lt_addon/rays/vertex_points.py), against independent
computations: the first triangle of each corner, the point moved towards the triangle's centre,
and the per-vertex mean of the corners' direct light under an analytic shadow."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import engine
from relightable_textures.lt_addon.rays.vertex_points import (POSITION_OFFSET, first_triangles,
                                                              nudged_barycentrics,
                                                              vertex_bake_points, vertex_rows)

needs_engine = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")


def test_each_corner_takes_the_first_triangle_that_holds_it():
    # a quad's corners 0..3 split 0-1-2 / 0-2-3, then a second quad 4..7 split 4-5-7 / 5-6-7
    loops = [[0, 1, 2], [0, 2, 3], [4, 5, 7], [5, 6, 7]]
    tri, slot = first_triangles(loops)
    assert tri.tolist() == [0, 0, 0, 1, 2, 2, 3, 2]
    assert slot.tolist() == [0, 1, 2, 2, 0, 1, 1, 2]


@pytest.mark.parametrize("scale", [1.0, 7.0, 1e-3])
def test_the_point_moves_towards_the_centre_by_cycles_step(scale):
    """The moved point is ``min(|c - P|, 1e-4 max(1, max|P|))`` from the vertex towards the
    centre ``c``: the barycentric point of the returned weights, recomputed in float64."""
    rng = np.random.default_rng(1)
    T = rng.normal(size=(200, 3, 3)) * scale + rng.normal(size=(200, 1, 3)) * 4.0
    w = nudged_barycentrics(T)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-6)
    got = np.einsum("pk,pkj->pj", w, T)
    P, c = T[:, 0], T.mean(axis=1)
    to_c = c - P
    length = np.linalg.norm(to_c, axis=1)
    step = np.minimum(length, np.maximum(np.abs(P).max(axis=1), 1.0) * float(POSITION_OFFSET))
    want = P + to_c / length[:, None] * step[:, None]
    # float32 as in Cycles: the error is float32 rounding of coordinates of size |P| (where
    # Cycles' clamp of a weight at 1e-5 did not move the point)
    free = np.all(w > 1.01e-5, axis=1)
    assert free.mean() > 0.9
    err = np.linalg.norm(got - want, axis=1) / np.maximum(np.abs(P).max(axis=1), 1.0)
    assert err[free].max() < 2e-6, err[free].max()
    assert np.all(w >= 1e-5 - 1e-9)          # no weight below Cycles' clamp


def test_a_degenerate_triangle_gives_cycles_fallback():
    T = np.array([[[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]])   # collinear: no plane
    np.testing.assert_array_equal(nudged_barycentrics(T), [[0.0, 0.0, 1.0]])


@needs_engine
def test_vertex_rows_average_the_corners_under_a_square_shadow():
    """A 4 x 4 grid of unit quads on z = 0 under a square plate at z = 1 lit from straight
    above: a vertex's corners lie 1e-4 inside their faces, so a vertex on the shadow's edge is
    lit by the share of its corners outside the square; inside 0, outside 1 (cosine 1)."""
    n = 5
    xs = np.arange(n, dtype=float)
    V = np.stack([*np.meshgrid(xs, xs, indexing="ij"), np.zeros((n, n))], -1).reshape(-1, 3)
    quads = [(i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1)
             for i in range(n - 1) for j in range(n - 1)]
    tris, loops, corner_v = [], [], []
    for q in quads:                       # corners numbered per quad, as a mesh's loops
        base = len(corner_v)
        corner_v += list(q)
        tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        loops += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    normals = np.tile([0.0, 0.0, 1.0], (len(corner_v), 1))
    pts, corner = vertex_bake_points(V, tris, loops, normals, np.zeros(len(tris), bool))
    plate = np.array([[0.5, 0.5, 1], [2.5, 0.5, 1], [2.5, 2.5, 1], [0.5, 2.5, 1]]) + [1, 1, 0]
    occ = engine.Occluder(plate, [[0, 1, 2], [0, 2, 3]])
    rows = vertex_rows(occ, pts, np.asarray(corner_v)[corner], len(V), [[0.0, 0.0, 1.0]])
    shadow = (V[:, 0] > 1.5) & (V[:, 0] < 3.5) & (V[:, 1] > 1.5) & (V[:, 1] < 3.5)
    np.testing.assert_allclose(rows[0], np.where(shadow, 0.0, 1.0), atol=1e-6)
    # a plate edge through the vertices' row x = 2 halves them: move it onto that row
    occ = engine.Occluder(plate - [0.5, 0, 0], [[0, 1, 2], [0, 2, 3]])
    rows = vertex_rows(occ, pts, np.asarray(corner_v)[corner], len(V), [[0.0, 0.0, 1.0]])
    on_edge = (V[:, 0] == 1.0) & (V[:, 1] > 1.5) & (V[:, 1] < 3.5)
    np.testing.assert_allclose(rows[0][on_edge], 0.5, atol=1e-6)
