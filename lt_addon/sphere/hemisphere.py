"""Directions on the upper hemisphere, the area-preserving disk map and equirectangular pixels.

Conventions (used by every steerable-light module):

* A *direction* is a 3-vector in a right-handed frame with **z up** (Blender world frame, or the
  surface's tangent frame with the normal as z). The *upper hemisphere* is ``z >= 0``.
* *Azimuth* is measured from +x toward +y, in degrees; *elevation* from the horizon (z = 0) toward
  +z, in degrees (zenith = 90).
* The *disk map* of Ashikhmin & Shirley (2002), eq. 7, sends a unit direction ``(xh, yh, zh)``
  with ``zh >= 0`` to the point ``(x, y) = (xh, yh) / sqrt(1 + zh)`` of the closed unit disk.
  Its inverse is ``zh = 1 - r**2``, ``(xh, yh) = (x, y) * sqrt(2 - r**2)``. The map preserves area
  up to a constant: a solid angle ``dOmega`` on the hemisphere is ``2 dA`` on the disk
  (hemisphere 2 pi sr <-> disk area pi). Zenith maps to the centre, the horizon to ``r = 1``,
  and ``cos(theta) = zh = 1 - r**2``.
* *Below-horizon directions* (``zh < 0``) have no disk point. :func:`hemisphere_to_disk` rejects
  them with a ``ValueError``; the light-evaluation and steering functions in
  :mod:`.steerable` define the steerable light to be **zero** there (radiance 0 below the
  horizon; the steering-coefficient vector of a below-horizon light direction is the zero
  vector, i.e. the light is off).
* Equirectangular images follow Cycles' ``direction_to_equirectangular`` (see
  :func:`direction_to_equirect_uv`).

Every function is vectorised over leading axes and validates its input at the boundary: NaN or
inf raise ``ValueError`` naming the argument.
"""

from __future__ import annotations

import numpy as np

#: Solid angle (sr) per unit area of the disk domain: dOmega = 2 dA (eq. 7 is area preserving).
SOLID_ANGLE_PER_DISK_AREA = 2.0

#: Tolerance for snapping values a hair outside the valid range (rounding) back onto it.
_SNAP = 1e-9

_ROW_ORDERS = ("top_first", "bottom_first")


def _finite_array(a, name: str, last: int | None = None) -> np.ndarray:
    """Return ``a`` as float64, checking finiteness and the size of the last axis."""
    arr = np.asarray(a, dtype=np.float64)
    if last is not None and (arr.ndim == 0 or arr.shape[-1] != last):
        raise ValueError(f"{name} must have shape (..., {last}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name} contains {bad} non-finite value(s) (NaN or inf); "
                         "directions and disk points must be finite")
    return arr


def normalize_directions(directions) -> np.ndarray:
    """Unit vectors along ``directions``.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Finite, non-zero vectors (any length).

    Returns
    -------
    unit : ndarray, shape (..., 3), float64

    Raises
    ------
    ValueError
        On NaN/inf, a wrong last axis, or a zero-length vector.
    """
    d = _finite_array(directions, "directions", 3)
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError("directions contains a zero-length vector; a direction needs a length")
    return d / norm


def is_upper_hemisphere(directions) -> np.ndarray:
    """Boolean mask of directions with ``z >= 0`` (the horizon counts as upper).

    Parameters
    ----------
    directions : array_like, shape (..., 3)

    Returns
    -------
    mask : ndarray of bool, shape (...)
    """
    d = normalize_directions(directions)
    return d[..., 2] >= -_SNAP


def hemisphere_to_disk(directions) -> np.ndarray:
    """Map upper-hemisphere directions to the unit disk (paper eq. 7).

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Directions (normalised here) with ``z >= 0``; the horizon ``z = 0`` maps to ``r = 1``.

    Returns
    -------
    xy : ndarray, shape (..., 2), float64
        ``(x, y) = (xh, yh) / sqrt(1 + zh)``, ``x**2 + y**2 = 1 - zh <= 1``.

    Raises
    ------
    ValueError
        On NaN/inf, zero vectors, or any direction below the horizon (``z < 0``); callers that
        accept such directions mask them first (see :func:`is_upper_hemisphere`).
    """
    d = normalize_directions(directions)
    z = d[..., 2]
    if np.any(z < -_SNAP):
        n = int(np.count_nonzero(z < -_SNAP))
        raise ValueError(f"{n} direction(s) lie below the horizon (z < 0); the disk map of "
                         "eq. 7 covers only the upper hemisphere")
    z = np.clip(z, 0.0, 1.0)
    return d[..., :2] / np.sqrt(1.0 + z)[..., None]


def disk_to_hemisphere(xy) -> np.ndarray:
    """Map points of the unit disk to upper-hemisphere unit directions (inverse of eq. 7).

    Parameters
    ----------
    xy : array_like, shape (..., 2)
        Points with ``x**2 + y**2 <= 1`` (values a rounding error outside are snapped onto
        the circle).

    Returns
    -------
    directions : ndarray, shape (..., 3), float64
        ``zh = 1 - r**2``, ``(xh, yh) = (x, y) * sqrt(2 - r**2)``; unit length.

    Raises
    ------
    ValueError
        On NaN/inf or points outside the unit disk (they have no direction; note that light
        *centres* outside the disk are still valid, see :mod:`.sampled_basis`).
    """
    p = _finite_array(xy, "xy", 2)
    r2 = np.sum(p * p, axis=-1)
    if np.any(r2 > 1.0 + _SNAP):
        n = int(np.count_nonzero(r2 > 1.0 + _SNAP))
        raise ValueError(f"{n} point(s) lie outside the unit disk (r > 1); only the closed unit "
                         "disk maps to the hemisphere")
    scale = np.where(r2 > 1.0, 1.0 / np.sqrt(np.maximum(r2, 1e-300)), 1.0)
    p = p * scale[..., None]
    r2 = np.minimum(r2, 1.0)
    z = 1.0 - r2
    xy_h = p * np.sqrt(2.0 - r2)[..., None]
    return np.concatenate([xy_h, z[..., None]], axis=-1)


def direction_from_az_el(azimuth_deg, elevation_deg) -> np.ndarray:
    """Unit direction from azimuth and elevation in degrees.

    Parameters
    ----------
    azimuth_deg : array_like, shape (...)
        Degrees from +x toward +y.
    elevation_deg : array_like, shape (...)
        Degrees above the horizon, in [-90, 90] (negative = below the horizon).

    Returns
    -------
    directions : ndarray, shape (..., 3), float64
        ``(cos el cos az, cos el sin az, sin el)``.
    """
    az = _finite_array(azimuth_deg, "azimuth_deg")
    el = _finite_array(elevation_deg, "elevation_deg")
    if np.any(np.abs(el) > 90.0 + 1e-9):
        raise ValueError("elevation_deg must lie in [-90, 90]")
    az, el = np.broadcast_arrays(np.radians(az), np.radians(el))
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1)


def az_el_from_direction(directions) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation (degrees) of directions.

    Parameters
    ----------
    directions : array_like, shape (..., 3)

    Returns
    -------
    azimuth_deg : ndarray, shape (...)
        In (-180, 180], from +x toward +y (0 at the poles).
    elevation_deg : ndarray, shape (...)
        In [-90, 90].
    """
    d = normalize_directions(directions)
    az = np.degrees(np.arctan2(d[..., 1], d[..., 0]))
    el = np.degrees(np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])))
    return az, el


def direction_to_equirect_uv(directions) -> np.ndarray:
    """Blender/Cycles equirectangular texture coordinates of directions.

    Cycles' ``direction_to_equirectangular`` (``intern/cycles/kernel/camera/projection.h``) is
    ``direction_to_equirectangular_range(dir, (-2 pi, pi, -pi, pi))`` with
    ``u = (atan2(y, x) - pi) / (-2 pi)`` and ``v = (acos(z) - pi) / (-pi)``, i.e.::

        u = 0.5 - atan2(y, x) / (2 pi)      (wrapped into [0, 1))
        v = 1 - acos(z) / pi  = 0.5 + elevation / pi

    so +x is the image centre column (u = 0.5), +y is at u = 0.25, -x at the left/right seam,
    the zenith at v = 1 and the horizon at v = 0.5. ``v = 0`` is the **bottom** image row in
    Blender (``Image.pixels`` is stored bottom row first).

    Parameters
    ----------
    directions : array_like, shape (..., 3)

    Returns
    -------
    uv : ndarray, shape (..., 2), float64, each in [0, 1]
    """
    d = normalize_directions(directions)
    u = np.mod(0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2.0 * np.pi), 1.0)
    v = 1.0 - np.arccos(np.clip(d[..., 2], -1.0, 1.0)) / np.pi
    return np.stack([u, v], axis=-1)


def equirect_uv_to_direction(uv) -> np.ndarray:
    """Inverse of :func:`direction_to_equirect_uv` (Cycles ``equirectangular_to_direction``).

    Parameters
    ----------
    uv : array_like, shape (..., 2)

    Returns
    -------
    directions : ndarray, shape (..., 3), float64, unit length
        ``phi = pi - 2 pi u``, ``theta = pi - pi v``,
        ``(sin theta cos phi, sin theta sin phi, cos theta)``.
    """
    p = _finite_array(uv, "uv", 2)
    phi = np.pi - 2.0 * np.pi * p[..., 0]
    theta = np.pi - np.pi * p[..., 1]
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def equirect_pixel_directions(height: int, width: int, *, row_order: str) -> np.ndarray:
    """Directions through the pixel centres of an equirectangular image.

    Parameters
    ----------
    height, width : int
        Image size in pixels (``width`` is usually ``2 * height``).
    row_order : {"top_first", "bottom_first"}
        ``"top_first"``: row 0 is the top of the image (zenith side; OpenEXR/NumPy image
        convention). ``"bottom_first"``: row 0 is the bottom (nadir side; Blender
        ``Image.pixels`` convention). Pixel ``(row, col)`` has ``u = (col + 0.5) / width`` and
        ``v = (j + 0.5) / height`` with ``j = row`` (bottom first) or ``height - 1 - row``
        (top first).

    Returns
    -------
    directions : ndarray, shape (height, width, 3), float64, unit length
    """
    if row_order not in _ROW_ORDERS:
        raise ValueError(f"row_order must be one of {_ROW_ORDERS}, got {row_order!r}")
    if int(height) < 1 or int(width) < 1:
        raise ValueError(f"image size must be positive, got {height} x {width}")
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    if row_order == "top_first":
        v = v[::-1]
    uu, vv = np.meshgrid(u, v)
    return equirect_uv_to_direction(np.stack([uu, vv], axis=-1))
