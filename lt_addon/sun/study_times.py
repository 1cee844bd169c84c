"""The instants of a sun study and the Sun's directions at them (bpy-free).

A study is a set of local dates (a list, or :func:`date_range`) and either clock **hours** of
each date ("9, 12 and 15 o'clock on the solstices": the cells of a shadow-study sheet) or a
**step** through each day (every 60 minutes from local midnight to midnight: the samples that
sunlight hours and radiation sum over), in an IANA time zone (``"Europe/London"``), daylight
saving included. :func:`study_times` turns it into UTC instants; :func:`study_suns` gives the
Sun's position and direction at each (:mod:`.solar_position`) and the unique directions above
the horizon; :func:`with_study` adds those to a bake's direction set, as
:func:`..sphere.sun_path.with_path` does for an animated Sun.

Daylight saving (the two days a year a zone's clock jumps):

* **hours**: a clock hour that does not exist that day (01:30 in London on the last Sunday of
  March, when 01:00 GMT becomes 02:00 BST) is skipped and listed in
  :attr:`StudyTimes.skipped`; one that happens twice (01:30 on the last Sunday of October) is
  taken at its first occurrence (PEP 495 ``fold=0``: still in summer time) and flagged in
  :attr:`StudyTimes.ambiguous`.
* **step**: the samples are equally spaced in real time from the window's local start to its
  local end, so a 00:00-24:00 window holds 23 hours on the spring day and 25 on the autumn day,
  and every sample stands for ``step`` of real time (:attr:`StudyTimes.step_h`): sums over the
  samples count each real hour once.

Time zones come from the standard library's :mod:`zoneinfo`, which reads the operating system's
IANA database (``/usr/share/zoneinfo`` on Linux and macOS) or else the ``tzdata`` package.
Windows has no system database, and Blender's bundled Python does not ship ``tzdata`` (its
build installs cython, idna, charset-normalizer, urllib3, certifi, requests, zstandard,
autopep8, pycodestyle, toml and meson besides numpy:
``build_files/build_environment/cmake/python_site_packages.cmake`` in Blender's source), so
**the extension ships tzdata itself**: one pure-Python wheel in every platform's zip
(requirements-wheels.txt), which Blender installs into the extension's site-packages, where
zoneinfo finds it (tests/blender/test_extension_install.py: with no system database, the
installed extension's zoneinfo reads it; not run on a Windows Blender). A Python without either
(this module outside the extension, on Windows) has no database: :func:`zone` says so in one
line and accepts a fixed offset instead (``"UTC+01:00"``: no daylight saving).
"""

from __future__ import annotations

import datetime as _dt
import re
from dataclasses import dataclass, field

import numpy as np

from .solar_position import DELTA_T_2020S, solar_position, sun_direction

__all__ = ["StudyTimes", "StudySuns", "zone", "date_range", "study_times", "study_suns",
           "with_study"]

_FIXED = re.compile(r"^(?:UTC|GMT)\s*(?:([+-])\s*(\d{1,2})(?::?(\d{2}))?)?$", re.IGNORECASE)


def zone(name) -> _dt.tzinfo:
    """The time zone called ``name``: an IANA name (``"Europe/London"``, ``"Australia/Sydney"``)
    via :mod:`zoneinfo`, or a fixed offset ``"UTC"``, ``"UTC+2"``, ``"UTC-03:30"``; a tzinfo
    passes through. Raises ValueError in one line when the name is unknown or this Python has
    no time-zone database (Windows without the ``tzdata`` package, which the extension ships)."""
    if isinstance(name, _dt.tzinfo):
        return name
    text = str(name).strip()
    m = _FIXED.match(text)
    if m:
        sign, hh, mm = m.groups()
        if sign is None:
            return _dt.timezone.utc
        minutes = int(hh) * 60 + int(mm or 0)
        if minutes > 14 * 60 or int(mm or 0) >= 60:
            raise ValueError(f"time zone {text!r}: offsets lie within UTC-14:00..UTC+14:00")
        off = _dt.timedelta(minutes=minutes if sign == "+" else -minutes)
        return _dt.timezone(off, text.upper())
    import zoneinfo
    try:
        return zoneinfo.ZoneInfo(text)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        have = bool(zoneinfo.available_timezones())
        why = ("not an IANA time-zone name (e.g. 'Europe/London')" if have else
               "this Python has no IANA time-zone database (the extension ships the "
               "'tzdata' package: reinstall it, or outside Blender `pip install tzdata`)")
        raise ValueError(f"time zone {text!r}: {why}; or give a fixed offset such as "
                         "'UTC+01:00' (no daylight saving)") from None


def date_range(start, end, every_days: int = 1) -> list[_dt.date]:
    """Dates from ``start`` to ``end`` inclusive (``datetime.date`` or ISO ``"2026-06-21"``),
    every ``every_days`` days."""
    a, b = _date(start), _date(end)
    if b < a:
        raise ValueError(f"date range ends ({b}) before it starts ({a})")
    if int(every_days) < 1:
        raise ValueError(f"every_days must be >= 1, got {every_days}")
    n = (b - a).days // int(every_days) + 1
    return [a + _dt.timedelta(days=i * int(every_days)) for i in range(n)]


def _date(d) -> _dt.date:
    if isinstance(d, _dt.datetime):
        return d.date()
    if isinstance(d, _dt.date):
        return d
    if isinstance(d, np.datetime64):
        return _dt.date.fromisoformat(str(d.astype("datetime64[D]")))
    return _dt.date.fromisoformat(str(d).strip())


@dataclass(frozen=True)
class StudyTimes:
    """The instants of a study, in order of date then time.

    Attributes
    ----------
    utc : ndarray, shape (N,), datetime64[s]
        The instants in UTC (what :func:`.solar_position.solar_position` takes).
    local : tuple of N aware datetimes
        The same instants on the zone's clock.
    date_index : ndarray, shape (N,), int64
        Which of :attr:`dates` each instant belongs to.
    dates : tuple of D dates
    clock_h : ndarray, shape (N,), float64
        Local clock time in hours (13.5 = 13:30).
    ambiguous : ndarray, shape (N,), bool
        Clock hours that happen twice that day (taken at the first occurrence).
    skipped : tuple of naive datetimes
        Clock hours that did not exist that day (the spring-forward gap), left out.
    step_h : float or None
        Real time each instant stands for (the step), None for a list of hours.
    zone : str
    """

    utc: np.ndarray
    local: tuple
    date_index: np.ndarray
    dates: tuple
    clock_h: np.ndarray
    ambiguous: np.ndarray
    skipped: tuple
    step_h: float | None
    zone: str

    @property
    def posix(self) -> np.ndarray:
        """POSIX seconds (N,), float64."""
        return (self.utc - np.datetime64(0, "s")) / np.timedelta64(1, "s")

    def __len__(self):
        return len(self.utc)


def _to_utc64(aware: _dt.datetime) -> np.datetime64:
    u = aware.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    return np.datetime64(u.replace(microsecond=0), "s")


def study_times(dates, tz="UTC", *, hours=None, step_minutes=None, start_hour: float = 0.0,
                end_hour: float = 24.0) -> StudyTimes:
    """The study's instants: each date at each clock hour of ``hours`` (floats in [0, 24),
    e.g. ``(9, 12, 15)``), or every ``step_minutes`` of real time from ``start_hour`` to
    ``end_hour`` (local clock, end excluded) of each date; ``tz`` an IANA name or fixed offset
    (:func:`zone`). Daylight saving: module docstring. Times are whole seconds."""
    if (hours is None) == (step_minutes is None):
        raise ValueError("give either hours (clock hours of each date) or step_minutes")
    tzinfo = zone(tz)
    days = [_date(d) for d in (dates if not isinstance(dates, (str, _dt.date)) else [dates])]
    if not days:
        raise ValueError("a study needs at least one date")
    utc, local, idx, amb, skipped = [], [], [], [], []
    if hours is not None:
        hs = sorted({float(h) for h in np.atleast_1d(np.asarray(hours, np.float64))})
        if not hs or hs[0] < 0.0 or hs[-1] >= 24.0:
            raise ValueError(f"clock hours must lie in [0, 24), got {hours}")
        for di, day in enumerate(days):
            midnight = _dt.datetime.combine(day, _dt.time())
            for h in hs:
                wall = midnight + _dt.timedelta(seconds=round(h * 3600.0))
                first = wall.replace(tzinfo=tzinfo, fold=0)
                back = first.astimezone(_dt.timezone.utc).astimezone(tzinfo).replace(tzinfo=None)
                if back != wall:                        # the clock jumped over this time
                    skipped.append(wall)
                    continue
                second = wall.replace(tzinfo=tzinfo, fold=1)
                utc.append(_to_utc64(first))
                local.append(first)
                idx.append(di)
                amb.append(first.utcoffset() != second.utcoffset())
        step_h = None
    else:
        step = float(step_minutes)
        if not step > 0:
            raise ValueError(f"step_minutes must be > 0, got {step_minutes}")
        if not 0.0 <= float(start_hour) < float(end_hour) <= 24.0:
            raise ValueError(f"need 0 <= start_hour < end_hour <= 24, got {start_hour}, "
                             f"{end_hour}")
        step_s = int(round(step * 60.0))
        for di, day in enumerate(days):
            midnight = _dt.datetime.combine(day, _dt.time())
            a = (midnight + _dt.timedelta(seconds=round(float(start_hour) * 3600.0))
                 ).replace(tzinfo=tzinfo)
            b = (midnight + _dt.timedelta(seconds=round(float(end_hour) * 3600.0))
                 ).replace(tzinfo=tzinfo)
            a_u, b_u = _to_utc64(a), _to_utc64(b)
            n = int(np.ceil((b_u - a_u) / np.timedelta64(step_s, "s")))
            for k in range(max(n, 0)):
                u = a_u + np.timedelta64(k * step_s, "s")
                loc = _dt.datetime.fromtimestamp(
                    float((u - np.datetime64(0, "s")) / np.timedelta64(1, "s")), tzinfo)
                utc.append(u)
                local.append(loc)
                idx.append(di)
                amb.append(loc.replace(fold=1 - loc.fold).utcoffset() != loc.utcoffset())
        step_h = step / 60.0
    clock = np.array([t.hour + t.minute / 60.0 + t.second / 3600.0 for t in local], np.float64)
    return StudyTimes(np.array(utc, dtype="datetime64[s]").reshape(-1), tuple(local),
                      np.array(idx, np.int64), tuple(days), clock, np.array(amb, bool),
                      tuple(skipped), step_h, str(tz if not isinstance(tz, _dt.tzinfo)
                                                  else tzinfo))


@dataclass(frozen=True)
class StudySuns:
    """The Sun at a study's instants.

    Attributes
    ----------
    elevation, azimuth : ndarray, shape (N,), float64
        Degrees, refracted topocentric elevation and azimuth eastward from north (SPA).
    directions : ndarray, shape (M, 3), float64
        The unique unit vectors towards the Sun (Blender frame, :func:`.sun_direction`) of the
        instants with the Sun above ``min_elevation_deg``, in order of first appearance.
    index : ndarray, shape (N,), int64
        Row of :attr:`directions` for each instant; -1 where the Sun is below the limit.
    params : dict
        Place, north and SPA settings used.
    """

    elevation: np.ndarray
    azimuth: np.ndarray
    directions: np.ndarray
    index: np.ndarray
    params: dict = field(default_factory=dict)

    @property
    def up(self) -> np.ndarray:
        """(N,) bool: the Sun is above the limit."""
        return self.index >= 0


def study_suns(times, latitude: float, longitude: float, elevation_m: float = 0.0, *,
               north_deg: float = 0.0, min_elevation_deg: float = 0.0,
               merge_deg: float = 1e-6, pressure_hpa: float = 1013.25,
               temperature_c: float = 12.0, delta_t: float = DELTA_T_2020S) -> StudySuns:
    """The Sun at each instant of ``times`` (a :class:`StudyTimes` or UTC instants) and its unique
    directions above ``min_elevation_deg`` (refracted elevation: the light that casts the
    shadows); directions closer than ``merge_deg`` to an earlier one (the same instant twice)
    share its row. Place in degrees north / east and metres; ``north_deg`` as
    :func:`.sun_direction` (the *Sun Position* add-on's North Offset)."""
    utc = times.utc if isinstance(times, StudyTimes) else times
    sp = solar_position(utc, latitude, longitude, elevation_m, pressure_hpa=pressure_hpa,
                        temperature_c=temperature_c, delta_t=delta_t)
    el = np.atleast_1d(sp.elevation).astype(np.float64).ravel()
    az = np.atleast_1d(sp.azimuth).astype(np.float64).ravel()
    d = sun_direction(el, az, north_deg)
    up = el > float(min_elevation_deg)
    index = np.full(el.shape, -1, np.int64)
    rows = np.flatnonzero(up)
    if len(rows):
        q = np.round(d[rows] / max(np.radians(float(merge_deg)), 1e-15)).astype(np.int64)
        _, first, inverse = np.unique(q, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)                       # unique rows in order of appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        index[rows] = rank[np.asarray(inverse).ravel()]
        dirs = d[rows[np.sort(first)]]
    else:
        dirs = np.zeros((0, 3), np.float64)
    params = {"latitude": float(latitude), "longitude": float(longitude),
              "elevation_m": float(elevation_m), "north_deg": float(north_deg),
              "min_elevation_deg": float(min_elevation_deg), "pressure_hpa": float(pressure_hpa),
              "temperature_c": float(temperature_c), "delta_t": float(delta_t),
              "algorithm": "NREL SPA (Reda & Andreas 2004)"}
    return StudySuns(el, az, dirs, index, params)


def with_study(base, suns: StudySuns, times: StudyTimes | None = None, *,
               step_deg: float | None = None, width_deg: float = 0.0):
    """``base`` (an upper-hemisphere :class:`..sphere.directions.DirectionSet`) plus the study's
    sun directions, like :func:`..sphere.sun_path.with_path` for an animated Sun: base
    directions closer than the spacing to a study direction are dropped, and every direction's
    solid angle comes from the spherical Voronoi cells of the union cut at the horizon.

    ``step_deg`` None adds the study's directions alone (every instant's Sun exactly). A step
    also adds each date's path between its instants every ``step_deg`` degrees, in a band
    ``width_deg`` wide (``sun_path.band``): the Sun's own path by SPA (:func:`_day_paths`),
    per date of ``times`` (then required, so no path jumps from one evening to the next
    morning) and above the horizon; the added path directions are thinned to at
    least ``step_deg / 2`` apart, from each other and from the instants' directions
    (consecutive dates' paths nearly coincide). Base directions within ``step_deg`` (0.5
    degrees without a step) of a study direction are dropped. Kind ``custom``."""
    from ..sphere.directions import DirectionSet
    from ..sphere.sun_path import band, upper_voronoi_areas

    exact = np.asarray(suns.directions, np.float64).reshape(-1, 3)
    extra = np.zeros((0, 3))
    if step_deg is not None:
        if times is None:
            raise ValueError("with_study: a step needs the StudyTimes (paths run per date)")
        step = float(step_deg)
        if not step > 0:
            raise ValueError(f"step_deg must be > 0, got {step_deg}")
        parts = [band(run, step, float(width_deg))
                 for path in _day_paths(times, suns.params, step) for run in _daylight(path)]
        if parts:
            extra = _thin(np.concatenate(parts), exact, np.radians(step / 2.0))
    pts = np.concatenate([exact, extra])
    if not len(pts):
        return base
    from scipy.spatial import cKDTree

    spacing = np.radians(float(step_deg) if step_deg is not None else 0.5)
    dist, _ = cKDTree(pts).query(base.directions, k=1)
    near = dist < 2.0 * np.sin(spacing / 2.0)
    keep = base.directions[~near]
    dirs = np.concatenate([keep, pts])
    el_all = np.degrees(np.arcsin(np.clip(pts[:, 2], -1, 1)))
    return DirectionSet(dirs, upper_voronoi_areas(dirs), "custom",
                        {"base": base.spec, "base_kept": int(len(keep)),
                         "base_dropped": int(near.sum()), "study_directions": int(len(exact)),
                         "study_path_directions": int(len(extra)),
                         "study_step_deg": None if step_deg is None else float(step_deg),
                         "study_elevation_deg": [round(float(el_all.min()), 2),
                                                 round(float(el_all.max()), 2)],
                         "study": {k: suns.params[k] for k in ("latitude", "longitude",
                                                               "north_deg") if k in suns.params}})


#: The Sun moves at most 15 degrees an hour (the hour angle's rate, at the celestial equator).
_MAX_DEG_PER_MIN = 0.25


def _day_paths(times: StudyTimes, params: dict, step_deg: float) -> list:
    """Per date, the Sun's directions (SPA) from its first to its last instant, every
    ``step_deg / 0.25`` minutes: at most ``step_deg`` apart (0.92 ``step_deg`` at the
    solstices). The Sun's own path, not ``sun_path.densify``'s great-circle slerp between
    instants: the diurnal circle is a small circle, which a slerp over an hour's 15 degrees
    misses by up to ~0.2 degrees at the solstices."""
    dt_s = max(int(step_deg / _MAX_DEG_PER_MIN * 60.0), 1)
    posix = times.posix
    fine, day = [], []
    for di in np.unique(times.date_index):
        t = np.sort(posix[times.date_index == di])
        if len(t) < 2:
            continue
        grid = np.concatenate([np.arange(a, b, dt_s, dtype=np.float64)
                               for a, b in zip(t[:-1], t[1:])] + [t[-1:]])
        fine.append(grid)
        day.append(np.full(len(grid), di))
    if not fine:
        return []
    fine, day = np.concatenate(fine), np.concatenate(day)
    sp = solar_position(fine, params["latitude"], params["longitude"], params["elevation_m"],
                        pressure_hpa=params["pressure_hpa"],
                        temperature_c=params["temperature_c"], delta_t=params["delta_t"])
    d = sun_direction(sp.elevation, sp.azimuth, params["north_deg"])
    return [d[day == di] for di in np.unique(day)]


def _daylight(path) -> list:
    """The runs of consecutive directions of ``path`` (F, 3) above the horizon."""
    up = path[:, 2] > 0.0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], up.astype(np.int8), [0]])))
    return [path[a:b] for a, b in zip(edges[::2], edges[1::2])]


def _thin(cand, fixed, min_rad: float) -> np.ndarray:
    """``cand`` (K, 3) less those within ``min_rad`` (chord) of ``fixed`` or of an earlier
    kept candidate (greedy, in order)."""
    from scipy.spatial import cKDTree

    chord = 2.0 * np.sin(min_rad / 2.0)
    if len(fixed):
        d, _ = cKDTree(fixed).query(cand, k=1)
        cand = cand[d >= chord]
    if len(cand) < 2:
        return cand
    pairs = cKDTree(cand).query_pairs(chord, output_type="ndarray")
    if not len(pairs):
        return cand
    nbrs = [[] for _ in range(len(cand))]
    for i, j in pairs:
        lo, hi = (i, j) if i < j else (j, i)
        nbrs[lo].append(hi)
    dropped = np.zeros(len(cand), bool)
    for i in range(len(cand)):
        if not dropped[i]:
            for j in nbrs[i]:
                dropped[j] = True
    return cand[~dropped]
