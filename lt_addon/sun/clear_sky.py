"""Clear-sky irradiance: the Ineichen-Perez model (bpy-free).

For a sun study's radiation map (:mod:`.radiation`): the direct normal (DNI), diffuse
horizontal (DHI) and global horizontal (GHI) irradiance of a cloudless sky, in W/m^2, from the
Sun's apparent zenith, the day of the year, the site's height and a Linke turbidity (the
atmosphere's haze: about 2 for very clean mountain air, 3 for a rural site, 4-6 for cities and
summer haze; Remund et al. 2003 map it by place and month).

- Extraterrestrial normal irradiance: Spencer (1971), 1366.1 W/m^2 at 1 AU.
- Relative air mass: Kasten & Young (1989), from the apparent (refracted) zenith; absolute:
  times the pressure of the standard atmosphere at the site's height over sea-level pressure.
- Ineichen & Perez (2002), "A new airmass independent formulation for the Linke turbidity
  coefficient", Solar Energy 73(3) 151-157, eqs. for GHI and the beam with the paper's
  empirical correction (SE 73, 157 and 312), as pvlib implements them
  (``pvlib.clearsky.ineichen``, ``perez_enhancement=False``): tests/core/test_clear_sky.py
  compares every quantity with pvlib's at 1e-9.

Units: degrees, metres, W/m^2. Night (zenith >= 90): 0.
"""

from __future__ import annotations

import numpy as np

#: The solar constant pvlib's and the Spencer formula use, W/m^2.
SOLAR_CONSTANT = 1366.1


def extra_radiation(day_of_year) -> np.ndarray:
    """Extraterrestrial normal irradiance (W/m^2) on ``day_of_year`` (1-366, fractional
    allowed): Spencer's Fourier series of the Earth-Sun distance."""
    b = 2.0 * np.pi * (np.asarray(day_of_year, np.float64) - 1.0) / 365.0
    return SOLAR_CONSTANT * (1.00011 + 0.034221 * np.cos(b) + 0.00128 * np.sin(b)
                             + 0.000719 * np.cos(2 * b) + 7.7e-05 * np.sin(2 * b))


def relative_airmass(apparent_zenith_deg) -> np.ndarray:
    """Kasten & Young (1989) relative air mass; NaN at and below the horizon (zenith > 90)."""
    z = np.asarray(apparent_zenith_deg, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        am = 1.0 / (np.cos(np.radians(z)) + 0.50572 * (96.07995 - z) ** -1.6364)
    return np.where(z > 90.0, np.nan, am)


def site_pressure(altitude_m) -> np.ndarray:
    """Pressure (Pa) of the standard atmosphere at ``altitude_m`` above sea level."""
    return 100.0 * ((44331.514 - np.asarray(altitude_m, np.float64)) / 11880.516) ** (
        1.0 / 0.1902632)


def ineichen(apparent_zenith_deg, day_of_year, linke_turbidity: float = 3.0,
             altitude_m: float = 0.0):
    """``(ghi, dni, dhi)`` W/m^2 of a clear sky (module docstring), arrays of the inputs'
    broadcast shape; 0 where the Sun is down."""
    z = np.asarray(apparent_zenith_deg, np.float64)
    tl = float(linke_turbidity)
    alt = float(altitude_m)
    if not 1.0 <= tl <= 10.0:
        raise ValueError(f"Linke turbidity must be in 1..10, got {tl:g}")
    cos_z = np.maximum(np.cos(np.radians(z)), 0.0)
    am = relative_airmass(z) * site_pressure(alt) / 101325.0
    am = np.where(np.isnan(am), np.inf, am)                   # below the horizon: no light
    e0 = extra_radiation(day_of_year)
    fh1, fh2 = np.exp(-alt / 8000.0), np.exp(-alt / 1250.0)
    cg1, cg2 = 5.09e-05 * alt + 0.868, 3.92e-05 * alt + 0.0387
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        ghi = cg1 * e0 * cos_z * np.maximum(np.exp(-cg2 * am * (fh1 + fh2 * (tl - 1.0))), 0.0)
        beam = e0 * np.maximum((0.664 + 0.163 / fh1) * np.exp(-0.09 * am * (tl - 1.0)), 0.0)
        corr = (1.0 - (0.1 - 0.2 * np.exp(-tl)) / (0.1 + 0.882 / fh1)) / cos_z
        beam2 = ghi * np.minimum(np.maximum(corr, 0.0), 1e20)
    dni = np.minimum(beam, np.nan_to_num(beam2, nan=0.0, posinf=0.0))
    up = z < 90.0
    ghi, dni = np.where(up, ghi, 0.0), np.where(up, dni, 0.0)
    dhi = ghi - dni * cos_z
    return ghi, dni, dhi
