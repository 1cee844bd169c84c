"""Real spherical harmonics: the classic PRT baseline for per-vertex transport (Sloan et al. 2002).

Used to compare with eigentransport at an equal number of per-vertex coefficients
(Nowrouzezahrai et al. 2008, Fig. 3 and 10). Order ``l`` means all bands ``0..l``:
``(l + 1)^2`` coefficients, index ``i = b^2 + b + m`` for band ``b`` and ``-b <= m <= b``.

Definition (orthonormal over the sphere, no Condon-Shortley phase; z up, ``phi`` from +x
toward +y)::

    Y_b^0  = Pn_b^0(cos theta) / sqrt(2 pi)
    Y_b^m  = Pn_b^m(cos theta) cos(m phi) / sqrt(pi)      (m > 0)
    Y_b^-m = Pn_b^m(cos theta) sin(m phi) / sqrt(pi)

with ``Pn`` the associated Legendre functions normalised to ``int_{-1}^{1} Pn^2 dx = 1``,
evaluated by the standard stable recurrences on the normalised functions (no factorials, so no
overflow for high orders)::

    Pn_0^0 = sqrt(1/2)
    Pn_m^m = sqrt((2m + 1) / (2m)) sin(theta) Pn_{m-1}^{m-1}
    Pn_{m+1}^m = sqrt(2m + 3) x Pn_m^m
    Pn_b^m = a (x Pn_{b-1}^m - c Pn_{b-2}^m),  a = sqrt((4b^2 - 1) / (b^2 - m^2)),
                                              c = sqrt(((b-1)^2 - m^2) / (4 (b-1)^2 - 1))

Projection of transport rows uses the solid-angle quadrature of the direction set:
``t = Y^T diag(dw) T^T`` (``method="quadrature"``), or the weighted least-squares fit
``argmin_t ||diag(dw)^{1/2} (T - Y t)||`` (``method="lstsq"``, identical when ``Y`` is exactly
orthonormal under the quadrature, and the best SH approximation in the discrete sphere-L2 norm
otherwise). Shading from coefficients, ``rho / pi * t . l`` with ``l = Y^T Lw``, equals
``rho / pi * sum_j T_rec[j] Lw_j`` of the reconstruction ``T_rec = Y t`` exactly.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .hemisphere import normalize_directions

METHODS = ("quadrature", "lstsq")


def sh_count(order: int) -> int:
    """Number of coefficients ``(order + 1)^2`` of bands ``0..order``."""
    order = _order(order)
    return (order + 1) ** 2


def sh_order_for_count(count: int) -> int:
    """Largest order ``l`` with ``(l + 1)^2 <= count`` (``count >= 1``)."""
    count = int(count)
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    l = int(np.floor(np.sqrt(count))) - 1
    while (l + 2) ** 2 <= count:
        l += 1
    while (l + 1) ** 2 > count:
        l -= 1
    return l


def sh_index(band: int, m: int) -> int:
    """Flat index ``band^2 + band + m`` of ``Y_band^m``."""
    if abs(m) > band:
        raise ValueError(f"|m| must be <= band, got band {band}, m {m}")
    return band * band + band + m


def _order(order) -> int:
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 0:
        raise ValueError(f"order must be a non-negative integer, got {order!r}")
    return int(order)


def real_sh(directions, order: int) -> np.ndarray:
    """Real spherical harmonics of bands ``0..order`` at directions.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Normalised here.
    order : int

    Returns
    -------
    Y : ndarray, shape (..., (order + 1)^2), float64
    """
    order = _order(order)
    d = normalize_directions(directions)
    lead = d.shape[:-1]
    d = d.reshape(-1, 3)
    x = np.clip(d[:, 2], -1.0, 1.0)                 # cos(theta)
    st = np.hypot(d[:, 0], d[:, 1])                 # sin(theta) >= 0
    phi = np.arctan2(d[:, 1], d[:, 0])
    out = np.empty((d.shape[0], (order + 1) ** 2))
    pmm = np.full(x.shape, np.sqrt(0.5))
    inv_sqrt_pi = 1.0 / np.sqrt(np.pi)
    for m in range(order + 1):
        if m > 0:
            pmm = np.sqrt((2.0 * m + 1.0) / (2.0 * m)) * st * pmm
        cos_m, sin_m = np.cos(m * phi), np.sin(m * phi)
        p_prev, p = None, pmm
        for b in range(m, order + 1):
            if b == m + 1:
                p_prev, p = p, np.sqrt(2.0 * m + 3.0) * x * pmm
            elif b > m + 1:
                a = np.sqrt((4.0 * b * b - 1.0) / (b * b - m * m))
                c = np.sqrt(((b - 1.0) ** 2 - m * m) / (4.0 * (b - 1.0) ** 2 - 1.0))
                p_prev, p = p, a * (x * p - c * p_prev)
            if m == 0:
                out[:, b * b + b] = p / np.sqrt(2.0 * np.pi)
            else:
                out[:, b * b + b + m] = p * cos_m * inv_sqrt_pi
                out[:, b * b + b - m] = p * sin_m * inv_sqrt_pi
    return out.reshape(lead + (out.shape[1],))


def _check_T(T, S: int) -> np.ndarray:
    t = np.asarray(T, dtype=np.float64)
    if t.ndim != 2 or t.shape[1] != S:
        raise ValueError(f"T must have shape (V, {S}), got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("T contains NaN or inf")
    return t


def sh_project(T, directions, solid_angles, order: int, method: str = "quadrature") -> np.ndarray:
    """SH coefficients of each row of sampled transport.

    Parameters
    ----------
    T : array_like, shape (V, S)
        Transport at the sample directions.
    directions : array_like, shape (S, 3)
    solid_angles : array_like, shape (S,)
        sr.
    order : int
    method : {"quadrature", "lstsq"}

    Returns
    -------
    coefficients : ndarray, shape (V, (order + 1)^2), float64
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    Y = real_sh(directions, order)
    w = np.asarray(solid_angles, dtype=np.float64)
    if w.shape != (Y.shape[0],):
        raise ValueError(f"solid_angles must have shape ({Y.shape[0]},), got {w.shape}")
    t = _check_T(T, Y.shape[0])
    rhs = (t * w) @ Y                               # (V, n)
    if method == "quadrature":
        return rhs
    G = Y.T @ (Y * w[:, None])                     # (n, n) Gram matrix under the quadrature
    return scipy.linalg.solve(G, rhs.T, assume_a="pos").T


def sh_reconstruct(coefficients, directions) -> np.ndarray:
    """Transport rows from SH coefficients at directions.

    Parameters
    ----------
    coefficients : array_like, shape (V, n), n a square
    directions : array_like, shape (S, 3)

    Returns
    -------
    T : ndarray, shape (V, S), float64
    """
    c = np.asarray(coefficients, dtype=np.float64)
    n = c.shape[-1]
    order = int(round(np.sqrt(n))) - 1
    if (order + 1) ** 2 != n:
        raise ValueError(f"the number of SH coefficients must be a square, got {n}")
    return c @ real_sh(directions, order).T


def sh_project_lighting(L_weighted, directions, order: int) -> np.ndarray:
    """SH coefficients ``l = Y^T Lw`` of weighted lighting (radiance x solid angle).

    Parameters
    ----------
    L_weighted : array_like, shape (S,) or (S, C)
    directions : array_like, shape (S, 3)
    order : int

    Returns
    -------
    ndarray, shape (n,) or (n, C)
    """
    Y = real_sh(directions, order)
    lw = np.asarray(L_weighted, dtype=np.float64)
    if lw.shape[:1] != (Y.shape[0],) or lw.ndim > 2:
        raise ValueError(f"L_weighted must have shape ({Y.shape[0]},) or ({Y.shape[0]}, C), "
                         f"got {lw.shape}")
    return Y.T @ lw


def sh_shade(coefficients, light_coefficients, albedo=1.0) -> np.ndarray:
    """Diffuse shading ``rho / pi * t . l`` from SH transport and lighting coefficients.

    Parameters
    ----------
    coefficients : array_like, shape (V, n)
    light_coefficients : array_like, shape (n,) or (n, C)
    albedo : float or array_like broadcastable to the result

    Returns
    -------
    B : ndarray, shape (V,) or (V, C)
    """
    c = np.asarray(coefficients, dtype=np.float64)
    lc = np.asarray(light_coefficients, dtype=np.float64)
    if lc.shape[0] != c.shape[1]:
        raise ValueError(f"light_coefficients must have {c.shape[1]} rows, got {lc.shape}")
    B = c @ lc
    a = np.asarray(albedo, dtype=np.float64)
    if a.ndim == 1 and B.ndim == 2 and a.shape[0] == B.shape[0]:
        a = a[:, None]
    return B * a / np.pi
