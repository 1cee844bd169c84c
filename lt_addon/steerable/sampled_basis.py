"""Sampled basis of steerable lights (Ashikhmin & Shirley 2002, sec. 3 eq. 3 and sec. 6.1).

Instead of baking the sign-changing basis lights ``b_ij`` themselves, bake ``K >= N`` copies of
the *steered light* centred at chosen points ``(x0_k, y0_k)`` of the disk domain:

    L_k(x, y) = sum_ij C[k, ij] b_ij(x, y),      C[k, ij] = c_i(x0_k) c_j(y0_k)

(:func:`coefficient_matrix`). Rendering is linear in the light, so the baked images satisfy
``S = C B`` and the basis images are ``B = C^{-1} S`` (least squares if ``K > N``). Any centre set
works as long as ``C`` is well conditioned; ``cond(C)`` is always computed and reported.

* Default centres (:func:`default_centres`): an ``N1 x N1`` tensor grid on ``[-s, s]^2``. Because
  the basis is a tensor product, ``C = C1 (x) C1`` (Kronecker) and ``cond(C) = cond(C1)**2``; the
  extent ``s`` minimising ``cond(C1)`` is found per N1 (rounded to 0.01). For N1 = 7 it is 0.81
  (cond 1.19); the design note's s = 0.85 gives cond 1.48.
* Centres outside the unit disk (the grid's corners, r up to s * sqrt 2) are **valid**: such a
  light is centred off the hemisphere but its lobe, tails and ringing still lie partly on it, and
  its environment image is simply the steered function restricted to the hemisphere. Only the
  matrix ``C`` matters for the solve.
* The paper's own set (:func:`ring_centres`) -- 8 azimuths x 6 heights plus the zenith -- is
  singular when the 8 azimuths are aligned with the axes (cond ~1e17); the paper's offset of the
  azimuths by pi/3 ("to avoid singularity") makes it invertible but poorly conditioned
  (cond ~1e4).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..sphere.hemisphere import direction_from_az_el, hemisphere_to_disk
from .basis import (
    SteerableBasis1D,
    environment_image,
    paper_basis,
    steer_images,
    steering_coefficients,
)

#: cond(C) above which :func:`build_sampled_basis` warns (noise in the baked images is amplified
#: by up to this factor in the basis images).
WARN_CONDITION = 1e3
#: cond(C) above which :func:`build_sampled_basis` refuses (numerically singular for float64 work
#: on noisy float32 images).
MAX_CONDITION = 1e8

#: Pixels per chunk in the basis transform (bounds float64 temporaries to ~chunk * K * 8 bytes).
_CHUNK = 1 << 18


class SingularCentreSetWarning(UserWarning):
    """The sampled light centres give a badly conditioned coefficient matrix."""


def coefficient_matrix(basis: SteerableBasis1D, centres, sigma=None) -> np.ndarray:
    """Coefficient matrix ``C[k, ij] = c_i(x0_k) c_j(y0_k)`` of a set of light centres.

    Parameters
    ----------
    basis : SteerableBasis1D
    centres : array_like, shape (K, 2)
        Light centres in the disk domain.
    sigma : array_like, shape (N1,), optional
        Gibbs factors used in the *baked* lights (normally none).

    Returns
    -------
    C : ndarray, shape (K, N1 * N1), float64
    """
    c = np.asarray(centres, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"centres must have shape (K, 2), got {c.shape}")
    return steering_coefficients(basis, c, sigma)


def _grid_condition(basis: SteerableBasis1D, extent: float) -> float:
    g = np.linspace(-extent, extent, basis.order)
    return float(np.linalg.cond(basis.steering_coefficients(g)) ** 2)


def default_grid_extent(basis: SteerableBasis1D) -> float:
    """Half-width ``s`` of the default ``N1 x N1`` centre grid that minimises ``cond(C)``.

    Grid search over ``s`` in [0.05, 1.0] (step 0.01, so the result is a round number);
    ``cond(C) = cond(C1)**2`` with ``C1[k, i] = c_i(g_k)``.

    Returns
    -------
    s : float
    """
    if basis.order == 1:
        return 0.0
    cand = np.round(np.arange(0.05, 1.0 + 1e-9, 0.01), 2)
    conds = [_grid_condition(basis, s) for s in cand]
    return float(cand[int(np.argmin(conds))])


def default_centres(order: int = 7, extent: float | None = None,
                    basis: SteerableBasis1D | None = None) -> np.ndarray:
    """Default sampled-light centres: an ``order x order`` tensor grid on ``[-s, s]^2``.

    Parameters
    ----------
    order : int
        N1 (2 .. 12 tested).
    extent : float, optional
        Grid half-width ``s``; default :func:`default_grid_extent` of ``basis``.
    basis : SteerableBasis1D, optional
        Default :func:`.steerable.paper_basis` of this order.

    Returns
    -------
    centres : ndarray, shape (order * order, 2), float64
        Row ``k = a * order + b`` is ``(g_a, g_b)`` with ``g = linspace(-s, s, order)``.
        Corner centres lie outside the unit disk; that is fine (module docstring).
    """
    basis = paper_basis(order) if basis is None else basis
    if basis.order != order:
        raise ValueError(f"basis.order = {basis.order} does not match order = {order}")
    s = default_grid_extent(basis) if extent is None else float(extent)
    if not np.isfinite(s) or s <= 0:
        raise ValueError(f"extent must be a positive finite number, got {extent!r}")
    g = np.linspace(-s, s, order)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], axis=-1)


def ring_centres(n_azimuth: int = 8, n_heights: int = 6, phase_deg: float = 0.0,
                 include_zenith: bool = True) -> np.ndarray:
    """Centres on rings of constant height: the paper's sec. 6.1 layout.

    ``n_azimuth`` azimuths ``phase + 360 m / n_azimuth`` times ``n_heights`` heights
    ``z = h / n_heights`` (h = 0 .. n_heights - 1, so the horizon ring is included), plus the
    zenith. With the defaults this is the azimuthally 8-fold symmetric set, which is **singular**
    for the product basis; ``phase_deg = 60`` (the paper's pi/3) is invertible but has
    cond ~1.3e4.

    Returns
    -------
    centres : ndarray, shape (n_azimuth * n_heights [+ 1], 2), float64
        Disk-domain points (all inside the unit disk).
    """
    az = phase_deg + 360.0 * np.arange(n_azimuth) / n_azimuth
    z = np.arange(n_heights) / n_heights
    el = np.degrees(np.arcsin(z))
    A, E = np.meshgrid(az, el, indexing="ij")
    d = direction_from_az_el(A.ravel(), E.ravel())
    if include_zenith:
        d = np.vstack([d, [0.0, 0.0, 1.0]])
    return hemisphere_to_disk(d)


@dataclass(frozen=True)
class SampledBasis:
    """A set of sampled steerable lights and the transform to/from the analytic basis.

    Attributes
    ----------
    basis : SteerableBasis1D
    centres : ndarray, shape (K, 2)
        Light centres (disk domain).
    matrix : ndarray, shape (K, N), float64
        ``C[k, ij] = c_i(x0_k) c_j(y0_k)``.
    condition_number : float
        ``cond(C)`` (2-norm).
    """

    basis: SteerableBasis1D
    centres: np.ndarray
    matrix: np.ndarray
    condition_number: float

    @property
    def n_lights(self) -> int:
        """K, the number of sampled lights to bake."""
        return int(self.centres.shape[0])

    def light_environment(self, k: int, height: int, width: int | None = None, *,
                          row_order: str, dtype=np.float32) -> np.ndarray:
        """Equirectangular image of sampled light ``k`` (see :func:`.steerable.environment_image`).

        Returns
        -------
        image : ndarray, shape (height, width), ``dtype``; zero below the horizon.
        """
        if not 0 <= int(k) < self.n_lights:
            raise ValueError(f"light index must be in [0, {self.n_lights}), got {k}")
        return environment_image(self.basis, self.centres[int(k)], height, width,
                                 row_order=row_order, dtype=dtype)

    def to_basis_images(self, sampled_images, *, dtype=np.float64, return_residual=False):
        """Transform baked sampled-light images to analytic-basis images, ``B = C^{-1} S``.

        Parameters
        ----------
        sampled_images : array_like, shape (K, ...)
            Images baked under the sampled lights, e.g. (K, H, W, C), any float dtype.
        dtype : numpy dtype
            Output dtype. The solve runs in float64 chunk by chunk either way.
        return_residual : bool
            Also return ``||C B - S||_F / ||S||_F`` (computed in float64 before casting).

        Returns
        -------
        basis_images : ndarray, shape (N, ...), ``dtype``
        residual : float, only if ``return_residual``
            About 1e-16 * cond(C) for K = N; for K > N the least-squares misfit (noise).
        """
        S = np.asarray(sampled_images)
        K, N = self.matrix.shape
        if S.ndim < 1 or S.shape[0] != K:
            raise ValueError(f"sampled_images must have shape ({K}, ...), got {S.shape}")
        if not np.all(np.isfinite(S)):
            raise ValueError("sampled_images contains NaN or inf")
        flat = S.reshape(K, -1)
        out = np.empty((N, flat.shape[1]), dtype=dtype)
        C = self.matrix
        if K == N:
            lu = scipy.linalg.lu_factor(C)
            solve = lambda rhs: scipy.linalg.lu_solve(lu, rhs)  # noqa: E731
        else:
            pinv = np.linalg.pinv(C)
            solve = lambda rhs: pinv @ rhs  # noqa: E731
        num = 0.0
        den = 0.0
        for start in range(0, flat.shape[1], _CHUNK):
            rhs = flat[:, start:start + _CHUNK].astype(np.float64)
            X = solve(rhs)
            if return_residual:
                num += float(np.sum((C @ X - rhs) ** 2))
                den += float(np.sum(rhs ** 2))
            out[:, start:start + _CHUNK] = X
        out = out.reshape((N,) + S.shape[1:])
        if return_residual:
            return out, (np.sqrt(num / den) if den > 0 else 0.0)
        return out

    def to_sampled_images(self, basis_images, *, dtype=np.float64) -> np.ndarray:
        """Inverse transform, ``S = C B``.

        Parameters
        ----------
        basis_images : array_like, shape (N, ...)

        Returns
        -------
        sampled_images : ndarray, shape (K, ...), ``dtype``
        """
        B = np.asarray(basis_images)
        K, N = self.matrix.shape
        if B.ndim < 1 or B.shape[0] != N:
            raise ValueError(f"basis_images must have shape ({N}, ...), got {B.shape}")
        flat = B.reshape(N, -1)
        out = np.empty((K, flat.shape[1]), dtype=dtype)
        for start in range(0, flat.shape[1], _CHUNK):
            out[:, start:start + _CHUNK] = self.matrix @ flat[:, start:start + _CHUNK].astype(
                np.float64)
        return out.reshape((K,) + B.shape[1:])

    def steer(self, basis_images, xy0, sigma=None) -> np.ndarray:
        """Relight: ``image(x0, y0) = sum_ij c_ij(x0, y0) * basis_images[ij]`` (not clamped).

        Parameters
        ----------
        basis_images : array_like, shape (N, ...)
            Output of :meth:`to_basis_images` (float32 storage is fine).
        xy0 : array_like, shape (2,)
            Light centre in the disk domain.
        sigma : array_like, shape (N1,), optional
            Gibbs factors (run-time choice; no re-bake needed).

        Returns
        -------
        image : ndarray, shape (...), dtype of ``basis_images``
        """
        c = steering_coefficients(self.basis, np.asarray(xy0, dtype=np.float64).reshape(2), sigma)
        return steer_images(basis_images, c)

    def sampled_weights(self, xy0, sigma=None) -> np.ndarray:
        """Weights to steer directly from the *sampled* images (eq. 3): ``c(xy0) C^{-1}``.

        Parameters
        ----------
        xy0 : array_like, shape (..., 2)
        sigma : array_like, shape (N1,), optional

        Returns
        -------
        weights : ndarray, shape (..., K), float64
            ``image(xy0) = sum_k weights[k] * sampled_images[k]``.
        """
        c = steering_coefficients(self.basis, xy0, sigma)
        Cp = np.linalg.pinv(self.matrix)  # (N, K); exact inverse when K == N
        return c @ Cp

    def to_dict(self) -> dict:
        """JSON-serialisable description for bake metadata."""
        return {
            "basis": self.basis.to_dict(),
            "centres": self.centres.tolist(),
            "condition_number": float(self.condition_number),
            "flattening": "C[k, i*N1 + j] = c_i(x0_k) c_j(y0_k)",
        }


def build_sampled_basis(basis: SteerableBasis1D | None = None, centres=None, *,
                        warn_condition: float = WARN_CONDITION,
                        max_condition: float = MAX_CONDITION) -> SampledBasis:
    """Build a sampled basis and check that its coefficient matrix can be inverted.

    Parameters
    ----------
    basis : SteerableBasis1D, optional
        Default :func:`.steerable.paper_basis` (N1 = 7).
    centres : array_like, shape (K, 2), optional
        Light centres, ``K >= N1**2``; default :func:`default_centres`.
    warn_condition : float
        Emit :class:`SingularCentreSetWarning` if ``cond(C)`` exceeds this.
    max_condition : float
        Raise ``ValueError`` if ``cond(C)`` exceeds this (near-singular set).

    Returns
    -------
    SampledBasis
    """
    basis = paper_basis() if basis is None else basis
    centres = default_centres(basis.order, basis=basis) if centres is None else centres
    centres = np.asarray(centres, dtype=np.float64)
    if not np.all(np.isfinite(centres)):
        raise ValueError("centres contains NaN or inf")
    C = coefficient_matrix(basis, centres)
    K, N = C.shape
    if K < N:
        raise ValueError(f"need at least N = {N} sampled lights for N1 = {basis.order}, got {K}")
    cond = float(np.linalg.cond(C))
    if not np.isfinite(cond) or cond > max_condition:
        raise ValueError(f"coefficient matrix of the light centres is near-singular: "
                         f"cond(C) = {cond:.3g} > {max_condition:.3g}; choose other centres "
                         "(e.g. default_centres; azimuthally symmetric rings are singular)")
    if cond > warn_condition:
        warnings.warn(f"sampled light centres are badly conditioned: cond(C) = {cond:.3g}; "
                      "bake noise is amplified by up to this factor", SingularCentreSetWarning,
                      stacklevel=2)
    return SampledBasis(basis=basis, centres=centres, matrix=C, condition_number=cond)
