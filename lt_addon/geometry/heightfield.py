"""Tileable height fields for the paper scenes (Ashikhmin & Shirley 2002, Fig. 5-8).

Two patches, both periodic on the unit square so a baked texture tiles:

* :func:`bumps_and_dents` -- a regular lattice of spherical caps, alternately raised (bumps)
  and sunk (dents), like the paper's "bumps and dents" test surface.
* :func:`perlin_noise` -- classic gradient (Perlin) noise with a given lattice period, summed
  over octaves, like the paper's noise height field.

Heights are in the same units as the patch side (the patch spans [0, 1] x [0, 1]).
"""

from __future__ import annotations

import numpy as np


def _check_grid(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if u.shape != v.shape:
        raise ValueError(f"u and v must have the same shape, got {u.shape} and {v.shape}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
        raise ValueError("u and v must be finite (got NaN or inf)")
    return u, v


def bumps_and_dents(u, v, cells: int = 4, radius: float = 0.35, depth: float = 0.8) -> np.ndarray:
    """Height of a periodic lattice of spherical bumps and dents.

    The unit square is split into ``cells x cells`` square cells of side ``h = 1 / cells``. Each
    cell holds one spherical cap centred in the cell with footprint radius ``radius * h``; in a
    checkerboard pattern the cap is raised (bump) or sunk (dent). The sphere radius is chosen so
    the cap height is ``depth * radius * h`` (``depth = 1`` would be a hemisphere).

    Parameters
    ----------
    u, v : array_like, same shape (...)
        Patch coordinates; any real values (the field has period 1 in both).
    cells : int
        Cells per side (>= 1).
    radius : float
        Cap footprint radius as a fraction of the cell side, in (0, 0.5].
    depth : float
        Cap height as a fraction of its footprint radius, in (0, 1].

    Returns
    -------
    height : ndarray, shape (...), float64
        Height above the base plane (negative inside dents).
    """
    u, v = _check_grid(u, v)
    if cells < 1:
        raise ValueError(f"cells must be >= 1, got {cells}")
    if not 0.0 < radius <= 0.5:
        raise ValueError(f"radius must be in (0, 0.5], got {radius}")
    if not 0.0 < depth <= 1.0:
        raise ValueError(f"depth must be in (0, 1], got {depth}")
    h = 1.0 / cells
    a = radius * h  # footprint radius
    cap = depth * a  # cap height
    sphere_r = (a * a + cap * cap) / (2.0 * cap)  # sphere through the rim with that height
    su, sv = u * cells, v * cells
    iu, iv = np.floor(su), np.floor(sv)
    du = (su - iu - 0.5) * h
    dv = (sv - iv - 0.5) * h
    r2 = du * du + dv * dv
    inside = r2 < a * a
    height = np.zeros_like(u)
    sag = np.sqrt(np.maximum(sphere_r * sphere_r - r2, 0.0)) - (sphere_r - cap)
    sign = np.where((iu.astype(np.int64) + iv.astype(np.int64)) % 2 == 0, 1.0, -1.0)
    height[inside] = (sign * sag)[inside]
    return height


def _fade(t: np.ndarray) -> np.ndarray:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def perlin_noise(u, v, period: int = 4, octaves: int = 3, persistence: float = 0.5,
                 amplitude: float = 0.1, seed: int = 0) -> np.ndarray:
    """Periodic 2D gradient (Perlin) noise, summed over octaves.

    Octave ``o`` uses a lattice of ``period * 2**o`` cells per unit with unit gradients drawn
    from ``numpy.random.default_rng(seed)``, so the field has period 1 in u and v and is the
    same for the same seed on any machine.

    Parameters
    ----------
    u, v : array_like, same shape (...)
        Patch coordinates.
    period : int
        Lattice cells per unit for the first octave (>= 1).
    octaves : int
        Number of octaves (>= 1).
    persistence : float
        Amplitude ratio between successive octaves.
    amplitude : float
        Peak amplitude scale of the first octave (patch units).
    seed : int
        Seed of the gradient lattice.

    Returns
    -------
    height : ndarray, shape (...), float64
    """
    u, v = _check_grid(u, v)
    if period < 1 or octaves < 1:
        raise ValueError(f"period and octaves must be >= 1, got {period}, {octaves}")
    rng = np.random.default_rng(seed)
    total = np.zeros_like(u)
    amp = amplitude
    for octave in range(octaves):
        n = period * (2 ** octave)
        angles = rng.uniform(0.0, 2.0 * np.pi, size=(n, n))
        gx, gy = np.cos(angles), np.sin(angles)
        su, sv = u * n, v * n
        i0, j0 = np.floor(su).astype(np.int64), np.floor(sv).astype(np.int64)
        fu, fv = su - i0, sv - j0
        i0 %= n
        j0 %= n
        i1, j1 = (i0 + 1) % n, (j0 + 1) % n

        def corner(ii, jj, ou, ov):
            return gx[ii, jj] * (fu - ou) + gy[ii, jj] * (fv - ov)

        wu, wv = _fade(fu), _fade(fv)
        n00, n10 = corner(i0, j0, 0.0, 0.0), corner(i1, j0, 1.0, 0.0)
        n01, n11 = corner(i0, j1, 0.0, 1.0), corner(i1, j1, 1.0, 1.0)
        nx0 = n00 + wu * (n10 - n00)
        nx1 = n01 + wu * (n11 - n01)
        total += amp * (nx0 + wv * (nx1 - nx0))
        amp *= persistence
    return total


def grid(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex coordinates of a ``(resolution + 1)^2`` grid over the unit square.

    Returns
    -------
    u, v : ndarray, shape (resolution + 1, resolution + 1), float64
        ``u`` varies along axis 1, ``v`` along axis 0; both in [0, 1] inclusive.
    """
    if resolution < 1:
        raise ValueError(f"resolution must be >= 1, got {resolution}")
    t = np.linspace(0.0, 1.0, resolution + 1)
    v, u = np.meshgrid(t, t, indexing="ij")
    return u, v
