"""Hourly solar radiation from an EnergyPlus weather file (EPW), for radiation maps (bpy-free).

An EPW holds a year of hourly records for one weather station (a typical meteorological year:
each month from a real year). Its first line is ``LOCATION,city,state,country,source,WMO,
latitude,longitude,time zone (hours from UTC),elevation (m)``; seven more header lines follow,
then one record a line, 35 fields: year, month, day, hour (1-24), minute, data flags, ...,
field 14 global horizontal, 15 direct normal and 16 diffuse horizontal radiation (1-based), in
**Wh/m^2 received over the hour that ends at ``hour``**, local *standard* time (the file's zone,
no daylight saving); 9999 marks a missing value (EnergyPlus Auxiliary Programs, "Weather
Converter Program": the data dictionary).

A study's radiation from the file (:func:`study_irradiance`): for each date of the study (by
month and day: a typical year mixes years) and each hour of the file, the Sun at the middle of
each 10-minute slice of that hour, at the study's place, in the file's zone; the hour's direct
normal energy is split evenly over the slices where the Sun is up (so a sunrise hour keeps its
energy, at the Sun's positions while it is up), and so is its diffuse energy. An hour with
energy but the Sun below the horizon all through it (twilight) is left out and its energy
reported.

The file is untrusted input (a user may have received it): a regular file of at most
:data:`MAX_BYTES`, every number parsed and range-checked, one line naming what is wrong.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: Largest weather file read: a year of records is 1.5-2 MB; a leap year at 10-minute records
#: would be 12 MB.
MAX_BYTES = 16 << 20
#: Most records: a leap year every 10 minutes.
MAX_RECORDS = 366 * 24 * 6
#: Header lines before the first record.
HEADER_LINES = 8
#: The EPW's mark for a missing radiation value.
MISSING = 9999.0
#: Slices the Sun is placed at within each hour (every 10 minutes, at their middles).
SLICES = 6
#: The largest plausible hourly value, Wh/m^2 (the solar constant is 1361 W/m^2).
MAX_WH = 1500.0


@dataclass(frozen=True)
class Weather:
    """The file's place and its hourly radiation. Arrays of shape (N,): ``month``, ``day``,
    ``hour`` (1-24: the hour ending then, local standard time), ``ghi``, ``dni``, ``dhi``
    (Wh/m^2 over that hour; NaN where the file says missing)."""

    city: str
    country: str
    latitude: float
    longitude: float
    tz_hours: float
    elevation_m: float
    month: np.ndarray
    day: np.ndarray
    hour: np.ndarray
    ghi: np.ndarray
    dni: np.ndarray
    dhi: np.ndarray

    @property
    def tz(self) -> str:
        """The file's zone as a fixed offset (``UTC+10:00``): EPW hours are standard time."""
        m = int(round(self.tz_hours * 60.0))
        return "UTC" if m == 0 else f"UTC{'+' if m > 0 else '-'}{abs(m) // 60:02d}:{abs(m) % 60:02d}"

    def place(self) -> dict:
        return {"city": self.city, "country": self.country, "latitude": self.latitude,
                "longitude": self.longitude, "tz": self.tz, "elevation_m": self.elevation_m}


def _number(text: str, path: str, what: str, lo: float, hi: float) -> float:
    try:
        x = float(text)
    except ValueError:
        raise InputError(f"{path}: {what} {text.strip()[:20]!r} is not a number; is this an "
                         "EnergyPlus weather file (.epw)?") from None
    if not (math.isfinite(x) and lo <= x <= hi):
        raise InputError(f"{path}: {what} {x:g} is outside {lo:g}..{hi:g}")
    return x


def read_epw(path: str) -> Weather:
    """The :class:`Weather` of EPW file ``path`` (module docstring); InputError in one line
    when it is not one, is too large, or holds a value out of range."""
    from ..io.untrusted import regular_file

    regular_file(path, MAX_BYTES)
    with open(path, "rb") as fh:
        raw = fh.read(MAX_BYTES + 1)
    text = raw.decode("latin-1")          # EPWs are ASCII; city names may be Latin-1
    lines = text.splitlines()
    if not lines or not lines[0].upper().startswith("LOCATION,"):
        raise InputError(f"{path}: does not start with a LOCATION line; is this an EnergyPlus "
                         "weather file (.epw)?")
    loc = lines[0].split(",")
    if len(loc) < 10:
        raise InputError(f"{path}: its LOCATION line has {len(loc)} fields, expected 10")
    lat = _number(loc[6], path, "latitude", -90.0, 90.0)
    lon = _number(loc[7], path, "longitude", -180.0, 180.0)
    tz = _number(loc[8], path, "time zone", -12.0, 14.0)
    elev = _number(loc[9], path, "elevation", -500.0, 9000.0)
    records = [ln for ln in lines[HEADER_LINES:] if ln.strip()]
    if not records:
        raise InputError(f"{path}: holds no hourly records after its {HEADER_LINES} header lines")
    if len(records) > MAX_RECORDS:
        raise InputError(f"{path}: holds {len(records)} records, more than {MAX_RECORDS}")
    n = len(records)
    month, day, hour = (np.zeros(n, np.int64) for _ in range(3))
    vals = np.zeros((n, 3), np.float64)
    for i, ln in enumerate(records):
        f = ln.split(",")
        if len(f) < 16:
            raise InputError(f"{path}: record {i + 1} (line {i + HEADER_LINES + 1}) has "
                             f"{len(f)} fields, expected 35")
        where = f"record {i + 1}"
        month[i] = int(_number(f[1], path, f"{where}'s month", 1, 12))
        day[i] = int(_number(f[2], path, f"{where}'s day", 1, 31))
        hour[i] = int(_number(f[3], path, f"{where}'s hour", 1, 24))
        for k, col in enumerate((13, 14, 15)):
            x = _number(f[col], path, f"{where}'s radiation", 0.0, MISSING)
            vals[i, k] = np.nan if x >= MISSING else x
        if np.nanmax(vals[i], initial=0.0) > MAX_WH:
            raise InputError(f"{path}: {where} has {np.nanmax(vals[i]):g} Wh/m2 in an hour, "
                             f"more than the Sun delivers ({MAX_WH:g})")
    key = month * 10000 + day * 100 + hour
    if len(np.unique(key)) != n:
        raise InputError(f"{path}: holds more than one record for some hours (sub-hourly "
                         "records are not read)")
    for m, d in set(zip(month.tolist(), day.tolist())):
        try:
            _dt.date(2024, m, d)           # a leap year: 02-29 is a day
        except ValueError:
            raise InputError(f"{path}: has a record for {m:02d}-{d:02d}, not a date") from None
    return Weather(loc[1].strip()[:80], loc[3].strip()[:80], lat, lon, tz, elev, month, day,
                   hour, vals[:, 0], vals[:, 1], vals[:, 2])


def study_irradiance(weather: Weather, dates, latitude: float, longitude: float,
                     elevation_m: float = 0.0, north_deg: float = 0.0):
    """The weather's radiation over ``dates`` at the study's place: ``(suns, dni, dhi, hours,
    info)`` for :func:`.radiation.radiation_map` -- ``suns`` a StudySuns at the middle of every
    10-minute slice of every hour of the dates (in the file's zone), ``dni``/``dhi`` W/m^2 (the
    hour's mean) and ``hours`` the part of an hour each slice stands for (its hour's sunlit
    slices share the hour; 0 where the Sun is down). ``info``: records used, dates the file
    lacks, energy left out (twilight, missing values)."""
    from .study_times import study_suns, study_times

    dates = sorted(set(dates))
    clock = [h + (k + 0.5) / SLICES for h in range(24) for k in range(SLICES)]
    times = study_times(dates, weather.tz, hours=clock)
    suns = study_suns(times, latitude, longitude, elevation_m, north_deg=north_deg)
    row = {(int(m), int(d), int(h)): i for i, (m, d, h) in
           enumerate(zip(weather.month, weather.day, weather.hour))}
    di = np.asarray(times.date_index)
    hour_of = np.floor(np.asarray(times.clock_h, np.float64)).astype(np.int64) + 1     # 1-24
    idx = np.array([row.get((dates[d].month, dates[d].day, int(h)), -1)
                    for d, h in zip(di, hour_of)], np.int64)
    missing_dates = sorted({dates[d].isoformat() for d, i in zip(di, idx) if i < 0})
    if len(missing_dates) == len(dates):
        raise InputError(f"the weather file has no records for the study's dates "
                         f"({dates[0].isoformat()}{' ...' if len(dates) > 1 else ''})")
    have = idx >= 0
    dni_wh = np.where(have, np.nan_to_num(weather.dni[idx]), 0.0)
    dhi_wh = np.where(have, np.nan_to_num(weather.dhi[idx]), 0.0)
    up = np.asarray(suns.up, bool) & have
    # each hour (date, hour) of the file: its sunlit slices share it
    hour_key = di * 25 + hour_of
    _, inverse = np.unique(hour_key, return_inverse=True)
    n_up = np.bincount(inverse, weights=up.astype(np.float64))
    hours = np.where(up, 1.0 / np.maximum(n_up[inverse], 1.0), 0.0)
    # energy in hours whose slices are all below the horizon: left out
    dark = have & (n_up[inverse] == 0)
    left_wh = {"beam": float(dni_wh[dark].sum() / SLICES),
               "diffuse": float(dhi_wh[dark].sum() / SLICES)}
    used_rows = np.unique(idx[have])
    miss = {k: int(np.isnan(getattr(weather, k)[used_rows]).sum()) for k in ("dni", "dhi")}
    info = {"records_used": int(len(used_rows)), "dates_missing": missing_dates,
            "left_out_kwh_m2": {k: round(v / 1000.0, 4) for k, v in left_wh.items()},
            "missing_values": miss, "slices_per_hour": SLICES,
            "what": "direct normal and diffuse horizontal Wh/m2 of each hour, split over the "
                    "hour's sunlit 10-minute slices"}
    return suns, dni_wh, dhi_wh, hours, info


def distance_km(lat1, lon1, lat2, lon2) -> float:
    """Great-circle distance in km (a 6371 km sphere)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(lon2 - lon1)
    c = (math.sin(p1) * math.sin(p2) + math.cos(p1) * math.cos(p2) * math.cos(dl))
    return 6371.0 * math.acos(max(-1.0, min(1.0, c)))
