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
Example: ``51.5,-0.13,Europe/London,2026-03-20,2026-06-21,2026-12-21``.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass

from ..errors import InputError

#: Most dates a study bake takes: each adds a day's path (about 100-200 directions at 1 degree);
#: a year of dates fills the band between the solstices (use the dates that matter, or the
#: default directions and the study's warning).
MAX_DATES = 24


@dataclass(frozen=True)
class StudySpec:
    latitude: float
    longitude: float
    tz: str
    dates: tuple
    north_deg: float = 0.0
    elevation_m: float = 0.0


def parse(text: str) -> StudySpec:
    """The :class:`StudySpec` of a study spec (module docstring); InputError naming what is
    wrong."""
    from .study_times import zone

    parts = [p.strip() for p in str(text).split(",") if p.strip()]
    form = ("expected LAT,LON,ZONE,DATE[,DATE...][,north=DEG][,elevation=M], e.g. "
            "51.5,-0.13,Europe/London,2026-06-21")
    if len(parts) < 3:
        raise InputError(f"bad study {str(text)[:80]!r}: {form}")
    try:
        lat, lon = float(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"bad study {str(text)[:80]!r}: latitude and longitude are degrees; "
                         f"{form}") from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise InputError(f"study latitude must be in -90..90 and longitude in -180..180, got "
                         f"{lat:g}, {lon:g}")
    tz = parts[2]
    try:
        zone(tz)
    except Exception as exc:     # an unknown zone name: say which, not the library's words
        raise InputError(f"study time zone {tz[:40]!r} is not known ({exc}); give an IANA "
                         "name (Europe/London) or a fixed offset (UTC+01:00)") from None
    dates, extra = [], {"north": 0.0, "elevation": 0.0}
    for p in parts[3:]:
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
        try:
            dates.append(_dt.date.fromisoformat(p))
        except ValueError:
            raise InputError(f"bad study date {p[:40]!r}: ISO dates, e.g. 2026-06-21") from None
    if not dates:
        raise InputError(f"bad study {str(text)[:80]!r}: no date; {form}")
    if len(dates) > MAX_DATES:
        raise InputError(f"a study bake takes up to {MAX_DATES} dates, got {len(dates)} (each "
                         "adds a day's sun path; pick the dates that matter)")
    return StudySpec(lat, lon, tz, tuple(sorted(set(dates))), extra["north"],
                     extra["elevation"])


def direction_set(base, text: str, step_deg: float):
    """``(DirectionSet, info)``: ``base`` plus the Sun of every whole hour of the study's dates
    and each date's path between them ``step_deg`` apart (:func:`.study_times.with_study`);
    ``info`` is the report's ``study`` entry."""
    from .study_times import study_suns, study_times, with_study

    spec = parse(text)
    times = study_times(list(spec.dates), spec.tz, step_minutes=60)
    suns = study_suns(times, spec.latitude, spec.longitude, spec.elevation_m,
                      north_deg=spec.north_deg)
    if not len(suns.directions):
        raise InputError(f"the Sun is below the horizon at every hour of the study's dates at "
                         f"{spec.latitude:g}, {spec.longitude:g} (polar night): nothing to add")
    dset = with_study(base, suns, times, step_deg=float(step_deg))
    p = dset.params
    info = {"latitude": spec.latitude, "longitude": spec.longitude, "tz": spec.tz,
            "dates": [d.isoformat() for d in spec.dates], "north_deg": spec.north_deg,
            "elevation_m": spec.elevation_m, "base": base.spec,
            "base_directions": p["base_kept"], "hour_directions": p["study_directions"],
            "path_directions": p["study_path_directions"], "step_deg": float(step_deg),
            "elevation_deg": p["study_elevation_deg"], "why": "asked for (--study)"}
    return dset, info
