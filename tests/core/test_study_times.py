"""Sun-study instants and directions (lt_addon/sun/study_times.py): local dates and hours in an
IANA zone with daylight saving, to UTC; the unique sun directions; a bake's direction set
extended along the study's sun paths."""

import datetime as dt

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
from relightable_textures.lt_addon.sun.solar_position import solar_position, sun_direction
from relightable_textures.lt_addon.sun.study_times import (date_range, study_suns, study_times,
                                                            with_study, zone)


def _utc(*args):
    return np.datetime64(dt.datetime(*args), "s")


# --- time zones --------------------------------------------------------------------------------

def test_zone_names_and_fixed_offsets():
    assert zone("Europe/London").utcoffset(dt.datetime(2026, 7, 1)) == dt.timedelta(hours=1)
    assert zone("UTC").utcoffset(None) == dt.timedelta(0)
    assert zone("UTC+05:30").utcoffset(None) == dt.timedelta(hours=5, minutes=30)
    assert zone("utc-3").utcoffset(None) == dt.timedelta(hours=-3)
    with pytest.raises(ValueError, match="Europe/Londn"):
        zone("Europe/Londn")
    with pytest.raises(ValueError, match="UTC-14:00"):
        zone("UTC+15")


def test_date_range_is_inclusive_and_steps():
    assert date_range("2026-06-19", "2026-06-21") == [dt.date(2026, 6, d) for d in (19, 20, 21)]
    assert len(date_range("2026-01-01", "2026-12-31")) == 365
    assert date_range("2026-01-01", "2026-01-31", every_days=10)[-1] == dt.date(2026, 1, 31)
    with pytest.raises(ValueError, match="before"):
        date_range("2026-02-01", "2026-01-01")


# --- Europe/London: the two daylight-saving days of 2026 -----------------------------------------

def test_london_clock_hours_around_the_spring_change():
    """BST starts 29 March 2026 at 01:00 GMT: 01:00-01:59 do not exist that day."""
    t = study_times(["2026-03-28", "2026-03-29", "2026-03-30"], "Europe/London",
                    hours=[0.5, 1.0, 1.5, 2.0, 12.0])
    assert t.skipped == (dt.datetime(2026, 3, 29, 1, 0), dt.datetime(2026, 3, 29, 1, 30))
    assert len(t) == 13
    on = dict(zip([(x.date(), x.hour + x.minute / 60) for x in t.local], t.utc))
    assert on[(dt.date(2026, 3, 28), 12.0)] == _utc(2026, 3, 28, 12)      # GMT
    assert on[(dt.date(2026, 3, 29), 0.5)] == _utc(2026, 3, 29, 0, 30)    # still GMT
    assert on[(dt.date(2026, 3, 29), 2.0)] == _utc(2026, 3, 29, 1)        # BST
    assert on[(dt.date(2026, 3, 29), 12.0)] == _utc(2026, 3, 29, 11)
    assert not t.ambiguous.any()
    assert t.step_h is None


def test_london_clock_hours_around_the_autumn_change():
    """BST ends 25 October 2026 at 02:00 BST (01:00 GMT): 01:00-01:59 happen twice; the first
    (BST) is taken and flagged."""
    t = study_times(["2026-10-25"], "Europe/London", hours=[0.5, 1.5, 2.5, 12])
    assert list(t.utc) == [_utc(2026, 10, 24, 23, 30), _utc(2026, 10, 25, 0, 30),
                           _utc(2026, 10, 25, 2, 30), _utc(2026, 10, 25, 12)]
    assert t.ambiguous.tolist() == [False, True, False, False]
    assert t.clock_h.tolist() == [0.5, 1.5, 2.5, 12.0]


def test_london_hourly_steps_count_real_hours_on_change_days():
    t = study_times(date_range("2026-03-28", "2026-03-30"), "Europe/London", step_minutes=60)
    assert np.bincount(t.date_index).tolist() == [24, 23, 24]
    d = np.diff(t.utc).astype(int)
    assert (d == 3600).all()                                   # evenly spaced in real time
    autumn = study_times(["2026-10-25"], "Europe/London", step_minutes=60)
    assert len(autumn) == 25 and autumn.ambiguous.sum() == 2   # 01:00 BST and 01:00 GMT
    assert autumn.utc[0] == _utc(2026, 10, 24, 23) and autumn.utc[-1] == _utc(2026, 10, 25, 23)
    year = study_times(date_range("2026-01-01", "2026-12-31"), "Europe/London", step_minutes=60)
    assert len(year) == 8760 and year.step_h == 1.0
    assert len(np.unique(year.utc)) == 8760


def test_a_window_of_the_day_and_a_sub_hour_step():
    t = study_times(["2026-06-21"], "Europe/London", step_minutes=20, start_hour=9,
                    end_hour=12)
    assert len(t) == 9
    assert t.utc[0] == _utc(2026, 6, 21, 8) and t.utc[-1] == _utc(2026, 6, 21, 10, 40)
    assert np.allclose(t.clock_h, 9 + np.arange(9) / 3)


# --- the southern hemisphere: Australia/Sydney's daylight saving runs October to April -----------

def test_sydney_summer_time_is_in_january_not_july():
    t = study_times(["2026-01-15", "2026-07-15"], "Australia/Sydney", hours=[12])
    assert list(t.utc) == [_utc(2026, 1, 15, 1), _utc(2026, 7, 15, 2)]   # AEDT +11, AEST +10


def test_sydney_change_days():
    """AEDT ends 5 April 2026 at 03:00 (-> 02:00 AEST); AEST ends 4 October 2026 at 02:00
    (-> 03:00 AEDT)."""
    t = study_times(date_range("2026-04-04", "2026-04-06"), "Australia/Sydney",
                    step_minutes=60)
    assert np.bincount(t.date_index).tolist() == [24, 25, 24]
    s = study_times(["2026-10-04"], "Australia/Sydney", hours=[1, 2, 2.5, 3])
    assert s.skipped == (dt.datetime(2026, 10, 4, 2), dt.datetime(2026, 10, 4, 2, 30))
    assert list(s.utc) == [_utc(2026, 10, 3, 15), _utc(2026, 10, 3, 16)]


def test_zones_without_daylight_saving_and_half_hours():
    t = study_times(["2026-01-15", "2026-07-15"], "Asia/Kolkata", hours=[12])
    assert list(t.utc) == [_utc(2026, 1, 15, 6, 30), _utc(2026, 7, 15, 6, 30)]
    f = study_times(["2026-07-15"], "UTC+02:00", hours=[12])
    assert f.utc[0] == _utc(2026, 7, 15, 10)


def test_bad_studies_say_what_is_wrong():
    with pytest.raises(ValueError, match="either hours"):
        study_times(["2026-01-01"], "UTC")
    with pytest.raises(ValueError, match=r"\[0, 24\)"):
        study_times(["2026-01-01"], "UTC", hours=[24])
    with pytest.raises(ValueError, match="start_hour < end_hour"):
        study_times(["2026-01-01"], "UTC", step_minutes=60, start_hour=12, end_hour=9)


# --- the Sun's directions for a study --------------------------------------------------------

def test_study_suns_are_the_suns_at_the_instants_above_the_horizon():
    t = study_times(date_range("2026-01-01", "2026-12-31"), "Europe/London", step_minutes=60)
    s = study_suns(t, 51.5074, -0.1278, north_deg=30.0)
    sp = solar_position(t.utc, 51.5074, -0.1278)
    assert np.array_equal(s.elevation, sp.elevation)
    assert np.array_equal(s.up, sp.elevation > 0)
    assert 4300 < s.up.sum() < 4600                     # ~half the year's 8,760 hours
    assert len(s.directions) == s.up.sum()              # every hour's Sun is its own
    d = sun_direction(s.elevation, s.azimuth, 30.0)
    assert np.array_equal(s.directions[s.index[s.up]], d[s.up])
    assert (s.directions[:, 2] > 0).all()
    assert np.allclose(np.linalg.norm(s.directions, axis=1), 1.0)


def test_study_suns_merge_repeated_instants_and_honour_a_minimum_elevation():
    inst = np.array(["2026-06-21T12:00", "2026-06-21T12:00", "2026-06-21T04:00"],
                    dtype="datetime64[s]")
    s = study_suns(inst, 51.5, 0.0, min_elevation_deg=5.0)
    assert s.index.tolist() == [0, 0, -1]               # 04:00 UTC: ~1 degree high
    assert len(s.directions) == 1


def test_polar_night_and_day():
    t = study_times(["2026-06-21", "2026-12-21"], "UTC", step_minutes=60)
    north = study_suns(t, 90.0, 0.0)
    assert north.up[:24].all() and not north.up[24:].any()
    south = study_suns(t, -90.0, 0.0)
    assert not south.up[:24].any() and south.up[24:].all()


def test_with_study_adds_every_instants_sun_to_the_bake_set():
    base = parse_direction_spec("hemi:400")
    t = study_times(["2026-03-20", "2026-06-21", "2026-12-21"], "Europe/London",
                    hours=[9, 12, 15])
    s = study_suns(t, 51.5074, -0.1278)
    ds = with_study(base, s)
    assert ds.kind == "custom"
    assert ds.params["study_directions"] == 9 and ds.params["study_path_directions"] == 0
    assert len(ds.directions) == ds.params["base_kept"] + 9
    for d in s.directions:                              # each Sun exactly in the set
        assert np.isclose((ds.directions @ d).max(), 1.0, rtol=0, atol=1e-15)
    assert ds.solid_angles.sum() == pytest.approx(2 * np.pi)


def test_with_study_along_the_paths_follows_the_suns_own_circle():
    base = parse_direction_spec("hemi:400")
    t = study_times(["2026-06-21"], "Europe/London", hours=[9, 12, 15])
    s = study_suns(t, 51.5074, -0.1278)
    ds = with_study(base, s, t, step_deg=0.5)
    n = ds.params["study_path_directions"]
    # 6 hours at 15 cos(23.4) = 13.8 degrees an hour: ~83 degrees of path, every 0.46-0.5
    assert 150 < n < 200
    path = ds.directions[-n:]
    # every path direction lies on the Sun's path of that day (minute by minute, by SPA)
    fine = np.arange(_utc(2026, 6, 21, 8), _utc(2026, 6, 21, 14) + 1, 20, dtype="datetime64[s]")
    sp = solar_position(fine, 51.5074, -0.1278)
    truth = sun_direction(sp.elevation, sp.azimuth)
    off = np.degrees(np.arccos(np.clip((path @ truth.T).max(axis=1), -1, 1)))
    assert off.max() < 0.01
    gaps = np.degrees(np.arccos(np.clip((path @ path.T - 2 * np.eye(n)).max(axis=1), -1, 1)))
    assert gaps.min() >= 0.25 - 1e-9 and gaps.max() <= 0.5 + 1e-9
    with pytest.raises(ValueError, match="StudyTimes"):
        with_study(base, s, step_deg=0.5)


def test_with_study_paths_need_no_jump_between_days():
    """Two dates' paths are separate: nothing is added across the night between them."""
    base = parse_direction_spec("hemi:100")
    t = study_times(["2026-06-20", "2026-06-21"], "UTC", hours=[10, 14])
    s = study_suns(t, 51.5, 0.0)
    ds = with_study(base, s, t, step_deg=1.0)
    path = ds.directions[-ds.params["study_path_directions"]:]
    az = np.degrees(np.arctan2(path[:, 0], path[:, 1])) % 360
    assert az.min() > 125 and az.max() < 235            # 10:00-14:00 only (130-229 degrees)
    # the two days' paths lie ~0.02 degrees apart: thinned to about one day's worth
    one = study_times(["2026-06-21"], "UTC", hours=[10, 14])
    n1 = with_study(base, study_suns(one, 51.5, 0.0), one, step_deg=1.0).params[
        "study_path_directions"]
    assert ds.params["study_path_directions"] <= 1.1 * n1


def test_the_sun_position_add_ons_place_as_a_study_place():
    """The add-on keeps one UTC offset all year (its Daylight Savings adds an hour to every
    date) and its north in radians: a fixed-offset zone and degrees; a ``scene,...`` study takes
    them, a north given in the spec wins."""
    import math

    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.lt_addon.sun import study_directions as sd

    sydney = {"latitude": -33.869998931884766, "longitude": 151.2100067138672,
              "UTC_zone": 10.0, "use_daylight_savings": True,
              "north_offset": math.radians(-200.0)}
    place = sd.place_from_sun_position(sydney)
    assert place == {"latitude": -33.87, "longitude": 151.21, "tz": "UTC+11:00",
                     "north_deg": 160.0}
    assert zone(place["tz"]).utcoffset(None).total_seconds() == 11 * 3600
    newfoundland = sd.place_from_sun_position({"latitude": 47.6, "longitude": -52.7,
                                               "UTC_zone": -3.5})
    assert newfoundland["tz"] == "UTC-03:30" and newfoundland["north_deg"] == 0.0
    assert sd.place_from_sun_position({"latitude": 0, "longitude": 0})["tz"] == "UTC"
    with pytest.raises(InputError, match="out of range"):
        sd.place_from_sun_position({"latitude": 91.0, "longitude": 0.0})
    spec = sd.parse("scene,2026-12-21,2026-06-21")
    assert spec.from_scene and spec.north_deg is None and len(spec.dates) == 2
    assert sd.with_place(spec, place).north_deg == 160.0
    assert sd.with_place(sd.parse("Scene,2026-12-21,north=5"), place).north_deg == 5.0
    with pytest.raises(InputError, match="no Sun Position settings"):
        sd.direction_set(None, "scene,2026-12-21", 1.0)
    with pytest.raises(InputError, match="no date"):
        sd.parse("scene,north=3")


# --- date ranges in a study spec, and the dates a study bake adds ------------------------------

def test_a_spec_takes_date_ranges():
    """``FIRST..LAST`` and ``FIRST..LAST/N`` expand to the dates, beside single dates; a
    backward range, a zero step and more than four years of dates are one line each."""
    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.lt_addon.sun import study_directions as sd

    spec = sd.parse("51.5,-0.13,Europe/London,2026-01-01..2026-12-31,north=3")
    assert len(spec.dates) == 365 and spec.dates[0] == dt.date(2026, 1, 1)
    assert spec.north_deg == 3.0
    weekly = sd.parse("-33.87,151.21,Australia/Sydney,2026-01-01..2026-12-31/7,2026-06-21")
    assert len(weekly.dates) == 54 and dt.date(2026, 6, 21) in weekly.dates
    assert weekly.dates == tuple(sorted(weekly.dates))
    for bad, words in (("2026-12-31..2026-01-01", "comes after"), ("2026-01-01..2026-02-01/0",
                       "comes after"), ("2026-01-01..x", "bad study date range"),
                       ("2020-01-01..2026-01-01", "more than 1464")):
        with pytest.raises(InputError, match=words):
            sd.parse(f"51.5,-0.13,UTC,{bad}")


def test_declination_equals_pvlibs_spa():
    """The Sun's declination (the parallel its day's path follows) against pvlib's SPA, over a
    year of noons: equal to 1e-6 degrees (the same algorithm)."""
    pvlib = pytest.importorskip("pvlib")
    from pvlib import spa

    from relightable_textures.lt_addon.sun.solar_position import declination

    t = np.arange(np.datetime64("2026-01-01T12:00"), np.datetime64("2027-01-01T12:00"),
                  np.timedelta64(1, "D"))
    unix = (t - np.datetime64(0, "s")) / np.timedelta64(1, "s")
    ours = declination(t)
    _, _, ref = spa.solar_position(unix, 51.5, -0.13, 0.0, 1013.25, 12.0, 69.2, 0.5667,
                                   sst=True)
    assert np.abs(ours - ref).max() < 1e-6
    assert ours.min() == pytest.approx(-23.44, abs=0.02) and ours.max() == pytest.approx(
        23.44, abs=0.02)
    del pvlib


@pytest.mark.parametrize("lat, lon, tz", [(51.5, -0.13, "Europe/London"),
                                          (-33.87, 151.21, "Australia/Sydney")])
def test_a_year_range_bakes_24_paths_spread_over_the_declinations(lat, lon, tz):
    """A year's range bakes the paths of 24 dates spread evenly over the year's declinations:
    every hourly sun of the year lies near a baked direction (measured 2026-12-06, London /
    Sydney: median 0.54 / 0.54 deg, 95 % within 1.02 / 1.00, worst 1.40 / 1.17, from 4,613 /
    4,603 directions), where the 400 default directions leave a median 2.8 deg and a worst
    6.6 deg, and 24 dates taken evenly in time (a date per fortnight or so: each declination
    twice a year) leave more."""
    from scipy.spatial import cKDTree

    from relightable_textures.lt_addon.sun import study_directions as sd

    base = parse_direction_spec("hemi:400")
    spec = sd.parse(f"{lat},{lon},{tz},2026-01-01..2026-12-31")
    dset, info = sd.direction_set(base, f"{lat},{lon},{tz},2026-01-01..2026-12-31", 1.0)
    assert len(info["dates"]) == sd.MAX_DATES and info["spec_dates"] == 365
    assert "24 of the spec's 365 dates" in info["dates_chosen"]
    # the solstices (the declinations' extremes; a day either side by the local noon) are
    # among them
    for solstice in (dt.date(2026, 6, 21), dt.date(2026, 12, 21)):
        assert any(abs((dt.date.fromisoformat(d) - solstice).days) <= 1 for d in info["dates"])
    year = study_times(list(spec.dates), tz, step_minutes=60)
    suns = study_suns(year, lat, lon)

    def degrees(dirs):
        d, _ = cKDTree(dirs).query(suns.directions)
        return np.degrees(2 * np.arcsin(d / 2))

    got = degrees(dset.directions)
    assert np.median(got) < 0.6 and np.percentile(got, 95) < 1.1 and got.max() < 1.5
    assert np.median(degrees(base.directions)) > 2.5
    # the same count of dates evenly in time: a worse spread (the equinoxes' fast declination)
    even = [spec.dates[i] for i in np.linspace(0, 364, sd.MAX_DATES).round().astype(int)]
    times = study_times(even, tz, step_minutes=60)
    in_time = with_study(base, study_suns(times, lat, lon), times, step_deg=1.0)
    assert degrees(in_time.directions).max() > got.max()


def test_spec_text_writes_ranges_back():
    from relightable_textures.lt_addon.sun import study_directions as sd

    year = sd.parse("51.5,-0.13,UTC,2026-01-01..2026-12-31/7").dates
    text = sd.spec_text(51.5, -0.13, "UTC", year, north_deg=3.0)
    assert text == "51.5,-0.13,UTC,2026-01-01..2026-12-31/7,north=3"
    assert sd.parse(text).dates == year
    assert sd.spec_text(1, 2, "UTC", ["2026-06-21", "2026-12-21"]).endswith(
        "UTC,2026-06-21,2026-12-21")
    odd = [dt.date(2026, 1, 1) + dt.timedelta(days=int(k * k / 7)) for k in range(40)]
    assert sd.spec_text(1, 2, "UTC", odd).endswith(f"UTC,2026-01-01..{max(odd)}")
