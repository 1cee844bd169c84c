"""Linear-interpolation baseline (Ashikhmin & Shirley 2002, sec. 7.3).

Bake ``K = N1 x N1`` images under positive Gaussian lights of about the steerable light's main-lobe
width, placed at the *same* centres as the sampled steerable basis (the paper compares methods
with the same 49 light orientations), and relight by **bilinear** interpolation of the (at most
four) images around the requested centre:

    f(x, y; x0, y0) = exp(-29 ((x - x0)**2 + (y - y0)**2))        (eq. 12, disk domain)

mapped onto the hemisphere by eq. 7. Its FWHM is ``2 sqrt(ln 2 / 29) = 0.309`` disk units (the
steerable light's is 0.336). Interpolated lights are not steered copies: shadows cross-fade a
little ("some shortening of shadows").
"""

from __future__ import annotations

import numpy as np

from ..sphere.hemisphere import equirect_pixel_directions, hemisphere_to_disk, is_upper_hemisphere
from .basis import steer_images

#: Sharpness of the paper's interpolation light, eq. 12.
PAPER_SHARPNESS = 29.0


def gaussian_light_disk(xy, xy0, sharpness: float = PAPER_SHARPNESS) -> np.ndarray:
    """Gaussian light ``exp(-sharpness |xy - xy0|**2)`` on the disk domain (eq. 12).

    Parameters
    ----------
    xy : array_like, shape (..., 2)
    xy0 : array_like, shape (..., 2), broadcastable
    sharpness : float

    Returns
    -------
    L : ndarray, shape (...), float64, in (0, 1]
    """
    p = np.asarray(xy, dtype=np.float64)
    p0 = np.asarray(xy0, dtype=np.float64)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(p0))):
        raise ValueError("xy / xy0 contain NaN or inf")
    return np.exp(-sharpness * np.sum((p - p0) ** 2, axis=-1))


def gaussian_environment(xy0, height: int, width: int | None = None, *, row_order: str,
                         sharpness: float = PAPER_SHARPNESS, dtype=np.float32) -> np.ndarray:
    """Equirectangular image of the Gaussian interpolation light centred at ``xy0``.

    Same conventions as :func:`.steerable.environment_image` (Cycles equirect mapping, zero
    below the horizon).

    Returns
    -------
    image : ndarray, shape (height, width), ``dtype``
    """
    width = 2 * int(height) if width is None else int(width)
    dirs = equirect_pixel_directions(int(height), width, row_order=row_order)
    up = is_upper_hemisphere(dirs)
    dd = np.where(up[..., None], dirs, np.array([0.0, 0.0, 1.0]))
    L = gaussian_light_disk(hemisphere_to_disk(dd), np.asarray(xy0, dtype=np.float64), sharpness)
    return np.where(up, L, 0.0).astype(dtype)


def bilinear_weights(xy0, grid_x, grid_y) -> np.ndarray:
    """Bilinear blend weights of the images baked on a tensor grid of centres.

    Parameters
    ----------
    xy0 : array_like, shape (..., 2)
        Requested light centres (disk domain). Points outside the grid are clamped onto it
        (the nearest edge images are used).
    grid_x : array_like, shape (nx,)
        Increasing x coordinates of the grid.
    grid_y : array_like, shape (ny,)
        Increasing y coordinates of the grid.

    Returns
    -------
    weights : ndarray, shape (..., nx * ny), float64
        Centres outside the grid are clamped onto its edge: give the baseline a grid spanning
        [-1, 1] (the whole disk), not the sampled basis' +-0.81 grid, or lights below about
        20 degrees elevation land in the wrong place.
        Non-negative, at most four non-zero, summing to 1; flattened with ``k = a * ny + b`` for
        the centre ``(grid_x[a], grid_y[b])`` -- the order of
        :func:`.sampled_basis.default_centres`.
    """
    p = np.asarray(xy0, dtype=np.float64)
    gx = np.asarray(grid_x, dtype=np.float64)
    gy = np.asarray(grid_y, dtype=np.float64)
    if not np.all(np.isfinite(p)):
        raise ValueError("xy0 contains NaN or inf")
    if p.ndim == 0 or p.shape[-1] != 2:
        raise ValueError(f"xy0 must have shape (..., 2), got {p.shape}")
    if gx.size < 2 or gy.size < 2 or np.any(np.diff(gx) <= 0) or np.any(np.diff(gy) <= 0):
        raise ValueError("grid_x and grid_y need >= 2 strictly increasing values")

    def axis(v, g):
        v = np.clip(v, g[0], g[-1])
        i = np.clip(np.searchsorted(g, v, side="right") - 1, 0, g.size - 2)
        t = (v - g[i]) / (g[i + 1] - g[i])
        return i, t

    ia, ta = axis(p[..., 0], gx)
    ib, tb = axis(p[..., 1], gy)
    lead = p.shape[:-1]
    W = np.zeros(lead + (gx.size * gy.size,), dtype=np.float64)
    for da, wa in ((0, 1.0 - ta), (1, ta)):
        for db, wb in ((0, 1.0 - tb), (1, tb)):
            k = (ia + da) * gy.size + (ib + db)
            np.put_along_axis(W, np.asarray(k)[..., None],
                              np.take_along_axis(W, np.asarray(k)[..., None], -1)
                              + (wa * wb)[..., None], -1)
    return W


def interpolate_images(sample_images, weights) -> np.ndarray:
    """Blend the Gaussian-light images with :func:`bilinear_weights` (no clamp needed: >= 0).

    Parameters
    ----------
    sample_images : array_like, shape (K, ...)
    weights : array_like, shape (K,)

    Returns
    -------
    image : ndarray, shape (...)
    """
    return steer_images(sample_images, weights)
