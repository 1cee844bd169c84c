"""Shading points on a floor of two triangles: the scenes of the bpy-free ray tests
(test_horizons.py, test_reach.py)."""

import numpy as np

from relightable_textures.lt_addon.rays.shading import shading_points


def floor_points(V, T, P):
    """Flat-shaded shading points at ``P`` (n, 3), on the floor ``z = 0`` made of triangles
    ``T[0]`` and ``T[1]`` of ``V`` (a square split along ``x = y``: ``T[0]`` holds
    ``x >= y``); normals up."""
    V, T, P = np.asarray(V, float), np.asarray(T), np.asarray(P, float)
    tri = np.where(P[:, 0] >= P[:, 1], 0, 1)
    bary = np.zeros((len(P), 3))
    for t in (0, 1):
        a, b, c = V[T[t]]
        m = np.linalg.inv(np.column_stack([b - a, c - a])[:2])
        uv = (P[tri == t, :2] - a[:2]) @ m.T
        bary[tri == t] = np.column_stack([1 - uv.sum(1), uv])
    up = np.tile([0.0, 0.0, 1.0], (2, 3, 1))
    return shading_points(V, T[:2], up, [False, False], tri, bary)
