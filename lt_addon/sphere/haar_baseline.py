"""2D Haar wavelets on the cubemap faces: the all-frequency PRT baseline (Ng et al. 2003).

Per-vertex transport sampled on a ``cube:n`` direction set (:func:`.directions.cubemap`, ``n`` a
power of two) is laid out as six ``n x n`` faces and transformed face by face with the
orthonormal non-standard 2D Haar decomposition: at each level every 2 x 2 block ``(p q / r s)``
of the current scaling image becomes ::

    average    (p + q + r + s) / 2      -> top-left quadrant (next level's scaling image)
    horizontal (p - q + r - s) / 2      -> top-right
    vertical   (p + q - r - s) / 2      -> bottom-left
    diagonal   (p - q - r + s) / 2      -> bottom-right

down to one scaling coefficient per face (Mallat layout, ``6 n^2`` coefficients in all). The
4 x 4 block matrix is orthogonal, so the transform preserves Euclidean inner products.

Solid angles: the transform is applied to ``T_j sqrt(dw_j)``, not to ``T_j``. Then for any
lighting, with ``h(.)`` the transform and ``Lw = L dw``::

    sum_j T_j L_j dw_j = (T sqrt(dw)) . (L sqrt(dw)) = h(T sqrt(dw)) . h(Lw / sqrt(dw))

so shading is an exact dot product of Haar coefficients, and keeping the ``d`` largest-magnitude
coefficients per vertex (non-linear approximation, Ng et al.) minimises the solid-angle-weighted
(sphere L2) transport error ``sum_j (T - T_d)_j^2 dw_j``, which therefore never grows with ``d``.
Texel solid angles on a cube face vary by up to ``3^{3/2} ~ 5.2`` (centre vs corner), so this
weighting matters.
"""

from __future__ import annotations

import numpy as np

from .directions import DirectionSet


def _check_face_size(n: int) -> int:
    n = int(n)
    if n < 1 or n & (n - 1):
        raise ValueError(f"Haar wavelets need a power-of-two face size, got {n}")
    return n


def _cube_n(direction_set: DirectionSet) -> int:
    if direction_set.kind != "cube":
        raise ValueError(f"Haar wavelets need a 'cube:n' direction set, got {direction_set.spec!r}")
    return _check_face_size(direction_set.params["n"])


def haar2d_forward(faces) -> np.ndarray:
    """Orthonormal non-standard 2D Haar transform of square images.

    Parameters
    ----------
    faces : array_like, shape (..., n, n), n a power of two

    Returns
    -------
    ndarray, shape (..., n, n), float64, Mallat layout (scaling coefficient at [..., 0, 0])
    """
    a = np.array(faces, dtype=np.float64)
    n = a.shape[-1]
    if a.ndim < 2 or a.shape[-2] != n:
        raise ValueError(f"faces must have shape (..., n, n), got {a.shape}")
    _check_face_size(n)
    m = n
    while m > 1:
        blk = a[..., :m, :m]
        p, q = blk[..., 0::2, 0::2], blk[..., 0::2, 1::2]
        r, s = blk[..., 1::2, 0::2], blk[..., 1::2, 1::2]
        h = m // 2
        out = np.empty_like(blk)
        out[..., :h, :h] = (p + q + r + s) * 0.5
        out[..., :h, h:] = (p - q + r - s) * 0.5
        out[..., h:, :h] = (p + q - r - s) * 0.5
        out[..., h:, h:] = (p - q - r + s) * 0.5
        a[..., :m, :m] = out
        m = h
    return a


def haar2d_inverse(coefficients) -> np.ndarray:
    """Inverse of :func:`haar2d_forward`; shape (..., n, n), float64."""
    a = np.array(coefficients, dtype=np.float64)
    n = a.shape[-1]
    if a.ndim < 2 or a.shape[-2] != n:
        raise ValueError(f"coefficients must have shape (..., n, n), got {a.shape}")
    _check_face_size(n)
    m = 2
    while m <= n:
        h = m // 2
        avg, hor = a[..., :h, :h].copy(), a[..., :h, h:m].copy()
        ver, dia = a[..., h:m, :h].copy(), a[..., h:m, h:m].copy()
        a[..., 0:m:2, 0:m:2] = (avg + hor + ver + dia) * 0.5
        a[..., 0:m:2, 1:m:2] = (avg - hor + ver - dia) * 0.5
        a[..., 1:m:2, 0:m:2] = (avg + hor - ver - dia) * 0.5
        a[..., 1:m:2, 1:m:2] = (avg - hor - ver + dia) * 0.5
        m *= 2
    return a


def haar_project(T, direction_set: DirectionSet) -> np.ndarray:
    """Haar coefficients of per-vertex transport on a cubemap direction set.

    Parameters
    ----------
    T : array_like, shape (V, S), S = 6 n^2
    direction_set : DirectionSet of kind ``"cube"``

    Returns
    -------
    coefficients : ndarray, shape (V, S), float64
        ``haar2d_forward`` of ``T sqrt(dw)`` per face, flattened face-major in the sample order.
    """
    n = _cube_n(direction_set)
    t = np.asarray(T, dtype=np.float64)
    if t.ndim != 2 or t.shape[1] != direction_set.size:
        raise ValueError(f"T must have shape (V, {direction_set.size}), got {t.shape}")
    f = (t * np.sqrt(direction_set.solid_angles)).reshape(t.shape[0], 6, n, n)
    return haar2d_forward(f).reshape(t.shape)


def haar_reconstruct(coefficients, direction_set: DirectionSet) -> np.ndarray:
    """Transport ``T`` (V, S) from Haar coefficients (undoes the ``sqrt(dw)`` weighting)."""
    n = _cube_n(direction_set)
    c = np.asarray(coefficients, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != direction_set.size:
        raise ValueError(f"coefficients must have shape (V, {direction_set.size}), got {c.shape}")
    f = haar2d_inverse(c.reshape(c.shape[0], 6, n, n)).reshape(c.shape)
    return f / np.sqrt(direction_set.solid_angles)


def haar_project_lighting(L_weighted, direction_set: DirectionSet) -> np.ndarray:
    """Haar coefficients of weighted lighting ``Lw = L dw``: transform of ``L sqrt(dw)``.

    Parameters
    ----------
    L_weighted : array_like, shape (S,) or (S, C)

    Returns
    -------
    ndarray, shape (S,) or (S, C); ``haar_project(T) @ result == T @ L_weighted``.
    """
    n = _cube_n(direction_set)
    lw = np.asarray(L_weighted, dtype=np.float64)
    if lw.shape[:1] != (direction_set.size,) or lw.ndim > 2:
        raise ValueError(f"L_weighted must have shape ({direction_set.size},) or "
                         f"({direction_set.size}, C), got {lw.shape}")
    w = np.sqrt(direction_set.solid_angles)
    x = (lw.T / w).reshape(-1, 6, n, n) if lw.ndim == 2 else (lw / w).reshape(1, 6, n, n)
    out = haar2d_forward(x).reshape(-1, direction_set.size)
    return out.T if lw.ndim == 2 else out[0]


def keep_largest(coefficients, d: int) -> np.ndarray:
    """Zero all but the ``d`` largest-magnitude coefficients of each row.

    Parameters
    ----------
    coefficients : array_like, shape (V, K)
    d : int, 0 <= d (values above K keep everything)

    Returns
    -------
    ndarray, shape (V, K), float64 (ties at the threshold are broken by position)
    """
    c = np.asarray(coefficients, dtype=np.float64)
    if c.ndim != 2:
        raise ValueError(f"coefficients must have shape (V, K), got {c.shape}")
    d = int(d)
    if d < 0:
        raise ValueError(f"d must be >= 0, got {d}")
    K = c.shape[1]
    if d >= K:
        return c.copy()
    out = np.zeros_like(c)
    if d == 0:
        return out
    idx = np.argpartition(-np.abs(c), d - 1, axis=1)[:, :d]
    rows = np.arange(c.shape[0])[:, None]
    out[rows, idx] = c[rows, idx]
    return out


def haar_approximate(T, direction_set: DirectionSet, d: int) -> np.ndarray:
    """Transport reconstructed from its ``d`` largest Haar coefficients per vertex; (V, S)."""
    return haar_reconstruct(keep_largest(haar_project(T, direction_set), d), direction_set)


def haar_shade(coefficients, light_coefficients, albedo=1.0) -> np.ndarray:
    """Diffuse shading ``rho / pi * c . h(L sqrt(dw))`` from (possibly truncated) Haar transport.

    Parameters
    ----------
    coefficients : array_like, shape (V, S)
    light_coefficients : array_like, shape (S,) or (S, C) (:func:`haar_project_lighting`)
    albedo : float

    Returns
    -------
    B : ndarray, shape (V,) or (V, C)
    """
    c = np.asarray(coefficients, dtype=np.float64)
    return (c @ np.asarray(light_coefficients, dtype=np.float64)) * (float(albedo) / np.pi)


def haar_shading_error(T, direction_set: DirectionSet, d: int, L_weighted) -> float:
    """Relative RMS shading error over vertices (and channels) of the ``d``-term Haar
    approximation under one weighted lighting ``(S,)`` or ``(S, C)`` (albedo cancels)."""
    t = np.asarray(T, dtype=np.float64)
    lc = haar_project_lighting(L_weighted, direction_set)
    approx = keep_largest(haar_project(t, direction_set), d) @ lc
    ref = t @ np.asarray(L_weighted, dtype=np.float64)
    nr = float(np.linalg.norm(ref))
    ne = float(np.linalg.norm(approx - ref))
    return (0.0 if ne == 0 else float("inf")) if nr == 0 else ne / nr
