"""The directions a sun study will ask for, baked up front (bpy-free): ``bake-textures --study``.

A sun study (:mod:`.sun_study`) relights a transport bake at every instant of its dates. Where an
instant's Sun is far from every baked direction, its shadows are blended from the neighbouring
directions' and texels near a shadow edge are off by hours (docs/sun-studies.md: 0.19 h a texel
with the 400 default directions, 0.02-0.03 h once the bake holds the study's sun paths). A study
spec names the place and dates; :func:`direction_set` adds the Sun of every hour of those dates
and each date's path between them, ``step_deg`` apart (:func:`.study_times.with_study`).

Spec: ``LAT,LON,ZONE,DATE[,DATE...][,north=DEG][,elevation=M]`` -- degrees north and east, an
IANA zone (or a fixed offset ``UTC+01:00``), ISO dates, and optionally the scene's north (the
*Sun Position* add-on's North Offset, as ``relight sun-study --north``) and the site's height.
Example: ``51.5,-0.13,Europe/London,2026-03-20,2026-06-21,2026-12-21``. A date may be a range,
``FIRST..LAST`` or ``FIRST..LAST/N`` (every N days): ``51.5,-0.13,Europe/London,2026-01-01..
2026-12-31/7``. Past :data:`MAX_DATES` dates the bake adds the paths of that many of them, spread
evenly over their declinations (:func:`bake_dates`), and the hours of those. Or
``scene,DATE[,DATE...]``: the place, zone and north the scene's *Sun Position* add-on holds
(:func:`place_from_sun_position`; the bpy layer reads them from the .blend).
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: Most dates whose paths a study bake adds: each adds a day's path (about 100-200 directions
#: at 1 degree), and a year of them would fill the band between the solstices (17,786
#: directions at 1 degree). A spec with more dates (a range, ``2026-01-01..2026-12-31``) bakes
#: the paths of this many, spread evenly over the dates' declinations (:func:`bake_dates`):
#: the other dates' paths lie between theirs.
MAX_DATES = 24
#: Most dates a spec may name, ranges expanded: four years of days.
MAX_SPEC_DATES = 4 * 366


#: The first field of a study spec that takes the place from the scene's Sun Position add-on.
FROM_SCENE = "scene"


@dataclass(frozen=True)
class StudySpec:
    latitude: float | None       # None: from the scene (FROM_SCENE)
    longitude: float | None
    tz: str | None
    dates: tuple
    north_deg: float | None = 0.0    # None: not given (from the scene: the add-on's)
    elevation_m: float = 0.0

    @property
    def from_scene(self) -> bool:
        return self.latitude is None


def place_from_sun_position(values: dict) -> dict:
    """The study's place from the *Sun Position* add-on's settings ``values``
    (:mod:`...operators.base.sun_position`: ``latitude``, ``longitude`` in degrees, ``UTC_zone``
    in hours, ``use_daylight_savings``, ``north_offset`` in radians): ``{latitude, longitude,
    tz, north_deg}``. The add-on keeps one offset all year (its daylight saving adds an hour to
    every date), so the zone is that fixed offset, ``UTC+HH:MM``. InputError when a value is
    out of range."""
    try:
        lat, lon = float(values["latitude"]), float(values["longitude"])
        hours = float(values.get("UTC_zone", 0.0)) + (1.0 if values.get("use_daylight_savings")
                                                      else 0.0)
        north = math.degrees(float(values.get("north_offset", 0.0)))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"the scene's Sun Position settings are not numbers ({exc})") from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and -14.0 <= hours <= 14.0
            and math.isfinite(north)):
        raise InputError(f"the scene's Sun Position settings are out of range: latitude "
                         f"{lat:g}, longitude {lon:g}, UTC zone {hours:g} h")
    minutes = int(round(hours * 60.0))
    tz = "UTC" if minutes == 0 else (f"UTC{'+' if minutes > 0 else '-'}"
                                     f"{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}")
    # the file holds float32 (-33.87 reads -33.869998...): 4 decimals, 11 m, 1e-4 deg of Sun
    return {"latitude": round(lat, 4), "longitude": round(lon, 4), "tz": tz,
            "north_deg": round(((north + 180.0) % 360.0) - 180.0, 4)}


def with_place(spec: StudySpec, place: dict) -> StudySpec:
    """``spec`` (from the scene) with ``place`` (:func:`place_from_sun_position`); a north
    given in the spec wins over the add-on's."""
    north = spec.north_deg if spec.north_deg is not None else place["north_deg"]
    return StudySpec(place["latitude"], place["longitude"], place["tz"], spec.dates, north,
                     spec.elevation_m)


def parse(text: str) -> StudySpec:
    """The :class:`StudySpec` of a study spec (module docstring); InputError naming what is
    wrong."""
    from .study_times import zone

    parts = [p.strip() for p in str(text).split(",") if p.strip()]
    form = ("expected LAT,LON,ZONE,DATE[,DATE...][,north=DEG][,elevation=M] (or "
            "scene,DATE,...: the Sun Position add-on's place), e.g. "
            "51.5,-0.13,Europe/London,2026-06-21")
    scene = bool(parts) and parts[0].lower() == FROM_SCENE
    if len(parts) < (2 if scene else 3):
        raise InputError(f"bad study {str(text)[:80]!r}: {form}")
    if scene:
        lat = lon = tz = None
    else:
        try:
            lat, lon = float(parts[0]), float(parts[1])
        except ValueError:
            raise InputError(f"bad study {str(text)[:80]!r}: latitude and longitude are "
                             f"degrees; {form}") from None
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise InputError(f"study latitude must be in -90..90 and longitude in -180..180, "
                             f"got {lat:g}, {lon:g}")
        tz = parts[2]
        try:
            zone(tz)
        except Exception as exc:     # an unknown zone name: say which, not the library's words
            raise InputError(f"study time zone {tz[:40]!r} is not known ({exc}); give an IANA "
                             "name (Europe/London) or a fixed offset (UTC+01:00)") from None
    dates, extra = [], {"north": None if scene else 0.0, "elevation": 0.0}
    for p in parts[1 if scene else 3:]:
        if "=" in p:
            key, _, value = p.partition("=")
            key = key.strip().lower()
            if key not in extra:
                raise InputError(f"bad study option {p[:40]!r}: north=DEG or elevation=M")
            try:
                extra[key] = float(value)
            except ValueError:
                raise InputError(f"bad study option {p[:40]!r}: {key} takes a number") from None
            continue
        dates.extend(_dates(p))
        if len(dates) > MAX_SPEC_DATES:
            raise InputError(f"a study spec names up to {MAX_SPEC_DATES} dates (four years of "
                             f"days), ranges expanded; {p[:40]!r} makes more")
    if not dates:
        raise InputError(f"bad study {str(text)[:80]!r}: no date; {form}")
    return StudySpec(lat, lon, tz, tuple(sorted(set(dates))), extra["north"],
                     extra["elevation"])


def _dates(part: str) -> list:
    """The dates of one spec field: ``DATE``, ``FIRST..LAST`` or ``FIRST..LAST/N``."""
    form = "ISO dates (2026-06-21) or a range FIRST..LAST[/EVERY_N_DAYS]"
    if ".." not in part:
        try:
            return [_dt.date.fromisoformat(part)]
        except ValueError:
            raise InputError(f"bad study date {part[:40]!r}: {form}") from None
    first, _, rest = part.partition("..")
    last, _, every = rest.partition("/")
    try:
        a, b = _dt.date.fromisoformat(first.strip()), _dt.date.fromisoformat(last.strip())
        n = int(every) if every.strip() else 1
    except ValueError:
        raise InputError(f"bad study date range {part[:40]!r}: {form}") from None
    if b < a or n < 1:
        raise InputError(f"bad study date range {part[:40]!r}: the last date comes after the "
                         f"first and the step is >= 1 day")
    if (b - a).days // n + 1 > MAX_SPEC_DATES:
        raise InputError(f"study date range {part[:40]!r} has more than {MAX_SPEC_DATES} "
                         "dates (four years of days)")
    return [a + _dt.timedelta(days=i * n) for i in range((b - a).days // n + 1)]


def bake_dates(dates, longitude: float = 0.0, max_dates: int = MAX_DATES) -> list:
    """The dates (sorted ``datetime.date``) whose paths a study bake adds: all of ``dates`` up
    to ``max_dates``, else ``max_dates`` of them spread evenly over the Sun's declination on
    those dates (at local solar noon, ``longitude`` degrees east): the two extremes and the
    dates nearest the levels between. A day's path is the parallel of its declination, so the
    others' paths lie between two baked ones, at most half the largest gap away (about 1
    degree for a year's 46.9 degrees over 24 dates)."""
    from .solar_position import declination

    dates = sorted(set(dates))
    if len(dates) <= max_dates:
        return dates
    noon = np.array([_dt.datetime(d.year, d.month, d.day, 12, tzinfo=_dt.timezone.utc)
                     .timestamp() - float(longitude) / 15.0 * 3600.0 for d in dates])
    dec = declination(noon)
    picked = set()
    for level in np.linspace(dec.min(), dec.max(), int(max_dates)):
        order = np.argsort(np.abs(dec - level), kind="stable")
        picked.add(int(next((i for i in order if int(i) not in picked), order[0])))
    return [dates[i] for i in sorted(picked)]


def spec_text(latitude, longitude, tz, dates, north_deg=0.0, elevation_m=0.0) -> str:
    """A study spec for these dates, the inverse of :func:`parse`: a regular run of dates
    (three or more, N days apart) as ``FIRST..LAST[/N]``, a short list as it is, and a long
    irregular one as the range from its first to its last date (a bake adds the paths of
    :data:`MAX_DATES` spread over the range's declinations either way)."""
    ds = sorted(set(d if isinstance(d, _dt.date) else _dt.date.fromisoformat(str(d))
                    for d in dates))
    gaps = {(b - a).days for a, b in zip(ds, ds[1:])}
    if len(ds) >= 3 and len(gaps) == 1:
        n = gaps.pop()
        text = f"{ds[0]}..{ds[-1]}" + (f"/{n}" if n > 1 else "")
    elif len(ds) <= MAX_DATES:
        text = ",".join(d.isoformat() for d in ds)
    else:
        text = f"{ds[0]}..{ds[-1]}"
    extra = "".join(f",{k}={v:g}" for k, v in (("north", north_deg or 0.0),
                                                 ("elevation", elevation_m or 0.0)) if v)
    return f"{latitude:g},{longitude:g},{tz},{text}{extra}"


def direction_set(base, text: str, step_deg: float, place: dict | None = None):
    """``(DirectionSet, info)``: ``base`` plus the Sun of every whole hour of the study's dates
    and each date's path between them ``step_deg`` apart (:func:`.study_times.with_study`);
    ``info`` is the report's ``study`` entry. ``place``: the scene's Sun Position place
    (:func:`place_from_sun_position`), which a ``scene,...`` spec needs."""
    from .study_times import study_suns, study_times, with_study

    spec = parse(text)
    if spec.from_scene:
        if place is None:
            raise InputError("the study takes its place from the scene ('scene,...'), but the "
                             "scene holds no Sun Position settings: set a place in the Sun "
                             "Position add-on, or give LAT,LON,ZONE")
        spec = with_place(spec, place)
    baked = bake_dates(spec.dates, spec.longitude)
    times = study_times(baked, spec.tz, step_minutes=60)
    suns = study_suns(times, spec.latitude, spec.longitude, spec.elevation_m,
                      north_deg=spec.north_deg)
    if not len(suns.directions):
        raise InputError(f"the Sun is below the horizon at every hour of the study's dates at "
                         f"{spec.latitude:g}, {spec.longitude:g} (polar night): nothing to add")
    dset = with_study(base, suns, times, step_deg=float(step_deg))
    p = dset.params
    info = {"latitude": spec.latitude, "longitude": spec.longitude, "tz": spec.tz,
            "dates": [d.isoformat() for d in baked], "north_deg": spec.north_deg,
            **({"spec_dates": len(spec.dates), "dates_chosen": (
                f"{len(baked)} of the spec's {len(spec.dates)} dates, spread evenly over "
                "their declinations (the others' paths lie between theirs)")}
               if len(baked) < len(spec.dates) else {}),
            "elevation_m": spec.elevation_m, "base": base.spec,
            "base_directions": p["base_kept"], "hour_directions": p["study_directions"],
            "path_directions": p["study_path_directions"], "step_deg": float(step_deg),
            "elevation_deg": p["study_elevation_deg"], "why": "asked for (--study)",
            **({"place_from": "the scene's Sun Position add-on"} if place is not None
               and parse(text).from_scene else {})}
    return dset, info
