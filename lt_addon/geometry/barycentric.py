"""Barycentric coordinates of points in triangles (bpy-free)."""

from __future__ import annotations

import numpy as np


def barycentric(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric weights (M, 3) of ``points`` (M, 3) in the triangles ``a, b, c`` (M, 3 each),
    the point projected onto each triangle's plane, clipped to the triangle and normalised (a
    hit on an edge may land a rounding off it); a degenerate triangle gives equal thirds."""
    v0, v1, v2 = b - a, c - a, points - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    ok = np.abs(den) > 1e-30
    safe = np.where(ok, den, 1.0)
    w1 = np.where(ok, (d11 * d20 - d01 * d21) / safe, 1.0 / 3.0)
    w2 = np.where(ok, (d00 * d21 - d01 * d20) / safe, 1.0 / 3.0)
    w = np.clip(np.stack([1.0 - w1 - w2, w1, w2], axis=1), 0.0, None)
    return w / np.maximum(w.sum(axis=1, keepdims=True), 1e-30)
