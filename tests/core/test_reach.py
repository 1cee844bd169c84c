"""Where casters can be met (lt_addon/rays/reach.py), against the rays themselves: no ray the
engine finds blocked lies outside the bound, on a floor and on a smooth sphere standing on it;
the boxes hold every triangle and keep the floor apart; and the horizon scan that skips the rays
outside the bound makes the same intervals, bit for bit, with far fewer rays."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import engine, horizon, reach
from relightable_textures.lt_addon.rays.shading import shading_points, shadow_origins
from floor_points import floor_points

needs_engine = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")


def _scene(n=400, seed=2):
    """A 6 m floor, a smooth UV sphere (r 0.5 m) standing on it and a floating roof;
    returns (vertices, triangles, floor points, sphere points)."""
    rng = np.random.default_rng(seed)
    floor = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], float)
    c, r, nu, nv = np.array([0.4, 0.2, 0.5]), 0.5, 24, 12
    th = np.linspace(0, np.pi, nv + 1)[:, None]
    ph = np.linspace(0, 2 * np.pi, nu, endpoint=False)[None]
    unit = np.stack(np.broadcast_arrays(np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph),
                                        np.cos(th)), -1).reshape(-1, 3)
    sphere = c + r * unit
    quads = [(i * nu + j, i * nu + (j + 1) % nu, (i + 1) * nu + (j + 1) % nu, (i + 1) * nu + j)
             for i in range(nv) for j in range(nu)]
    st = np.array([[a, b, cc] for a, b, cc, d in quads] + [[a, cc, d] for a, b, cc, d in quads])
    st = st[(st[:, 0] != st[:, 1]) & (st[:, 1] != st[:, 2]) & (st[:, 0] != st[:, 2])]
    roof = np.array([[-2.5, 1.0, 1.2], [-1.5, 1.0, 1.2], [-1.5, 2.0, 1.4], [-2.5, 2.0, 1.4]])
    V = np.concatenate([floor, sphere, roof])
    o_s, o_r = 4, 4 + len(sphere)
    T = np.concatenate([[[0, 1, 2], [0, 2, 3]], st + o_s,
                        [[o_r, o_r + 1, o_r + 2], [o_r, o_r + 2, o_r + 3]]])
    # floor points: random, some under the sphere and the roof
    P = np.column_stack([rng.uniform(-2.9, 2.9, n), rng.uniform(-2.9, 2.9, n), np.zeros(n)])
    on_floor = floor_points(V, T, P)
    # sphere points: smooth shaded, with Cycles' terminator lift
    corner = (V[st + o_s] - c) / r
    ts = rng.integers(0, len(st), n)
    on_sphere = shading_points(V, st + o_s, corner, np.ones(len(st), bool), ts,
                               rng.dirichlet(np.ones(3), n), cutoff=0.1)
    return V, T, on_floor, on_sphere


def test_the_boxes_hold_every_triangle_and_keep_the_floor_apart():
    V, T, _, _ = _scene(n=10)
    boxes = reach.clusters(V, T, leaves=16)
    assert 2 <= len(boxes) <= 16
    tri = V[T]
    inside = ((tri.min(1)[:, None] >= boxes[None, :, 0] - 1e-6)
              & (tri.max(1)[:, None] <= boxes[None, :, 1] + 1e-6)).all(2)
    assert inside.any(1).all()
    # the floor's two triangles share a flat box: no box reaches both the floor's corners and
    # above the roof's lowest point (a mixed box would cover every floor point's sky)
    flat = (boxes[:, 1, 2] - boxes[:, 0, 2] < 1e-9) & (boxes[:, 1, 0] - boxes[:, 0, 0] > 5)
    assert flat.any()


@needs_engine
@pytest.mark.parametrize("where", ["floor", "sphere"])
def test_no_blocked_ray_lies_outside_the_bound(where):
    V, T, on_floor, on_sphere = _scene()
    pts = on_floor if where == "floor" else on_sphere
    occ = engine.Occluder(V, T)
    A = 48
    covered, e_lo, e_hi = horizon._bounds(occ, pts, A)
    rng = np.random.default_rng(7)
    els = np.concatenate([np.radians(horizon.ELEVATIONS), rng.uniform(-1.5, 1.5, 30)])
    blocked_up = unreachable_up = outside = 0
    for a in range(A):
        for e in els:
            L = horizon._dirs(2 * np.pi * a / A, e)
            upward = pts.Ng @ L > horizon.UPWARD
            b = occ.occluded(shadow_origins(pts, L), L.astype(np.float32))
            ok = covered[a] & (e >= e_lo) & (e <= e_hi)
            outside += int(np.sum(b & upward & ~ok))
            blocked_up += int(np.sum(b & upward))
            unreachable_up += int(np.sum(upward & ~ok))
    assert outside == 0
    assert blocked_up > 500                   # the check saw blocked rays on both sides
    if where == "floor":                      # and the bound skips most of the floor's rays
        assert unreachable_up > 0.6 * A * len(els) * pts.size / 2


class _NoTriangles:
    """The engine without its triangles: the scan then casts every ray in front."""

    def __init__(self, occ):
        self.occ = occ

    @property
    def rays(self):
        return self.occ.rays

    def occluded(self, o, d):
        return self.occ.occluded(o, d)


@needs_engine
def test_the_scan_makes_the_same_intervals_with_fewer_rays():
    V, T, on_floor, on_sphere = _scene(n=300)
    occ = engine.Occluder(V, T)
    # the floor skips most of its rays; the sphere's points lie inside its own boxes, which
    # cover their whole sky: nothing skipped there, and nothing changed
    for pts, fewer in ((on_floor, 0.5), (on_sphere, 1.0)):
        r0 = occ.rays
        gen = horizon.iter_horizons(occ, pts, 24)
        while True:
            try:
                next(gen)
            except StopIteration as stop:
                H, figs = stop.value
                break
        pruned = occ.rays - r0
        bare = _NoTriangles(occ)
        r0 = occ.rays
        H0 = horizon.horizons(bare, pts, 24)
        full = occ.rays - r0
        assert np.array_equal(H, H0)
        assert pruned <= fewer * full and pruned + figs["skipped"] == full, (pruned, full)


@needs_engine
def test_the_bound_in_pieces_is_the_bound_in_one(monkeypatch):
    """The bound is computed in pieces of REACH_POINTS points (its transient memory); the
    pieces change no bit."""
    V, T, on_floor, _ = _scene(n=300)
    occ = engine.Occluder(V, T)
    whole = horizon._bounds(occ, on_floor, 24)
    monkeypatch.setattr(horizon, "REACH_POINTS", 7)
    parts = horizon._bounds(occ, on_floor, 24)
    assert all(np.array_equal(a, b) for a, b in zip(whole, parts))
    assert whole[0].shape == (24, on_floor.size) and 0 < whole[0].mean() < 0.9
