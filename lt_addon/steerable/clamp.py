"""Negative lobes of steerable lights: the offset fallback for baking, and the post-steering clamp.

The steerable lights ring: they have negative lobes (about -18 % of the peak in 1D for the
paper's design). Two consequences (Ashikhmin & Shirley 2002, sec. 6.1 and 7.1):

* **Baking.** Cycles accepts negative world radiance, so the lights can be baked as they are
  (with the world's importance sampling off, the bake is exactly linear). If a renderer does not
  accept negative radiance, add a constant ``c_k`` times the *uniform hemisphere light* ``U``
  (radiance 1 over the upper hemisphere, 0 below) so that ``L_k + c_k U >= 0``, bake that and one
  extra image under ``U``, and subtract: ``bake(L_k) = bake(L_k + c_k U) - c_k bake(U)``
  (:func:`positive_offsets`, :func:`offset_environment`, :func:`remove_offsets`).
  Keep everything in float: the difference of two large numbers loses precision in half/8-bit.
* **After steering.** A steered result can be negative (non-physical); clamp it to 0
  (:func:`clamp_steered`). Never clamp basis images -- only the final steered image.
"""

from __future__ import annotations

import numpy as np

from ..sphere.hemisphere import equirect_pixel_directions, is_upper_hemisphere


def uniform_hemisphere_environment(height: int, width: int | None = None, *, row_order: str,
                                   dtype=np.float32) -> np.ndarray:
    """Equirectangular image of the uniform upper-hemisphere light ``U``.

    Parameters
    ----------
    height : int
    width : int, optional
        Default ``2 * height``.
    row_order : {"top_first", "bottom_first"}
        See :func:`.hemisphere.equirect_pixel_directions`.

    Returns
    -------
    image : ndarray, shape (height, width), ``dtype``
        1 for pixels whose centre direction has ``z >= 0``, else 0.
    """
    width = 2 * int(height) if width is None else int(width)
    dirs = equirect_pixel_directions(int(height), width, row_order=row_order)
    return is_upper_hemisphere(dirs).astype(dtype)


def positive_offsets(light_environments, uniform_environment=None, margin: float = 0.0):
    """Smallest offsets ``c_k >= 0`` making ``L_k + c_k U`` non-negative.

    Parameters
    ----------
    light_environments : array_like, shape (K, H, W) or (H, W)
        Environment images of the lights (zero below the horizon).
    uniform_environment : array_like, shape (H, W), optional
        ``U``; only its support matters (pixels where ``U > 0``). Default: every pixel where
        some light is non-zero is assumed covered by ``U``.
    margin : float
        Relative safety margin: ``c_k = (1 + margin) * max(0, -min L_k)``.

    Returns
    -------
    offsets : ndarray, shape (K,) (or scalar for a single image), float64
    """
    L = np.asarray(light_environments, dtype=np.float64)
    single = L.ndim == 2
    if single:
        L = L[None]
    if not np.all(np.isfinite(L)):
        raise ValueError("light_environments contains NaN or inf")
    if uniform_environment is not None:
        U = np.asarray(uniform_environment, dtype=np.float64)
        if U.shape != L.shape[1:]:
            raise ValueError(f"uniform_environment shape {U.shape} != light shape {L.shape[1:]}")
        if np.any((U <= 0) & np.any(L < 0, axis=0)):
            raise ValueError("a light is negative where the uniform light is zero; "
                             "no offset of U can make it non-negative")
    c = (1.0 + float(margin)) * np.maximum(0.0, -L.reshape(L.shape[0], -1).min(axis=1))
    return float(c[0]) if single else c


def offset_environment(light_environment, offset, uniform_environment) -> np.ndarray:
    """``L + c U``: the non-negative light actually baked in the offset fallback.

    Parameters
    ----------
    light_environment : array_like, shape (H, W)
    offset : float
    uniform_environment : array_like, shape (H, W)

    Returns
    -------
    image : ndarray, shape (H, W), float64
    """
    return (np.asarray(light_environment, dtype=np.float64)
            + float(offset) * np.asarray(uniform_environment, dtype=np.float64))


def remove_offsets(baked_offset_images, baked_uniform_image, offsets) -> np.ndarray:
    """Recover ``bake(L_k) = bake(L_k + c_k U) - c_k bake(U)`` (linearity of rendering).

    Parameters
    ----------
    baked_offset_images : array_like, shape (K, ...)
        Images baked under ``L_k + c_k U``.
    baked_uniform_image : array_like, shape (...)
        Image baked under ``U``.
    offsets : array_like, shape (K,)

    Returns
    -------
    images : ndarray, shape (K, ...), float64
    """
    B = np.asarray(baked_offset_images, dtype=np.float64)
    U = np.asarray(baked_uniform_image, dtype=np.float64)
    c = np.asarray(offsets, dtype=np.float64).reshape(-1)
    if B.shape[0] != c.shape[0] or B.shape[1:] != U.shape:
        raise ValueError(f"shapes do not match: images {B.shape}, uniform {U.shape}, "
                         f"offsets {c.shape}")
    return B - c.reshape((-1,) + (1,) * U.ndim) * U[None]


def clamp_steered(image) -> np.ndarray:
    """Clamp a steered image to non-negative values (paper sec. 7.1: "we simply return zero").

    Parameters
    ----------
    image : array_like, any shape

    Returns
    -------
    clamped : ndarray, same shape and (floating) dtype
    """
    a = np.asarray(image)
    return np.maximum(a, np.zeros((), dtype=a.dtype))
