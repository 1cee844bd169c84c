"""Steerable basis lights of Ashikhmin & Shirley (2002), sections 5-6.

Design (all fitting in float64):

1. **Numerical 1D design** (:func:`eigen_basis_1d`). Sample the target light, a 1D Gaussian
   ``f(x, x0) = exp(-(x - x0)**2 / width)``, on ``n`` uniform points of ``[-1, 1]``
   (``numpy.linspace(-1, 1, n)``, end points included) for both ``x`` and ``x0``. The matrix
   ``F_ij = f(x_i, x0_j)`` is symmetric, so its SVD is an eigen-decomposition
   ``F = U diag(lam) U^T``; keeping the ``N1`` largest eigenvalues gives the SVD-optimal rank-N1
   approximation (paper eq. 10) with basis functions ``b_k = sqrt(lam_k) u_k`` and the *same*
   functions as steering coefficients. Sampled on ``n`` points the ``b_k`` do not depend on ``n``
   (up to discretisation), so two ``n`` can be compared directly.

2. **Analytic fit** (:func:`fit_steerable_basis_1d`), paper eq. 11::

       b_i(x) = a_i cos(i w x + 3 (i - 1) pi / 2),   i = 1 .. N1

   The paper's index runs from **1** (``i = 1, ..., 7``): frequencies ``w, 2w, ..., N1 w`` and
   phases ``0, 3pi/2, 3pi, ...``, i.e. ``cos, sin, -cos, -sin, ...``, alternately even and odd.
   This matches the numerical eigenvectors (sine-like modes that nearly vanish at ``x = +-1``,
   the k-th one with ``k - 1`` zeros inside the interval). Indexing from 0 would give a zero
   function for ``i = 0`` (``cos(0 - 3pi/2) = 0``), so the 1-based reading is the only one that
   works. ``w`` and the ``a_i`` are fitted by nonlinear least squares
   (``scipy.optimize.least_squares``) to the numerical basis functions (eigenvector signs are
   fixed to agree with the analytic shapes first). The steering coefficients are the same
   functions: ``c_i(x0) = b_i(x0)``.

3. **2D product basis** (eq. 9): ``b_ij(x, y) = b_i(x) b_j(y)`` on the disk domain of
   :mod:`.hemisphere`, flattened with index ``k = i * N1 + j`` (``i`` for x, ``j`` for y, both
   0-based in arrays). Steering coefficients ``c_ij(x0, y0) = c_i(x0) c_j(y0)`` with the same
   flattening. The steered light is ``L(x, y; x0, y0) = sum_ij c_ij(x0, y0) b_ij(x, y)`` on the
   disk, mapped onto the hemisphere by eq. 7, and **zero below the horizon**.

4. **Gibbs reduction** (optional): sigma factors ``s_i`` multiply the steering coefficients,
   ``c_i -> s_i c_i``. Because the baked images are responses to the unchanged ``b_ij``, the
   factors can be switched at run time without re-baking; they broaden the lobe
   (see :func:`light_profile_1d` for the measured cost).

Units: lights are dimensionless radiance shapes (peak about 0.6 in 1D, 0.36 in 2D for the
paper's design); :mod:`.calibration` maps steered results to physical intensity.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..sphere.hemisphere import (
    equirect_pixel_directions,
    hemisphere_to_disk,
    is_upper_hemisphere,
    normalize_directions,
    SOLID_ANGLE_PER_DISK_AREA,
)

#: Paper's design parameters (section 5): target width, basis order, sample count.
PAPER_WIDTH = 0.01
PAPER_ORDER = 7
PAPER_SAMPLES = 100


def _check_finite(a, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf; steerable lights need finite coordinates")
    return arr


def _check_design(order: int, width: float, n: int) -> None:
    if int(order) != order or order < 1:
        raise ValueError(f"order (N1) must be a positive integer, got {order!r}")
    if not (np.isfinite(width) and width > 0):
        raise ValueError(f"width must be a positive finite number, got {width!r}")
    if int(n) != n or n < 2 * order:
        raise ValueError(f"n (samples) must be an integer >= 2 * order = {2 * order}, got {n!r}")


def gaussian_kernel_matrix(n: int = PAPER_SAMPLES, width: float = PAPER_WIDTH):
    """Sampled target light ``F_ij = exp(-(x_i - x0_j)**2 / width)`` (paper sec. 5).

    Parameters
    ----------
    n : int
        Samples per axis, uniform on [-1, 1] with both end points.
    width : float
        The Gaussian's width parameter (0.01 in the paper), in disk-domain units squared.

    Returns
    -------
    x : ndarray, shape (n,), float64
        Sample positions (used for both ``x`` and ``x0``).
    F : ndarray, shape (n, n), float64, symmetric
    """
    x = np.linspace(-1.0, 1.0, int(n))
    F = np.exp(-((x[:, None] - x[None, :]) ** 2) / width)
    return x, F


def eigen_basis_1d(order: int = PAPER_ORDER, width: float = PAPER_WIDTH, n: int = PAPER_SAMPLES):
    """Numerical steerable basis: leading eigenvectors of the sampled Gaussian kernel.

    Parameters
    ----------
    order : int
        N1, number of 1D basis functions kept.
    width : float
        Target Gaussian width parameter.
    n : int
        Samples on [-1, 1].

    Returns
    -------
    x : ndarray, shape (n,)
        Sample positions.
    basis : ndarray, shape (n, order), float64
        ``b_k(x_i) = sqrt(lam_k) u_k(x_i)``, columns sorted by decreasing eigenvalue. Signs are
        arbitrary here (:func:`fit_steerable_basis_1d` aligns them with eq. 11).
    eigenvalues : ndarray, shape (n,), float64
        All eigenvalues of ``F`` in decreasing order.
    """
    _check_design(order, width, n)
    x, F = gaussian_kernel_matrix(n, width)
    lam, U = np.linalg.eigh(F)
    idx = np.argsort(lam)[::-1]
    lam, U = lam[idx], U[:, idx]
    if lam[order - 1] <= 0:
        raise ValueError(f"kernel has fewer than {order} positive eigenvalues; "
                         "use a narrower width or a smaller order")
    basis = U[:, :order] * np.sqrt(lam[:order])
    return x, basis, lam


def _analytic(x: np.ndarray, w: float, a: np.ndarray) -> np.ndarray:
    i = np.arange(1, a.shape[0] + 1, dtype=np.float64)
    phase = 3.0 * (i - 1.0) * np.pi / 2.0
    return a * np.cos(i * w * x[..., None] + phase)


@dataclass(frozen=True)
class SteerableBasis1D:
    """Analytic 1D steerable basis ``b_i(x) = a_i cos(i w x + 3 (i - 1) pi / 2)``, i = 1..N1.

    Attributes
    ----------
    order : int
        N1 (number of 1D functions; the 2D basis has N1**2).
    w : float
        Base angular frequency (radians per disk-domain unit).
    a : ndarray, shape (order,)
        Amplitudes ``a_1 .. a_N1``.
    width : float
        Width parameter of the target Gaussian the basis was designed for.
    n_samples : int
        Samples used for the numerical design.
    eigenvalues : ndarray, shape (order + 1,)
        Leading eigenvalues of the sampled kernel (one beyond the kept ones).
    fit_rms : float
        RMS difference between analytic and numerical basis functions on the samples.
    fit_max : float
        Maximum absolute difference between them.
    kernel_error_fit : float
        ``||F - B_fit B_fit^T||_F`` (Frobenius, sampled kernel).
    kernel_error_optimal : float
        SVD-optimal rank-N1 error ``sqrt(sum_{k > N1} lam_k**2)``.
    """

    order: int
    w: float
    a: np.ndarray
    width: float = PAPER_WIDTH
    n_samples: int = PAPER_SAMPLES
    eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fit_rms: float = float("nan")
    fit_max: float = float("nan")
    kernel_error_fit: float = float("nan")
    kernel_error_optimal: float = float("nan")

    @property
    def size(self) -> int:
        """Number of 2D basis functions, N = N1**2."""
        return self.order * self.order

    @property
    def kernel_error_ratio(self) -> float:
        """``kernel_error_fit / kernel_error_optimal`` (1 = as good as the SVD)."""
        return self.kernel_error_fit / self.kernel_error_optimal

    def evaluate(self, x) -> np.ndarray:
        """1D basis functions ``b_i(x)``.

        Parameters
        ----------
        x : array_like, shape (...)
            Disk-domain coordinates (any real values; the design interval is [-1, 1]).

        Returns
        -------
        b : ndarray, shape (..., order), float64
        """
        return _analytic(_check_finite(x, "x"), self.w, np.asarray(self.a, dtype=np.float64))

    def steering_coefficients(self, x0, sigma=None) -> np.ndarray:
        """1D steering coefficients ``c_i(x0) = s_i b_i(x0)`` (same functions as the basis).

        Parameters
        ----------
        x0 : array_like, shape (...)
            Light centre coordinate.
        sigma : array_like, shape (order,), optional
            Gibbs/sigma factors ``s_i`` (see :func:`gibbs_factors`); default all ones.

        Returns
        -------
        c : ndarray, shape (..., order), float64
        """
        c = self.evaluate(x0)
        if sigma is not None:
            c = c * _check_sigma(sigma, self.order)
        return c

    def light(self, x, x0, sigma=None) -> np.ndarray:
        """Steered 1D light ``sum_i c_i(x0) b_i(x)``; ``x`` and ``x0`` broadcast."""
        return np.sum(self.evaluate(x) * self.steering_coefficients(x0, sigma), axis=-1)

    def to_dict(self) -> dict:
        """JSON-serialisable description (plain floats and lists)."""
        return {
            "order": int(self.order), "w": float(self.w), "a": [float(v) for v in self.a],
            "width": float(self.width), "n_samples": int(self.n_samples),
            "eigenvalues": [float(v) for v in self.eigenvalues],
            "fit_rms": float(self.fit_rms), "fit_max": float(self.fit_max),
            "kernel_error_fit": float(self.kernel_error_fit),
            "kernel_error_optimal": float(self.kernel_error_optimal),
            "formula": "b_i(x) = a_i cos(i w x + 3 (i-1) pi/2), i = 1..order",
        }

    @classmethod
    def from_dict(cls, d: dict) -> "SteerableBasis1D":
        """Inverse of :meth:`to_dict` (what a bake's metadata stores)."""
        return cls(order=int(d["order"]), w=float(d["w"]), a=np.asarray(d["a"], dtype=np.float64),
                   width=float(d.get("width", PAPER_WIDTH)),
                   n_samples=int(d.get("n_samples", PAPER_SAMPLES)),
                   eigenvalues=np.asarray(d.get("eigenvalues", []), dtype=np.float64),
                   fit_rms=float(d.get("fit_rms", "nan")), fit_max=float(d.get("fit_max", "nan")),
                   kernel_error_fit=float(d.get("kernel_error_fit", "nan")),
                   kernel_error_optimal=float(d.get("kernel_error_optimal", "nan")))


def _check_sigma(sigma, order: int) -> np.ndarray:
    s = _check_finite(sigma, "sigma")
    if s.shape != (order,):
        raise ValueError(f"sigma must have shape ({order},), got {s.shape}")
    return s


def fit_steerable_basis_1d(order: int = PAPER_ORDER, width: float = PAPER_WIDTH,
                           n: int = PAPER_SAMPLES) -> SteerableBasis1D:
    """Fit the paper's analytic basis (eq. 11) to the numerical eigen-basis.

    Parameters
    ----------
    order : int
        N1 (the paper uses 7).
    width : float
        Target Gaussian width parameter (paper: 0.01).
    n : int
        Samples on [-1, 1] for the numerical design (paper: 100).

    Returns
    -------
    SteerableBasis1D
        With ``w``, ``a`` and fit diagnostics. For the paper's parameters ``w = 1.4912``
        (paper: 1.492).

    Notes
    -----
    The initial guess is ``w = (pi / 2) / (1 + sqrt(width) / 2)`` (the sine modes of an
    interval of half-length about 1 with a soft edge) and ``a_k`` from projecting the numerical
    functions on the unit-amplitude analytic shapes. The residual is the stacked difference of all
    ``order`` functions on the ``n`` samples.
    """
    x, B, lam = eigen_basis_1d(order, width, n)
    w0 = 0.5 * np.pi / (1.0 + 0.5 * np.sqrt(width))
    shapes = _analytic(x, w0, np.ones(order))
    proj = np.sum(shapes * B, axis=0)
    B = B * np.where(proj < 0, -1.0, 1.0)  # eigenvector sign convention -> eq. 11 phases
    a0 = np.abs(proj) / np.sum(shapes * shapes, axis=0)

    def residual(p):
        return (_analytic(x, p[0], p[1:]) - B).ravel()

    res = least_squares(residual, np.concatenate([[w0], a0]), method="lm", xtol=1e-14,
                        ftol=1e-14, gtol=1e-14)
    if not res.success:
        raise RuntimeError(f"analytic basis fit did not converge: {res.message}")
    w, a = float(res.x[0]), np.array(res.x[1:], dtype=np.float64)
    if np.any(a < 0):  # a sign flip of a_i is the same basis; keep amplitudes positive
        raise RuntimeError("analytic fit produced a negative amplitude; the eigenvectors did not "
                           "match eq. 11 (width too large for this order?)")
    Bf = _analytic(x, w, a)
    _, F = gaussian_kernel_matrix(n, width)
    diff = Bf - B
    a = a.copy()
    a.setflags(write=False)  # paper_basis() shares this object: nobody may edit it in place
    eig = lam[: order + 1].copy()
    eig.setflags(write=False)
    return SteerableBasis1D(
        order=int(order), w=w, a=a, width=float(width), n_samples=int(n),
        eigenvalues=eig,
        fit_rms=float(np.sqrt(np.mean(diff ** 2))), fit_max=float(np.max(np.abs(diff))),
        kernel_error_fit=float(np.linalg.norm(F - Bf @ Bf.T)),
        kernel_error_optimal=float(np.sqrt(np.sum(lam[order:] ** 2))),
    )


@functools.lru_cache(maxsize=32)
def _cached_basis(order: int, width: float, n: int) -> SteerableBasis1D:
    return fit_steerable_basis_1d(order, width, n)


def paper_basis(order: int = PAPER_ORDER, width: float = PAPER_WIDTH,
                n: int = PAPER_SAMPLES) -> SteerableBasis1D:
    """The fitted basis for the given design, cached (defaults: the paper's 7 / 0.01 / 100)."""
    return _cached_basis(int(order), float(width), int(n))


# ----------------------------------------------------------------------------------------------
# Gibbs reduction


def gibbs_factors(order: int, kind: str = "lanczos") -> np.ndarray:
    """Sigma factors for reducing the ringing (negative lobes) of the steered light.

    Parameters
    ----------
    order : int
        N1.
    kind : {"none", "lanczos", "fejer"}
        ``"lanczos"``: ``s_i = sinc(i / (N1 + 1))`` (Lanczos sigma factors, as used by Dobashi
        et al. 1995 after Hamming 1977); ``"fejer"``: ``s_i = 1 - i / (N1 + 1)`` (stronger);
        ``"none"``: ones. ``i = 1 .. N1`` is the frequency index of eq. 11.

    Returns
    -------
    sigma : ndarray, shape (order,), float64, in (0, 1]
    """
    i = np.arange(1, int(order) + 1, dtype=np.float64)
    if kind == "none":
        return np.ones_like(i)
    if kind == "lanczos":
        return np.sinc(i / (order + 1.0))
    if kind == "fejer":
        return 1.0 - i / (order + 1.0)
    raise ValueError(f"unknown Gibbs factor kind {kind!r}; use 'none', 'lanczos' or 'fejer'")


# ----------------------------------------------------------------------------------------------
# 2D product basis, steering coefficients, steered light


def _check_xy(xy, name: str) -> np.ndarray:
    p = _check_finite(xy, name)
    if p.ndim == 0 or p.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (..., 2), got {p.shape}")
    return p


def basis_2d(basis: SteerableBasis1D, xy) -> np.ndarray:
    """2D product basis ``b_ij(x, y) = b_i(x) b_j(y)`` on the disk domain.

    Parameters
    ----------
    basis : SteerableBasis1D
    xy : array_like, shape (..., 2)
        Disk-domain points (any real values; only the unit disk is the hemisphere).

    Returns
    -------
    b : ndarray, shape (..., N1 * N1), float64
        Flattened with ``k = i * N1 + j`` (``i`` indexes x, ``j`` indexes y).
    """
    p = _check_xy(xy, "xy")
    bx = basis.evaluate(p[..., 0])
    by = basis.evaluate(p[..., 1])
    return (bx[..., :, None] * by[..., None, :]).reshape(p.shape[:-1] + (basis.size,))


def steering_coefficients(basis: SteerableBasis1D, xy0, sigma=None) -> np.ndarray:
    """2D steering coefficients ``c_ij(x0, y0) = s_i s_j b_i(x0) b_j(y0)``.

    Parameters
    ----------
    basis : SteerableBasis1D
    xy0 : array_like, shape (..., 2)
        Light centres in the disk domain. Centres outside the unit disk are allowed (the lobe
        still lies partly on the hemisphere).
    sigma : array_like, shape (N1,), optional
        Gibbs factors (:func:`gibbs_factors`); default none.

    Returns
    -------
    c : ndarray, shape (..., N1 * N1), float64
        Same flattening as :func:`basis_2d`.
    """
    c = basis_2d(basis, xy0)
    if sigma is not None:
        s = _check_sigma(sigma, basis.order)
        c = c * np.outer(s, s).ravel()
    return c


def steering_coefficients_for_direction(basis: SteerableBasis1D, directions,
                                        sigma=None) -> np.ndarray:
    """Steering coefficients for light directions on the hemisphere.

    Parameters
    ----------
    basis : SteerableBasis1D
    directions : array_like, shape (..., 3)
        Light directions (towards the light, z up); normalised here.
    sigma : array_like, shape (N1,), optional
        Gibbs factors.

    Returns
    -------
    c : ndarray, shape (..., N1 * N1), float64
        ``c(hemisphere_to_disk(d))`` for ``z >= 0``; the **zero vector** for directions below
        the horizon (the light is off: steering gives a black image, as a point light below
        the surface's horizon would).
    """
    d = normalize_directions(directions)
    up = is_upper_hemisphere(d)
    dd = np.where(up[..., None], d, np.array([0.0, 0.0, 1.0]))
    c = steering_coefficients(basis, hemisphere_to_disk(dd), sigma)
    return np.where(up[..., None], c, 0.0)


def steered_light_disk(basis: SteerableBasis1D, xy, xy0, sigma=None) -> np.ndarray:
    """Steered 2D light on the disk domain, ``sum_ij c_ij(xy0) b_ij(xy)``.

    Evaluated as the separable product ``(sum_i c_i(x0) b_i(x)) (sum_j c_j(y0) b_j(y))``.

    Parameters
    ----------
    xy : array_like, shape (..., 2)
    xy0 : array_like, shape (..., 2) or (2,)
        Broadcasts against ``xy``'s leading axes.

    Returns
    -------
    L : ndarray, shape (...), float64
    """
    p = _check_xy(xy, "xy")
    p0 = _check_xy(xy0, "xy0")
    return (basis.light(p[..., 0], p0[..., 0], sigma) * basis.light(p[..., 1], p0[..., 1], sigma))


def evaluate_light(basis: SteerableBasis1D, directions, xy0, sigma=None) -> np.ndarray:
    """Radiance of the steered light centred at ``xy0`` seen along ``directions``.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Directions (z up); normalised here.
    xy0 : array_like, shape (2,) or broadcastable (..., 2)
        Light centre in the disk domain (use :func:`.hemisphere.hemisphere_to_disk` to get it
        from a direction).

    Returns
    -------
    L : ndarray, shape (...), float64
        The steered light at ``hemisphere_to_disk(d)``; **zero below the horizon**.
    """
    d = normalize_directions(directions)
    up = is_upper_hemisphere(d)
    dd = np.where(up[..., None], d, np.array([0.0, 0.0, 1.0]))
    L = steered_light_disk(basis, hemisphere_to_disk(dd), xy0, sigma)
    return np.where(up, L, 0.0)


def evaluate_basis_on_hemisphere(basis: SteerableBasis1D, directions) -> np.ndarray:
    """All 2D basis lights ``b_ij`` along ``directions``, zero below the horizon.

    Returns
    -------
    b : ndarray, shape (..., N1 * N1), float64
    """
    d = normalize_directions(directions)
    up = is_upper_hemisphere(d)
    dd = np.where(up[..., None], d, np.array([0.0, 0.0, 1.0]))
    return np.where(up[..., None], basis_2d(basis, hemisphere_to_disk(dd)), 0.0)


def environment_image(basis: SteerableBasis1D, xy0, height: int, width: int | None = None, *,
                      row_order: str, sigma=None, dtype=np.float32) -> np.ndarray:
    """Equirectangular environment image of the steered light centred at ``xy0``.

    Blender/Cycles convention (verified against ``direction_to_equirectangular`` in
    ``intern/cycles/kernel/camera/projection.h``): pixel ``(u, v)`` looks along
    ``phi = pi - 2 pi u``, ``theta = pi (1 - v)`` (z up), i.e.
    ``u = 0.5 - atan2(y, x) / (2 pi)``, ``v = 0.5 + elevation / pi``; +x at the centre column.
    Each pixel holds the steered light at the disk point of its centre direction
    (:func:`.hemisphere.hemisphere_to_disk`); the lower half (v < 0.5) is zero.

    Parameters
    ----------
    basis : SteerableBasis1D
    xy0 : array_like, shape (2,)
        Light centre in the disk domain (may lie outside the unit disk).
    height : int
        Image rows.
    width : int, optional
        Image columns; default ``2 * height``.
    row_order : {"top_first", "bottom_first"}
        Row 0 = top (zenith side; OpenEXR/NumPy) or bottom (Blender ``Image.pixels``).
    sigma : array_like, shape (N1,), optional
        Gibbs factors (bake lights normally use none).
    dtype : numpy dtype
        Output dtype; computed in float64. Values may be negative (the lobes ring).

    Returns
    -------
    image : ndarray, shape (height, width), ``dtype``
        Radiance (single channel; replicate for RGB).
    """
    width = 2 * int(height) if width is None else int(width)
    dirs = equirect_pixel_directions(int(height), width, row_order=row_order)
    return evaluate_light(basis, dirs, np.asarray(xy0, dtype=np.float64), sigma).astype(dtype)


def basis_environment_image(basis: SteerableBasis1D, k: int, height: int, width: int | None = None,
                            *, row_order: str, dtype=np.float32) -> np.ndarray:
    """Equirectangular image of one 2D basis light ``b_k`` (``k = i * N1 + j``).

    Same conventions as :func:`environment_image`; lower hemisphere zero. Useful when the
    renderer accepts negative radiance and the basis is baked directly instead of a sampled
    basis.

    Returns
    -------
    image : ndarray, shape (height, width), ``dtype``
    """
    if not 0 <= int(k) < basis.size:
        raise ValueError(f"basis index k must be in [0, {basis.size}), got {k}")
    width = 2 * int(height) if width is None else int(width)
    dirs = equirect_pixel_directions(int(height), width, row_order=row_order)
    up = is_upper_hemisphere(dirs)
    dd = np.where(up[..., None], dirs, np.array([0.0, 0.0, 1.0]))
    xy = hemisphere_to_disk(dd)
    i, j = divmod(int(k), basis.order)
    val = basis.evaluate(xy[..., 0])[..., i] * basis.evaluate(xy[..., 1])[..., j]
    return np.where(up, val, 0.0).astype(dtype)


# ----------------------------------------------------------------------------------------------
# Steering images


def steer_images(basis_images, coefficients) -> np.ndarray:
    """Linear combination ``sum_k c_k image_k`` of basis images (the run-time relighting step).

    Parameters
    ----------
    basis_images : array_like, shape (N, ...)
        Basis images (responses to ``b_k``), any trailing shape, e.g. (N, H, W, C). Kept in
        their dtype (float32 is the intended storage; the sum accumulates in that dtype).
    coefficients : array_like, shape (N,)
        Steering coefficients, e.g. from :func:`steering_coefficients`.

    Returns
    -------
    image : ndarray, shape (...), dtype of ``basis_images`` (float64 if not floating)

    Notes
    -----
    No clamping here; apply :func:`.clamp.clamp_steered` afterwards (paper sec. 7.1).
    """
    imgs = np.asarray(basis_images)
    if not np.issubdtype(imgs.dtype, np.floating):
        imgs = imgs.astype(np.float64)
    c = _check_finite(coefficients, "coefficients")
    if c.ndim != 1 or c.shape[0] != imgs.shape[0]:
        raise ValueError(f"coefficients must have shape ({imgs.shape[0]},), got {c.shape}")
    flat = imgs.reshape(imgs.shape[0], -1)
    out = c.astype(imgs.dtype) @ flat
    return out.reshape(imgs.shape[1:])


# ----------------------------------------------------------------------------------------------
# Measurements of the light shape


def light_profile_1d(basis: SteerableBasis1D, x0: float = 0.0, sigma=None,
                     samples: int = 4001) -> dict:
    """Peak, full width at half maximum and negative-lobe ratio of the steered 1D light.

    Parameters
    ----------
    basis : SteerableBasis1D
    x0 : float
        Light centre.
    sigma : array_like, shape (N1,), optional
        Gibbs factors (to measure their lobe-width cost).
    samples : int
        Evaluation points on [-1, 1].

    Returns
    -------
    dict
        ``peak`` (max value), ``peak_x``, ``fwhm`` (width of the main lobe at half the peak, in
        disk units, linearly interpolated between samples), ``negative_lobe_ratio``
        (most negative value / peak; paper: "about one to five"), ``target_fwhm`` of the
        Gaussian ``exp(-(x - x0)**2 / width)``: ``2 sqrt(width ln 2)``.
    """
    x = np.linspace(-1.0, 1.0, int(samples))
    f = basis.light(x, float(x0), sigma)
    k = int(np.argmax(f))
    peak = float(f[k])
    half = 0.5 * peak
    # walk left/right from the peak to the half-maximum crossings
    left = k
    while left > 0 and f[left] > half:
        left -= 1
    right = k
    while right < f.size - 1 and f[right] > half:
        right += 1

    def cross(i0, i1):
        if f[i0] == f[i1]:
            return x[i0]
        return x[i0] + (half - f[i0]) * (x[i1] - x[i0]) / (f[i1] - f[i0])

    xl = cross(left, left + 1) if f[left] <= half else x[left]
    xr = cross(right - 1, right) if f[right] <= half else x[right]
    return {
        "peak": peak, "peak_x": float(x[k]), "fwhm": float(xr - xl),
        "negative_lobe_ratio": float(np.min(f) / peak),
        "target_fwhm": float(2.0 * np.sqrt(basis.width * np.log(2.0))),
    }


def light_profile_2d(basis: SteerableBasis1D, xy0=(0.0, 0.0), sigma=None,
                     resolution: int = 401) -> dict:
    """Shape of the steered 2D light on the disk: peak location, widths, lobe solid angle.

    Parameters
    ----------
    basis : SteerableBasis1D
    xy0 : array_like, shape (2,)
        Light centre (disk domain).
    sigma : array_like, shape (N1,), optional
        Gibbs factors.
    resolution : int
        Grid points per axis on [-1, 1]^2 (grid step ``2 / (resolution - 1)``).

    Returns
    -------
    dict
        ``peak``, ``peak_xy`` (grid point of the maximum inside the unit disk), ``grid_step``,
        ``fwhm_x`` / ``fwhm_y`` (1D widths through the centre, disk units),
        ``half_max_solid_angle_sr`` (solid angle of the region above half the peak, using
        dOmega = 2 dA; the paper quotes "about 0.25 steradians" for its lights),
        ``negative_lobe_ratio`` (minimum over the disk / peak) and
        ``negative_energy_fraction`` (integral of the negative part / integral of |L|).
    """
    p0 = _check_xy(xy0, "xy0").reshape(2)
    g = np.linspace(-1.0, 1.0, int(resolution))
    h = g[1] - g[0]
    fx = basis.light(g, p0[0], sigma)
    fy = basis.light(g, p0[1], sigma)
    L = fx[:, None] * fy[None, :]  # L[ix, iy]
    inside = (g[:, None] ** 2 + g[None, :] ** 2) <= 1.0
    Lin = np.where(inside, L, -np.inf)
    ix, iy = np.unravel_index(int(np.argmax(Lin)), L.shape)
    peak = float(L[ix, iy])
    dA = h * h
    above = inside & (L >= 0.5 * peak)
    Lmask = np.where(inside, L, 0.0)
    prof_x = light_profile_1d(basis, float(p0[0]), sigma)
    prof_y = light_profile_1d(basis, float(p0[1]), sigma)
    return {
        "peak": peak, "peak_xy": [float(g[ix]), float(g[iy])], "grid_step": float(h),
        "fwhm_x": prof_x["fwhm"], "fwhm_y": prof_y["fwhm"],
        "half_max_solid_angle_sr": float(np.count_nonzero(above) * dA * SOLID_ANGLE_PER_DISK_AREA),
        "negative_lobe_ratio": float(np.min(np.where(inside, L, np.inf)) / peak),
        "negative_energy_fraction": float(np.sum(np.clip(-Lmask, 0, None)) /
                                          np.sum(np.abs(Lmask))),
    }
