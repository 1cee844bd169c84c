"""The Ineichen-Perez clear sky (lt_addon/sun/clear_sky.py) against pvlib's, a test-only
reference in the development venv (requirements.txt)."""

import numpy as np
import pytest

from relightable_textures.lt_addon.sun import clear_sky as cs

pvlib = pytest.importorskip("pvlib")
pd = pytest.importorskip("pandas")


@pytest.mark.parametrize("altitude, tl", [(0.0, 3.0), (0.0, 2.0), (1500.0, 4.5), (3000.0, 6.0)])
def test_ineichen_equals_pvlib(altitude, tl):
    times = pd.date_range("2026-01-01", "2026-12-31 23:00", freq="37h", tz="UTC")
    doy = times.dayofyear.to_numpy() + times.hour.to_numpy() / 24.0
    zen = np.linspace(0.0, 95.0, len(times))          # every zenith, to below the horizon
    ref = pvlib.clearsky.ineichen(
        pd.Series(zen, index=times),
        pvlib.atmosphere.get_absolute_airmass(
            pvlib.atmosphere.get_relative_airmass(pd.Series(zen, index=times)),
            pvlib.atmosphere.alt2pres(altitude)),
        tl, altitude=altitude,
        dni_extra=pvlib.irradiance.get_extra_radiation(doy))
    ghi, dni, dhi = cs.ineichen(zen, doy, tl, altitude)
    for got, want in ((ghi, ref["ghi"]), (dni, ref["dni"]), (dhi, ref["dhi"])):
        want = np.nan_to_num(want.to_numpy(), nan=0.0)
        assert np.allclose(got, want, rtol=1e-9, atol=1e-9)
    assert (ghi[zen >= 90] == 0).all() and ghi.max() > 900 / (1 + altitude / 1e4) - 200


def test_clear_noon_at_sea_level_is_about_a_thousand_watts():
    # the textbook figure: a clear summer noon, sun 60 degrees high, GHI 800-950 W/m^2
    ghi, dni, dhi = cs.ineichen(30.0, 172, 3.0)
    assert 800 < ghi < 950 and 750 < dni < 950 and 50 < dhi < 150
    with pytest.raises(ValueError, match="Linke turbidity"):
        cs.ineichen(30.0, 172, 0.5)
