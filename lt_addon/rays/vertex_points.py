"""Where Cycles shades a vertex bake: each face corner's shading point, as the texture bake's
texel points (:mod:`.texels`) are for image bakes.

Blender's vertex-colour bake (``bake_targets_populate_pixels_color_attributes`` in
``object_bake_api.cc``) gives every face corner the *first* loop triangle that contains it and
the barycentric coordinates of its vertex there; per vertex (``POINT``) it averages the
corners' results. Cycles (``integrator_init_from_bake`` in ``kernel/integrator/init_from_bake.h``)
moves a point that lies exactly on a vertex towards its triangle's centre
(``bake_offset_towards_center``: by ``1e-4 max(1, max |P|)`` or to the centre, whichever is
nearer, then each barycentric weight clamped to ``[1e-5, 1 - 1e-5]``), in float32. The point is
then an ordinary shading point inside that triangle: its smooth normal interpolated there, the
shadow-terminator lift and the self-intersection rules of :mod:`.shading` apply.

Measured against Cycles' 1-spp vertex bake of hard suns (``tests/blender/test_transport_bake.py``):
without the nudge, rays from the vertex itself differed at 10 % of the statue's values (near its
terminator a ray from the vertex meets the neighbouring faces; from inside its own face it does
not).
"""

from __future__ import annotations

import numpy as np

from .direct import direct_rows
from .shading import ShadingPoints, shading_points

#: Cycles' ``bake_offset_towards_center``: the move (relative to ``max(1, max |P|)``, metres) and
#: the barycentric clamp.
POSITION_OFFSET = np.float32(1e-4)
UV_OFFSET = np.float32(1e-5)
#: The origins' push off their triangle's plane (relative, :data:`.shading.EPSILON` for texels):
#: a vertex-bake point is 1e-4 from its triangle's edges, so the texels' 2e-5 moved grazing rays
#: across neighbouring faces. Measured on the statue (test size, 96 directions, against Cycles'
#: vertex bake): values more than 1e-4 off 171 / 71 / 14 / 10 of 48,672 at 2e-5 / 5e-6 / 1e-6 /
#: 2e-7; float32 rays carry ~6e-8.
EPSILON = 1e-6


def first_triangles(loops) -> tuple[np.ndarray, np.ndarray]:
    """For each face corner, the first loop triangle containing it and its slot there (0..2).

    Parameters
    ----------
    loops : (T, 3) int
        The corners of each loop triangle (Blender's ``corner_tris``), in mesh order.

    Returns
    -------
    triangle : (C,) int64 (-1 for a corner in no triangle);  slot : (C,) int64
    """
    loops = np.asarray(loops, np.int64).reshape(-1, 3)
    C = int(loops.max()) + 1 if loops.size else 0
    triangle = np.full(C, -1, np.int64)
    slot = np.zeros(C, np.int64)
    flat = loops.ravel()
    # the first occurrence of each corner in triangle order wins
    corners, first = np.unique(flat, return_index=True)
    triangle[corners] = first // 3
    slot[corners] = first % 3
    return triangle, slot


def nudged_barycentrics(corners) -> np.ndarray:
    """Cycles' ``bake_offset_towards_center`` for points on a triangle's vertex.

    Parameters
    ----------
    corners : (C, 3, 3) float
        Each point's triangle, world space, rolled so that the point's vertex comes first.

    Returns
    -------
    (C, 3) float64 barycentric weights of the moved point on the rolled triangle.
    """
    Vt = np.asarray(corners, np.float32)
    P = Vt[:, 0]
    to_c = Vt.sum(axis=1) / np.float32(3) - P
    length = np.linalg.norm(to_c, axis=1)
    step = np.minimum(length, np.maximum(np.abs(P).max(axis=1), np.float32(1)) * POSITION_OFFSET)
    with np.errstate(invalid="ignore", divide="ignore"):
        moved = P + to_c / np.maximum(length, np.float32(1e-30))[:, None] * step[:, None]
        v1, v2, vP = Vt[:, 1] - P, Vt[:, 2] - P, moved - P
        d11, d12, d22 = (v1 * v1).sum(1), (v1 * v2).sum(1), (v2 * v2).sum(1)
        dP1, dP2 = (vP * v1).sum(1), (vP * v2).sum(1)
        denom = d11 * d22 - d12 * d12
        b1 = np.clip((d22 * dP1 - d12 * dP2) / denom, UV_OFFSET, 1 - UV_OFFSET)
        b2 = np.clip((d11 * dP2 - d12 * dP1) / denom, UV_OFFSET, 1 - UV_OFFSET)
    b0 = np.clip(1 - b1 - b2, UV_OFFSET, 1 - UV_OFFSET)
    out = np.stack([b0, b1, 1 - b0 - b1], axis=1).astype(np.float64)
    degenerate = ~(denom != 0)            # Cycles returns (0, 0): the third vertex
    out[degenerate] = (0.0, 0.0, 1.0)
    return out


def vertex_bake_points(vertices, triangles, loops, corner_normals, smooth, cutoff: float = 0.1,
                       mirrored: bool = False) -> tuple[ShadingPoints, np.ndarray]:
    """The shading point of every face corner of a vertex bake.

    Parameters
    ----------
    vertices : (V, 3) world positions;  triangles : (T, 3) vertex indices of the loop triangles;
    loops : (T, 3) their corners;  corner_normals : (C, 3) world unit normals per corner;
    smooth : (T,) bool, smooth-shaded;  cutoff : the object's shadow terminator geometry offset;
    mirrored : the object's transform has a negative determinant.

    Returns
    -------
    points : ShadingPoints of the corners that lie in a triangle;  corner : (P,) their corners.
    """
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    lp = np.asarray(loops, np.int64).reshape(-1, 3)
    triangle, slot = first_triangles(lp)
    corner = np.nonzero(triangle >= 0)[0]
    triangle, slot = triangle[corner], slot[corner]
    roll = (slot[:, None] + np.arange(3)[None]) % 3          # the corner's vertex first
    V = np.asarray(vertices, np.float64)
    rolled = np.take_along_axis(tri[triangle], roll, axis=1)
    bary_rolled = nudged_barycentrics(V[rolled])
    bary = np.zeros_like(bary_rolled)
    np.put_along_axis(bary, roll, bary_rolled, axis=1)       # back to the triangle's order
    cn = np.asarray(corner_normals, np.float64)
    points = shading_points(V, tri, cn[lp], smooth, triangle, bary, cutoff=cutoff,
                            mirrored=mirrored)
    points.epsilon = EPSILON
    return points, corner


def vertex_rows(occluder, points: ShadingPoints, group, count: int, directions) -> np.ndarray:
    """Visibility x cosine per unit normal irradiance (S, count) float32 at unit ``directions``
    (S, 3): each point's value (Cycles' diffuse direct pass times pi) averaged over the points of
    each receiver ``group`` (P,) -- a vertex's corners, or one corner each."""
    rows = direct_rows(occluder, points, directions).astype(np.float64) * np.pi   # (S, P)
    group = np.asarray(group, np.int64)
    per = np.maximum(np.bincount(group, minlength=count), 1).astype(np.float64)
    out = np.zeros((len(rows), count), np.float32)
    for s, row in enumerate(rows):
        out[s] = np.bincount(group, weights=row, minlength=count) / per
    return out
