"""Intensity calibration of steered results (Ashikhmin & Shirley 2002, sec. 6.1, and a better one).

A steerable light is a broad, ringing lobe, not a directional light of unit irradiance, so a
steered image must be rescaled. All calibrations here are expressed on the *flat-plane
irradiance*: a flat plane facing +z lit by the steered light centred on direction ``w0``
receives

    E(w0) = sum_ij c_ij(w0) E_ij,     E_ij = integral over the hemisphere of b_ij cos(theta) dOmega

(:func:`flat_plane_basis_irradiance`; computed on the disk with ``dOmega = 2 dA`` and
``cos theta = 1 - r**2``, by Gauss-Legendre in r and the trapezoid rule in phi). ``E`` is itself
steerable: one dot product per light direction. The target is the cosine law of a directional
light of unit normal irradiance, ``cos(theta0)``.

Methods (select by name, :data:`METHODS`):

``"paper_linear"``
    The paper's two-point linear map ``v -> gain * v + offset * reference``: normal incidence
    gives the reference value (the albedo, i.e. the flat plane under unit normal irradiance) and
    grazing incidence gives 0. ``gain = 1 / (E(zenith) - E(horizon))``,
    ``offset = -E(horizon) * gain`` (``E(horizon)`` averaged over azimuth). Constant in ``w0``.
``"steerable_cos"``
    ``gain(w0) = cos(theta0) / max(E(w0), floor * E(zenith))``, ``offset = 0``: exact cosine law
    for a flat plane wherever ``E(w0)`` is above the floor; the floor keeps the gain bounded near
    grazing (where ``cos theta0 -> 0`` as well, so the gain goes to 0 at the horizon).

Apply with :func:`calibrate_image`; measure with :func:`flat_plane_calibration_error`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sphere.hemisphere import normalize_directions
from .basis import (
    SOLID_ANGLE_PER_DISK_AREA,
    SteerableBasis1D,
    basis_2d,
    steering_coefficients_for_direction,
)
from ..sphere.hemisphere import direction_from_az_el

#: Calibration method names.
METHODS = ("paper_linear", "steerable_cos")

#: Default floor of the steerable-cos calibration, as a fraction of E(zenith).
DEFAULT_FLOOR = 0.05


def flat_plane_basis_irradiance(basis: SteerableBasis1D, n_radial: int = 64,
                                n_azimuth: int = 256) -> np.ndarray:
    """``E_ij``: irradiance of a flat plane (normal +z) under each 2D basis light.

    Parameters
    ----------
    basis : SteerableBasis1D
    n_radial : int
        Gauss-Legendre nodes in ``r`` on [0, 1].
    n_azimuth : int
        Trapezoid nodes in ``phi`` (periodic: spectrally accurate). Gibbs factors act on the
        steering coefficients, not on ``E_ij``, so they do not enter here.

    Returns
    -------
    E : ndarray, shape (N1 * N1,), float64
        ``E_ij = 2 * integral over the unit disk of b_i(x) b_j(y) (1 - r**2) dA`` (sr-weighted
        radiance units). A constant radiance 1 would give ``pi``.
    """
    t, wt = np.polynomial.legendre.leggauss(int(n_radial))
    r = 0.5 * (t + 1.0)
    wr = 0.5 * wt
    phi = np.arange(int(n_azimuth)) * (2.0 * np.pi / n_azimuth)
    R, P = np.meshgrid(r, phi, indexing="ij")
    xy = np.stack([R * np.cos(P), R * np.sin(P)], axis=-1)
    weight = (wr[:, None] * (2.0 * np.pi / n_azimuth)) * R * (1.0 - R * R)
    B = basis_2d(basis, xy)
    return SOLID_ANGLE_PER_DISK_AREA * np.einsum("ij,ijk->k", weight, B)


def flat_plane_response(basis: SteerableBasis1D, directions, E=None, sigma=None) -> np.ndarray:
    """``E(w0) = c(w0) . E``: flat-plane irradiance under the light steered to ``w0``.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Light directions (z = plane normal). Below the horizon the result is 0.
    E : ndarray, shape (N,), optional
        Precomputed :func:`flat_plane_basis_irradiance`.
    sigma : array_like, shape (N1,), optional
        Gibbs factors used when steering.

    Returns
    -------
    E_w0 : ndarray, shape (...), float64
    """
    E = flat_plane_basis_irradiance(basis) if E is None else np.asarray(E, dtype=np.float64)
    return steering_coefficients_for_direction(basis, directions, sigma) @ E


@dataclass(frozen=True)
class Calibration:
    """A calibration of steered results to a unit-irradiance directional light.

    Attributes
    ----------
    method : str
        One of :data:`METHODS`.
    basis : SteerableBasis1D
    E : ndarray, shape (N,)
        Flat-plane basis irradiances ``E_ij``.
    E_zenith : float
        ``E`` for the light at the zenith.
    E_horizon : float
        ``E`` for the light on the horizon, averaged over 16 azimuths.
    floor : float
        Floor (fraction of ``E_zenith``) of ``"steerable_cos"``.
    sigma : ndarray or None
        Gibbs factors the calibration was computed for.
    """

    method: str
    basis: SteerableBasis1D
    E: np.ndarray
    E_zenith: float
    E_horizon: float
    floor: float = DEFAULT_FLOOR
    sigma: np.ndarray | None = None

    def gain_offset(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Gain and offset for light directions.

        Parameters
        ----------
        directions : array_like, shape (..., 3)

        Returns
        -------
        gain, offset : ndarray, shape (...), float64
            Calibrated = ``gain * steered + offset * reference`` where ``reference`` is the
            value of the same surface as a flat plane under unit normal irradiance (the
            albedo image; only needed if ``offset != 0``). Both are 0 below the horizon.
        """
        d = normalize_directions(directions)
        up = d[..., 2] >= 0
        cos0 = np.clip(d[..., 2], 0.0, 1.0)
        if self.method == "paper_linear":
            g = 1.0 / (self.E_zenith - self.E_horizon)
            gain = np.where(up, g, 0.0)
            offset = np.where(up, -self.E_horizon * g, 0.0)
        else:
            Ew = flat_plane_response(self.basis, d, self.E, self.sigma)
            denom = np.maximum(Ew, self.floor * self.E_zenith)
            gain = np.where(up, cos0 / denom, 0.0)
            offset = np.zeros_like(gain)
        return gain, offset

    def calibrated_flat_response(self, directions) -> np.ndarray:
        """Calibrated flat-plane irradiance (ideal: ``cos theta0``, 0 below the horizon).

        Returns
        -------
        response : ndarray, shape (...), float64
        """
        d = normalize_directions(directions)
        gain, offset = self.gain_offset(d)
        Ew = flat_plane_response(self.basis, d, self.E, self.sigma)
        return np.where(d[..., 2] >= 0, gain * Ew + offset, 0.0)

    def to_dict(self) -> dict:
        """JSON-serialisable parameters."""
        return {"method": self.method, "E": [float(v) for v in self.E],
                "E_zenith": float(self.E_zenith), "E_horizon": float(self.E_horizon),
                "floor": float(self.floor),
                "sigma": None if self.sigma is None else [float(v) for v in self.sigma]}


def make_calibration(basis: SteerableBasis1D, method: str = "steerable_cos",
                     floor: float = DEFAULT_FLOOR, sigma=None) -> Calibration:
    """Build a calibration by name.

    Parameters
    ----------
    basis : SteerableBasis1D
    method : {"paper_linear", "steerable_cos"}
    floor : float
        Floor of ``"steerable_cos"`` as a fraction of ``E(zenith)``, in (0, 1).
    sigma : array_like, shape (N1,), optional
        Gibbs factors used when steering.

    Returns
    -------
    Calibration
    """
    if method not in METHODS:
        raise ValueError(f"unknown calibration method {method!r}; choose one of {METHODS}")
    if not 0.0 < floor < 1.0:
        raise ValueError(f"floor must be in (0, 1), got {floor}")
    sig = None if sigma is None else np.asarray(sigma, dtype=np.float64)
    E = flat_plane_basis_irradiance(basis)
    Ez = float(flat_plane_response(basis, [0.0, 0.0, 1.0], E, sig))
    az = np.arange(16) * 22.5
    Eh = float(np.mean(flat_plane_response(basis, direction_from_az_el(az, 0.0), E, sig)))
    if Ez - Eh <= 0 or Ez <= 0:
        raise ValueError(f"flat-plane response is not peaked at the zenith (E_zenith = {Ez:.3g}, "
                         f"E_horizon = {Eh:.3g}); cannot calibrate")
    return Calibration(method=method, basis=basis, E=E, E_zenith=Ez, E_horizon=Eh,
                       floor=float(floor), sigma=sig)


def calibrate_image(calibration: Calibration, steered_image, direction, reference_image=None):
    """Apply a calibration to one steered image.

    Parameters
    ----------
    calibration : Calibration
    steered_image : array_like, shape (...)
        Result of steering (before or after clamping).
    direction : array_like, shape (3,)
        The light direction it was steered to.
    reference_image : array_like, broadcastable to ``steered_image``, optional
        The surface's response to unit normal irradiance on a flat plane (the albedo image);
        required by ``"paper_linear"`` (its offset is non-zero).

    Returns
    -------
    image : ndarray, same shape as ``steered_image``, its dtype if floating
    """
    img = np.asarray(steered_image)
    gain, offset = calibration.gain_offset(np.asarray(direction, dtype=np.float64).reshape(3))
    gain, offset = float(gain), float(offset)
    out = img * np.asarray(gain, dtype=img.dtype if np.issubdtype(img.dtype, np.floating)
                           else np.float64)
    if offset != 0.0:
        if reference_image is None:
            raise ValueError(f"calibration {calibration.method!r} has a non-zero offset and needs "
                             "reference_image (the flat-plane / albedo response)")
        out = out + offset * np.asarray(reference_image, dtype=out.dtype)
    return out


def flat_plane_calibration_error(basis: SteerableBasis1D, method: str,
                                 elevations_deg=None, azimuths_deg=(0.0, 22.5, 45.0),
                                 floor: float = DEFAULT_FLOOR, sigma=None) -> dict:
    """Measure a calibration: calibrated flat-plane response vs the cosine law.

    Parameters
    ----------
    basis : SteerableBasis1D
    method : {"paper_linear", "steerable_cos"}
    elevations_deg : array_like, shape (M,), optional
        Light elevations; default 0, 1, ..., 90.
    azimuths_deg : sequence of float
        Azimuths to evaluate (the response is not exactly rotation invariant: the basis lives
        on a square).
    floor, sigma : see :func:`make_calibration`.

    Returns
    -------
    dict
        ``method``, ``elevations_deg`` (list), ``response`` (list over elevations of the mean
        over azimuths), ``cos_law`` (list), ``max_abs_error``, ``rms_error`` (over all
        elevation/azimuth pairs), ``max_abs_error_above_10deg`` (excluding near-grazing).
    """
    cal = make_calibration(basis, method, floor, sigma)
    el = np.arange(0.0, 90.0 + 1e-9, 1.0) if elevations_deg is None else np.asarray(
        elevations_deg, dtype=np.float64)
    az = np.asarray(azimuths_deg, dtype=np.float64)
    A, Elv = np.meshgrid(az, el, indexing="ij")  # (naz, nel)
    d = direction_from_az_el(A, Elv)
    resp = cal.calibrated_flat_response(d)
    target = np.sin(np.radians(Elv))
    err = resp - target
    hi = Elv >= 10.0
    return {
        "method": method,
        "elevations_deg": [float(v) for v in el],
        "response": [float(v) for v in resp.mean(axis=0)],
        "cos_law": [float(v) for v in np.sin(np.radians(el))],
        "max_abs_error": float(np.max(np.abs(err))),
        "rms_error": float(np.sqrt(np.mean(err ** 2))),
        "max_abs_error_above_10deg": float(np.max(np.abs(err[hi]))) if np.any(hi) else 0.0,
    }


def light_environment(order: int, calibration: str, direction, height: int,
                      intensity: float = 1.0):
    """The equirectangular image (height, 2 * height) of the calibrated steerable light of
    ``order`` centred on ``direction`` (3,), scaled by ``intensity``, row 0 at the bottom, and
    the calibration's gain: what ``relight light-env`` writes (its negative lobes are part of
    the light). float64."""
    from ..sphere.hemisphere import hemisphere_to_disk
    from .basis import environment_image, paper_basis

    basis = paper_basis(order)
    gain, _ = make_calibration(basis, calibration).gain_offset(direction)
    env = environment_image(basis, hemisphere_to_disk(direction), height, 2 * height,
                            row_order="bottom_first", dtype=np.float64)
    return env * float(gain) * intensity, float(gain)
