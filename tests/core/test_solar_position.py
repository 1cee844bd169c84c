"""NREL SPA (lt_addon/sun/solar_position.py): the paper's worked example, pvlib at places on
every continent and at both poles over a year of hours, and the Blender frame of the Sun
Position add-on.

Tolerances against pvlib: ``pvlib.solarposition.spa_python(..., how="numpy")`` (the method
``get_solarposition`` calls ``nrel_numpy``) is the same algorithm, float64 throughout, so the
two differ only by rounding. The largest part is pvlib's Julian day: it forms
``JD = t / 86400 + 2440587.5`` (float64 spacing 4.7e-10 days at JD 2.46e6: rounding moves
the sidereal time by up to 8e-8 degrees), where ours keeps days from J2000 (~300x finer); with
pvlib's JD substituted the zenith agrees to 2e-10 degrees (checked by hand). Measured on
2026's 8,760 hours: worst zenith 5.6e-8, direction 5.6e-8, azimuth 6.1e-7 degrees (Singapore,
the Sun near the zenith; benchmarks/bench_solar_position.py). Hence 1e-6 degrees for the
zenith and for the angle between the two Sun directions, and for the azimuth where the Sun
is between 1 and 85 degrees high: near the zenith an azimuth is ill-conditioned (1/cos e:
at 89.9 degrees a 1e-7 degree error in hour angle is 6e-5 degrees of azimuth), and at the
horizon the refraction formula is steep.
"""

import datetime as dt

import numpy as np
import pytest

from relightable_textures.lt_addon.sun import solar_position as sp
from relightable_textures.lt_addon.sun.solar_position import (solar_position, sun_direction,
                                                               posix_seconds)

#: (name, latitude N, longitude E, elevation m): every continent and both poles.
PLACES = [
    ("London", 51.5074, -0.1278, 11.0),             # Europe
    ("Reykjavik", 64.1466, -21.9426, 20.0),         # Europe, sub-arctic
    ("New York", 40.7128, -74.0060, 10.0),          # North America
    ("Golden CO (NREL)", 39.742476, -105.1786, 1830.14),
    ("Sao Paulo", -23.5505, -46.6333, 760.0),       # South America
    ("Nairobi", -1.2921, 36.8219, 1795.0),          # Africa
    ("Cape Town", -33.9249, 18.4241, 10.0),         # Africa, 33.9 S
    ("Singapore", 1.3521, 103.8198, 15.0),          # Asia, equatorial
    ("Tokyo", 35.6762, 139.6503, 40.0),             # Asia
    ("Sydney", -33.8688, 151.2093, 20.0),           # Oceania
    ("McMurdo", -77.846, 166.676, 10.0),            # Antarctica
    ("North Pole", 90.0, 0.0, 0.0),
    ("South Pole", -90.0, 0.0, 2835.0),
]

TOL_DEG = 1e-6


def _year_of_hours(year=2026):
    return np.arange(np.datetime64(f"{year}-01-01T00:00"), np.datetime64(f"{year + 1}-01-01T00:00"),
                     np.timedelta64(1, "h"))


def _angle_deg(a, b):
    """Angle between unit vectors, accurate for tiny angles."""
    return np.degrees(2.0 * np.arcsin(np.clip(np.linalg.norm(a - b, axis=-1) / 2.0, 0, 1)))


# --- the paper's worked example (Reda & Andreas 2004, Table A5.1), no pvlib needed ---------

PAPER = dict(instants=np.datetime64("2003-10-17T19:30:30"),      # 12:30:30 at UTC-7
             latitude=39.742476, longitude=-105.1786, elevation_m=1830.14)
PAPER_AIR = dict(pressure_hpa=820.0, temperature_c=11.0, delta_t=67.0)


def test_the_papers_example_zenith_and_azimuth():
    r = solar_position(**PAPER, **PAPER_AIR)
    assert r.zenith == pytest.approx(50.11162, abs=1e-5)
    assert r.azimuth == pytest.approx(194.34024, abs=1e-5)
    assert r.elevation_unrefracted == pytest.approx(39.872046, abs=1e-6)
    assert r.elevation == pytest.approx(90.0 - 50.11162, abs=1e-5)


def test_the_papers_intermediate_values():
    """L, B, R use every row of Table A4.2 and the nutation every row of A4.3: a wrong term
    shows here at the paper's printed precision."""
    posix = posix_seconds(PAPER["instants"])
    assert sp.julian_day(posix) == pytest.approx(2452930.312847, abs=1e-6)
    days = sp._days_from_j2000(np.atleast_1d(posix))
    jce = (days + 67.0 / 86400.0) / 36525.0
    L, B, R = sp.heliocentric(jce / 10.0)
    assert L[0] == pytest.approx(24.0182616917, abs=1e-9)
    assert B[0] == pytest.approx(-0.0001011219, abs=1e-10)
    assert R[0] == pytest.approx(0.9965422974, abs=1e-10)
    dpsi, deps = sp.nutation(jce)
    assert dpsi[0] == pytest.approx(-0.00399840, abs=1e-8)
    assert deps[0] == pytest.approx(0.00166657, abs=1e-8)
    nu, alpha, delta, _ = sp._ephemeris(days, np.array([67.0]))
    assert nu[0] == pytest.approx(318.5119, abs=1e-4)
    assert alpha[0] == pytest.approx(202.22741, abs=1e-5)
    assert delta[0] == pytest.approx(-9.31434, abs=1e-5)


def test_the_tables_have_the_papers_term_counts():
    counts = {k: len(v) for k, v in sp._TERMS.items()}
    assert counts == {"L0": 64, "L1": 34, "L2": 20, "L3": 7, "L4": 3, "L5": 1, "B0": 5,
                      "B1": 2, "R0": 40, "R1": 10, "R2": 6, "R3": 2, "R4": 1}
    assert sp._NUT.shape == (63, 9)
    assert np.array_equal(sp._NUT_Y, np.round(sp._NUT_Y))


# --- inputs, shapes and units ---------------------------------------------------------------

def test_instants_in_any_form_give_the_same_sun():
    t = np.datetime64("2026-06-21T12:00:00")
    aware = dt.datetime(2026, 6, 21, 13, 0, tzinfo=dt.timezone(dt.timedelta(hours=1)))
    a = solar_position(t, 51.5, -0.1)
    b = solar_position(posix_seconds(t), 51.5, -0.1)
    c = solar_position(np.array([aware], dtype=object), 51.5, -0.1)
    d = solar_position(t.astype("datetime64[ns]"), 51.5, -0.1)
    for r in (b, c, d):
        assert np.allclose(r.zenith, a.zenith, rtol=0, atol=1e-12)
        assert np.allclose(r.azimuth, a.azimuth, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="naive"):
        solar_position(np.array([dt.datetime(2026, 6, 21, 12)], dtype=object), 51.5, -0.1)


def test_instants_broadcast_against_places():
    t = _year_of_hours()[:48]
    lat = np.array([p[1] for p in PLACES])
    lon = np.array([p[2] for p in PLACES])
    both = solar_position(t[:, None], lat, lon)
    assert both.zenith.shape == (48, len(PLACES)) and both.zenith.dtype == np.float64
    for j in (0, 7, len(PLACES) - 1):
        one = solar_position(t, lat[j], lon[j])
        assert np.array_equal(one.zenith, both.zenith[:, j])
        assert np.array_equal(one.azimuth, both.azimuth[:, j])


def test_refraction_lifts_a_low_sun_and_follows_pressure_and_temperature():
    t = np.datetime64("2026-06-21T20:00:00")                 # London, about 2 degrees high
    base = solar_position(t, 51.5, -0.1)
    assert 0 < base.elevation - base.elevation_unrefracted < 0.5
    thin = solar_position(t, 51.5, -0.1, pressure_hpa=500.0)
    warm = solar_position(t, 51.5, -0.1, temperature_c=35.0)
    lift = base.elevation - base.elevation_unrefracted
    assert thin.elevation - thin.elevation_unrefracted == pytest.approx(lift * 500 / 1013.25)
    assert warm.elevation - warm.elevation_unrefracted < lift
    night = solar_position(np.datetime64("2026-06-21T00:00:00"), 51.5, -0.1)
    assert night.elevation == night.elevation_unrefracted    # no refraction far below


def test_noon_sun_stands_south_in_the_north_and_north_in_the_south():
    t = np.datetime64("2026-12-21T12:00:00")
    # within a few degrees: 12:00 UTC is ~2 minutes after solar noon at longitude 0 that day
    assert np.cos(np.radians(solar_position(t, 51.5, 0.0).azimuth)) < -0.99      # south
    assert np.cos(np.radians(solar_position(t, -33.9, 0.0).azimuth)) > 0.99      # north
    # the December solstice: the Sun at the tropic of Capricorn, overhead at noon there
    assert solar_position(t, -23.44, 0.0).elevation > 89.0


# --- the Blender frame: the Sun Position add-on's convention ---------------------------------

def _addon_vector(azimuth_deg, elevation_deg, north_offset_deg):
    """blender-addons sun_position/sun_calc.py: ``azimuth += north_offset``; then
    get_sun_vector with phi = -azimuth, theta = pi/2 - elevation:
    (sin(phi) sin(-theta), sin(theta) cos(phi), cos(theta))."""
    phi = -np.radians(azimuth_deg + north_offset_deg)
    theta = np.pi / 2 - np.radians(elevation_deg)
    return np.array([np.sin(phi) * np.sin(-theta), np.sin(theta) * np.cos(phi), np.cos(theta)])


def test_sun_direction_north_is_plus_y_and_east_plus_x():
    assert np.allclose(sun_direction(0.0, 0.0), [0, 1, 0], atol=1e-15)
    assert np.allclose(sun_direction(0.0, 90.0), [1, 0, 0], atol=1e-15)
    assert np.allclose(sun_direction(0.0, 180.0), [0, -1, 0], atol=1e-15)
    assert np.allclose(sun_direction(90.0, 123.0), [0, 0, 1], atol=1e-15)
    # North Offset 90: the scene's north is +X (turned from +Y towards +X)
    assert np.allclose(sun_direction(0.0, 0.0, north_deg=90.0), [1, 0, 0], atol=1e-15)


def test_sun_direction_matches_the_addons_vector():
    rng = np.random.default_rng(7)
    az, el, north = rng.uniform(0, 360, 50), rng.uniform(-10, 90, 50), rng.uniform(-180, 180, 50)
    ours = sun_direction(el, az, north)
    assert ours.shape == (50, 3)
    assert np.allclose(np.linalg.norm(ours, axis=1), 1.0)
    for k in range(50):
        assert np.allclose(ours[k], _addon_vector(az[k], el[k], north[k]), atol=1e-14)


# --- against pvlib (test-only dependency) -----------------------------------------------------

def _pvlib():
    return pytest.importorskip(
        "pvlib.solarposition",
        reason="pvlib is a test-only dependency (requirements.txt; make venv installs it)")


def _pvlib_year(pvs, t, lat, lon, h):
    import pandas as pd

    p = pvs.spa_python(pd.DatetimeIndex(t, tz="UTC"), lat, lon, altitude=h, pressure=101325.0,
                       temperature=12.0, delta_t=sp.DELTA_T_2020S, how="numpy")
    return p


def worst_differences(pvs, t, places=PLACES):
    """{name: (zenith, azimuth, direction, unrefracted elevation)} worst |difference| in
    degrees over ``t`` against pvlib's spa_python (azimuth where 1 < elevation < 85)."""
    out = {}
    for name, lat, lon, h in places:
        ours = solar_position(t, lat, lon, h, pressure_hpa=1013.25, temperature_c=12.0,
                              delta_t=sp.DELTA_T_2020S)
        p = _pvlib_year(pvs, t, lat, lon, h)
        dz = np.abs(ours.zenith - p["apparent_zenith"].to_numpy())
        daz = np.abs((ours.azimuth - p["azimuth"].to_numpy() + 180.0) % 360.0 - 180.0)
        mid = (ours.elevation > 1.0) & (ours.elevation < 85.0)
        theirs = sun_direction(p["apparent_elevation"].to_numpy(), p["azimuth"].to_numpy())
        dang = _angle_deg(sun_direction(ours.elevation, ours.azimuth), theirs)
        de0 = np.abs(ours.elevation_unrefracted - p["elevation"].to_numpy())
        out[name] = (float(dz.max()), float(daz[mid].max()) if mid.any() else 0.0,
                     float(dang.max()), float(de0.max()))
    return out


def test_agrees_with_pvlib_spa_over_a_year_of_hours_everywhere():
    pvs = _pvlib()
    t = _year_of_hours()
    worst = worst_differences(pvs, t)
    bad = {k: v for k, v in worst.items() if max(v) > TOL_DEG}
    assert not bad, bad


def test_agrees_with_pvlib_in_other_centuries():
    """SPA's range is -2000..6000; pvlib and ours agree far from the present too (the
    periodic terms' JME powers, the obliquity polynomial)."""
    pvs = _pvlib()
    t = np.arange(np.datetime64("1850-03-01T00:00"), np.datetime64("1850-03-03T00:00"),
                  np.timedelta64(1, "h"))
    t2 = np.arange(np.datetime64("2150-09-01T00:00"), np.datetime64("2150-09-03T00:00"),
                   np.timedelta64(1, "h"))
    for tt in (t, t2):
        worst = worst_differences(pvs, tt, PLACES[:3])
        assert max(max(v) for v in worst.values()) < 1e-5, worst
