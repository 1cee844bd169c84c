"""Radiation maps from an EnergyPlus weather file (lt_addon/sun/weather.py): the file read as
pvlib reads it (a test-only reference), and the map against an independent sum over the
hours with pvlib's SPA and the closed-form T of tests/core/test_sunlight_hours.py."""

import datetime as dt
import json
import os

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
from relightable_textures.lt_addon.sun import weather as wx
from relightable_textures.lt_addon.sun.radiation import radiation_map
from relightable_textures.lt_addon.sun.study_times import with_study

from test_sunlight_hours import _T, _store

LAT, LON, TZ_H, ELEV = 51.15, -0.18, 0.0, 62.0
DATES = [dt.date(2026, 3, 20), dt.date(2026, 6, 21), dt.date(2026, 12, 21)]


def _values(month, day, hour):
    """A cloudy day's made-up hourly Wh/m^2 (direct normal, diffuse horizontal), not a clear
    sky: the map must follow the file, hour by hour."""
    rng = np.random.default_rng(month * 100 + day)
    dni = np.where((hour > 4) & (hour < 22), rng.uniform(0, 850, len(hour)), 0.0)
    dhi = np.where((hour > 4) & (hour < 22), rng.uniform(20, 300, len(hour)), 0.0)
    return dni.round(), dhi.round()


def write_epw(path, days=None, lat=LAT, lon=LON, tz=TZ_H, city="Gatwick"):
    """An EPW of ``days`` (all of a non-leap year by default) in the file format's 35 fields."""
    days = days or [dt.date(2026, 1, 1) + dt.timedelta(days=i) for i in range(365)]
    head = [f"LOCATION,{city},SXW,GBR,IWEC Data,037760,{lat},{lon},{tz},{ELEV}",
            "DESIGN CONDITIONS,0", "TYPICAL/EXTREME PERIODS,0", "GROUND TEMPERATURES,0",
            "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0", "COMMENTS 1,made by the test",
            "COMMENTS 2,", "DATA PERIODS,1,1,Data,Sunday, 1/ 1,12/31"]
    rows = []
    hours = np.arange(1, 25)
    for d in days:
        dni, dhi = _values(d.month, d.day, hours)
        for h, b, s in zip(hours, dni, dhi):
            ghi = round(s + b * 0.5)
            rows.append(",".join(str(v) for v in [
                1995, d.month, d.day, h, 60, "?9?9?9?9E0?9?9?9*9*9?9?9?9?9?9?9?9?9*_*9*9*9*9*9",
                10.0, 5.0, 70, 101325, 0, 1415, 300, ghi, int(b), int(s), 0, 0, 0, 0, 180,
                2.0, 5, 5, 20.0, 77777, 9, 999999999, 10, 0.1, 0, 88, 0.0, 0.0, 0.0]))
    path.write_text("\n".join(head + rows) + "\n")
    return path


def test_the_file_reads_as_pvlib_reads_it(tmp_path):
    pvlib = pytest.importorskip("pvlib")
    path = write_epw(tmp_path / "w.epw")
    w = wx.read_epw(str(path))
    ref, meta = pvlib.iotools.read_epw(str(path))
    assert (w.latitude, w.longitude, w.tz_hours, w.elevation_m) == (
        meta["latitude"], meta["longitude"], meta["TZ"], meta["altitude"])
    assert w.city == meta["city"] and w.tz == "UTC" and len(w.dni) == len(ref) == 8760
    for ours, theirs in ((w.ghi, "ghi"), (w.dni, "dni"), (w.dhi, "dhi")):
        np.testing.assert_array_equal(ours, ref[theirs].to_numpy(np.float64))
    np.testing.assert_array_equal(w.hour, ref["hour"].to_numpy())
    assert wx.read_epw(str(write_epw(tmp_path / "s.epw", tz=10.0))).tz == "UTC+10:00"


def test_the_map_is_the_files_hours_at_the_suns_of_each_hour(tmp_path):
    """The map over three dates against an independent sum: per hour of the file (the hour
    *ending* at its clock hour, standard time), the Sun by pvlib's SPA at the middle of each
    10-minute slice, the hour's direct normal energy shared by the slices with the Sun up, times
    the closed-form ``max(0, n.s) V(s)``; diffuse: the hour's diffuse energy when any slice is
    up, times the sky view (1 on the open flat texel). Equal to 1e-4 relative (3.4e-5 measured). Read as the
    hour *starting* at its clock hour, the same file's beam is off by more than 10 % on a wall
    facing north, east or west: the check sees an hour's shift."""
    pvlib = pytest.importorskip("pvlib")
    from pvlib import solarposition

    w = wx.read_epw(str(write_epw(tmp_path / "w.epw")))
    suns, dni, dhi, hours, info = wx.study_irradiance(w, DATES, LAT, LON, ELEV)
    assert info["records_used"] == 72 and not info["dates_missing"]
    dset = with_study(parse_direction_spec("hemi:100:1.5"), suns)
    store, n = _store(tmp_path, dset)
    rmap = radiation_map(store, suns, dni, dhi, hours)

    def reference(shift_h):
        beam = np.zeros(16)
        diffuse, dark = 0.0, 0.0
        for d in DATES:
            b_h, s_h = _values(d.month, d.day, np.arange(1, 25))
            for h in range(1, 25):
                t0 = dt.datetime(d.year, d.month, d.day, tzinfo=dt.timezone.utc) + dt.timedelta(
                    hours=h - 1 + shift_h)
                when = [t0 + dt.timedelta(minutes=10 * k + 5) for k in range(6)]
                import pandas as pd

                sp = solarposition.spa_python(pd.DatetimeIndex(when), LAT, LON, ELEV)
                el, az = np.radians(sp["apparent_elevation"].to_numpy()), np.radians(
                    sp["azimuth"].to_numpy())
                D = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)
                upk = el > 0
                if not upk.any():
                    dark += b_h[h - 1]
                    continue
                beam += b_h[h - 1] * (np.pi * _T(D[upk], n)).sum(0) / upk.sum()
                diffuse += s_h[h - 1]
        return beam / 1000.0, diffuse / 1000.0, dark / 1000.0

    beam, diffuse, dark = reference(0.0)
    got = rmap.beam.ravel()
    lit = beam > 1.0
    # measured 3.4e-5: float32 maps over T as stored
    assert np.abs(got[lit] - beam[lit]).max() / beam[lit].max() < 1e-4
    assert rmap.diffuse.ravel()[0] == pytest.approx(diffuse, rel=1e-4)
    assert rmap.horizontal_kwh["beam"] == pytest.approx(beam[0], rel=1e-5)
    shifted, *_ = reference(1.0)
    off = np.abs(shifted[lit] - got[lit]) / beam[lit]
    assert off.max() > 0.1     # measured 0.18 (the north wall), 0.09-0.12 east and west
    # the file's made-up hours with energy and the Sun down all through them: left out, said
    assert dark > 1.0 and info["left_out_kwh_m2"]["beam"] == pytest.approx(dark, abs=1e-3)
    del pvlib


def test_a_study_with_a_weather_file_writes_its_map_and_says_whose_sky(tmp_path):
    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.sun import sun_study as ss
    from relightable_textures.lt_addon.sun.study_times import study_suns, study_times

    from test_sunlight_hours import _bundle

    times = study_times(DATES, "Europe/London", hours=list(range(24)))
    dset = with_study(parse_direction_spec("hemi:200:1.5"), study_suns(times, LAT, LON))
    bake = tmp_path / "bake"
    bake.mkdir()
    report_path, _ = _bundle(bake, dset)
    epw = write_epw(tmp_path / "far.epw", lat=48.0, lon=2.0, city="Elsewhere")
    settings = ss.StudySettings(latitude=LAT, longitude=LON, tz="Europe/London",
                                dates=DATES, hours=[9, 12, 15], weather=str(epw))
    out = tmp_path / "study"
    rep = ss.run_study([report_path], settings, str(out))
    assert rep["weather"]["city"] == "Elsewhere" and rep["weather"]["km_from_study"] > 300
    assert any("Elsewhere" in line and "km from the study's place" in line
               for line in rep["warnings"])
    ch, meta = exrio.read_exr(str(out / "A_radiation.exr"))
    assert "far.epw" in meta["sky"] and ch["Y"].ravel()[0] > 0
    assert json.loads((out / "sun_study.json").read_text())["radiation_sky"].startswith(
        "weather file far.epw")
    # a date the file lacks is said, and counted as 0
    short = write_epw(tmp_path / "short.epw", days=DATES[:2])
    rep = ss.run_study([report_path], ss.StudySettings(
        latitude=LAT, longitude=LON, tz="Europe/London", dates=DATES, hours=[12],
        weather=str(short)), str(tmp_path / "s2"))
    assert rep["weather"]["dates_missing"] == ["2026-12-21"]
    assert any("no records for 1 of the study's dates" in line for line in rep["warnings"])
    # the dates a weather study places the Sun for (144 a date) are bounded
    many = ss.dates_from(start="2020-01-01", end="2025-01-04")
    with pytest.raises(InputError, match="up to 1464 dates"):
        ss.run_study([report_path], ss.StudySettings(
            latitude=LAT, longitude=LON, tz="UTC", dates=many, hours=[12],
            weather=str(short)), str(tmp_path / "s3"))


def _record(text, field, value, month=None):
    """``text`` with field ``field`` of its first record set to ``value`` (and its month)."""
    lines = text.split("\n")
    f = lines[8].split(",")
    f[field] = value
    if month is not None:
        f[1] = month
    lines[8] = ",".join(f)
    return "\n".join(lines)


@pytest.mark.parametrize("mangle, words", [
    (lambda t: "\x89PNG\r\n" + t, "does not start with a LOCATION line"),
    (lambda t: t.replace(",51.15,", ",951.15,", 1), "latitude 951.15 is outside"),
    (lambda t: _record(t, 14, "5000"), "record 1 has 5000 Wh/m2 in an hour"),
    (lambda t: _record(t, 3, "x"), "record 1's hour 'x' is not a number"),
    (lambda t: _record(t, 2, "30", month="2"), "02-30, not a date"),
    (lambda t: "\n".join(t.split("\n")[:8]), "no hourly records"),
])
def test_a_bad_weather_file_is_one_line(tmp_path, mangle, words):
    path = write_epw(tmp_path / "w.epw", days=DATES)
    path.write_text(mangle(path.read_text()))
    with pytest.raises(InputError, match=words):
        wx.read_epw(str(path))


def test_a_huge_or_linked_weather_file_is_refused_before_it_is_read(tmp_path):
    big = tmp_path / "big.epw"
    with open(big, "wb") as fh:
        fh.truncate(wx.MAX_BYTES + 1)
    with pytest.raises(InputError, match="more than"):
        wx.read_epw(str(big))
    link = tmp_path / "link.epw"
    os.symlink(write_epw(tmp_path / "w.epw", days=DATES), link)
    with pytest.raises(InputError, match="symbolic link|refused"):
        wx.read_epw(str(link))
