"""Points touching another object's surface (lt_addon/rays/contact.py): a flat box's bottom face
coplanar with a one-sided floor is dark towards every direction leaving through the floor, as
Cycles' ray (starting at the point, skipping only its own triangle) meets the floor at t ~ 0;
a floor a little below is met by the ordinary ray, and a floor a little *above* the point
(behind it) is not met at all -- by Cycles' ray or by the contact ray."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import contact, engine
from relightable_textures.lt_addon.rays.direct import direct_rows
from relightable_textures.lt_addon.rays.shading import EPSILON, shading_points

pytestmark = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")

FLOOR_V = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
FLOOR_T = np.array([[0, 1, 2], [0, 2, 3]])


def _bottom_points(n=50, seed=0):
    """Shading points on the bottom face (z = 0, facing down) of a unit box, flat."""
    V = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], float)
    T = np.array([[0, 2, 1], [0, 3, 2]])      # wound to face -z
    rng = np.random.default_rng(seed)
    w = rng.dirichlet((1, 1, 1), n)
    tri = rng.integers(0, 2, n)
    cn = np.broadcast_to([0.0, 0.0, -1.0], (2, 3, 3))
    pts = shading_points(V, T, cn, np.zeros(2, bool), tri, w, cutoff=0.0)
    assert np.allclose(pts.Ng, [0, 0, -1])
    return V, T, pts


def _rows(floor_z, use_contact):
    V, T, pts = _bottom_points()
    fv = FLOOR_V + [0, 0, floor_z]
    occ = engine.Occluder(np.concatenate([V, fv]), np.concatenate([T, FLOOR_T + 4]))
    found = contact.find(pts, engine.Occluder(fv, FLOOR_T)) if use_contact else None
    pts.contact = found
    L = np.array([[0.3, 0.1, -1.0], [0.0, 0.0, -1.0], [1.0, 0.0, -0.05]])
    L /= np.linalg.norm(L, axis=1, keepdims=True)
    return direct_rows(occ, pts, L), found


def test_a_coplanar_floor_darkens_the_face_on_it():
    before, _ = _rows(0.0, use_contact=False)
    assert (before > 0).all()                    # the push went through the floor: lit
    after, found = _rows(0.0, use_contact=True)
    assert found is not None and found.count == 50
    assert (after == 0).all()


@pytest.mark.parametrize("dz, dark", [(-1e-3, True), (-3 * EPSILON, True), (-0.5 * EPSILON, True),
                                      (0.5 * EPSILON, False), (3 * EPSILON, False),
                                      (1e-3, False)])
def test_a_floor_off_the_plane_is_met_only_in_front(dz, dark):
    """A floor ``dz`` below the face (in front of it, for these downward suns) is met as
    Cycles' ray meets it; one above it lies behind the point: never met."""
    got, _ = _rows(dz, use_contact=True)
    assert (got == 0).all() if dark else (got > 0).all()


def test_nothing_near_finds_no_contact_and_the_box_alone_is_unchanged():
    V, T, pts = _bottom_points()
    far = engine.Occluder(FLOOR_V + [0, 0, -0.5], FLOOR_T)
    assert contact.find(pts, far) is None
    rows = contact.near_triangles(FLOOR_V + [0, 0, -0.5], FLOOR_T, pts.P.min(0), pts.P.max(0),
                                  contact.reach(pts))
    assert len(rows) == 0
    rows = contact.near_triangles(FLOOR_V, FLOOR_T, pts.P.min(0), pts.P.max(0),
                                  contact.reach(pts))
    assert sorted(rows) == [0, 1]


def test_subset_and_join_keep_each_points_occluder():
    _, _, pts = _bottom_points(10)
    a = contact.Contact(["A"], np.array([0, -1, 0], np.int32))
    b = contact.Contact(["B"], np.array([-1, 0], np.int32))
    j = contact.Contact.join([a, None, b], [3, 4, 2])
    assert j.others == ["A", "B"]
    assert j.owner.tolist() == [0, -1, 0, -1, -1, -1, -1, -1, 1]
    assert j.subset([2, 8]).owner.tolist() == [0, 1]
    assert contact.Contact.join([None, None], [1, 2]) is None
