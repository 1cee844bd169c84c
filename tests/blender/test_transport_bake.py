"""Per-vertex transport bakes with real Cycles (hard Sun, 1 spp, no bounces = exact)."""

import numpy as np
import pytest


@pytest.fixture
def ball(fresh_scene):
    import bmesh

    from relightable_textures.operators.meshes import object_from_bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=1.0)
    return fresh_scene, object_from_bmesh("Ball", bm, fresh_scene.collection, smooth=True)


def _normals(obj):
    n = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("normal", n)
    return n.reshape(-1, 3)


def test_convex_transport_is_the_clamped_cosine(ball):
    """No occluder: T[v, s] = max(0, n_v . w_s), which Cycles reproduces to float precision."""
    from relightable_textures.operators import transport_bake as tb
    from relightable_textures.operators.steerable_bake import run

    scene, obj = ball
    rng = np.random.default_rng(0)
    d = rng.normal(size=(6, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    res = run(tb.bake_transport(scene, obj, d))
    cos = _normals(obj) @ d.T
    lit = cos > 0.2  # away from the terminator (shadow-terminator offsets apply there)
    assert res.transport.shape == (len(cos), 6) and res.bake_calls == 6
    assert np.abs(res.transport[lit] - cos[lit]).max() < 1e-4
    assert np.all(res.transport[cos < -0.05] == 0)


def test_an_occluder_casts_a_shadow_and_cancel_restores_attributes(ball):
    """A plate above the ball blocks light from the zenith for the upper vertices."""
    import bpy

    from relightable_textures.operators import transport_bake as tb
    from relightable_textures.operators.meshes import grid_faces, mesh_object
    from relightable_textures.operators.steerable_bake import run

    scene, obj = ball
    t = np.linspace(-3, 3, 3)
    verts = np.stack(np.meshgrid(t, t, indexing="ij") + [np.full((3, 3), 2.0)], -1).reshape(-1, 3)
    mesh_object("Plate", verts, grid_faces(3, 3), scene.collection)
    before = [a.name for a in obj.data.color_attributes]
    res = run(tb.bake_transport(scene, obj, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))
    n = _normals(obj)
    top = n[:, 2] > 0.5
    assert np.all(res.transport[top, 0] == 0)  # shadowed from above
    side = n[:, 0] > 0.5
    assert np.abs(res.transport[side, 1] - n[side, 0]).max() < 1e-4  # lit from +x
    steps = []
    gen = tb.bake_transport(scene, obj, np.eye(3))
    assert run(gen, on_progress=steps.append, should_cancel=lambda: len(steps) == 1) is None
    assert [a.name for a in obj.data.color_attributes] == before
    assert not [o for o in bpy.data.objects if o.name.startswith("RelightBake")]
