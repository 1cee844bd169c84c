"""A sun study from transport-texture bakes, written to a folder (bpy-free): per object the
sunlight-hours map (EXR in hours, PNG in false colour with a legend), a shadow-study sheet of
relit textures, a CSV of hours per object and a JSON report. ``relight sun-study`` calls
:func:`run_study`; see docs/sun-studies.md.

The bakes are read with :func:`..transport.bundle.load_bake`, as files from elsewhere
(:mod:`..io.untrusted`); the study's instants and suns come from :mod:`.study_times` (SPA),
the hours from :mod:`.sunlight_hours`, the pictures from :mod:`.study_images`.
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import math
import os
import time
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import InputError
from . import study_images, sunlight_hours as sh
from .study_times import date_range, study_suns, study_times, zone

__all__ = ["StudySettings", "KIND", "FORMAT", "FAR_DEG", "SUN_ANGLE_DEG", "MAX_INSTANTS",
           "MAX_SHEET_CELLS", "run_study", "output_names"]

KIND = "sun_study"
#: The report's format and version (:mod:`..io.versions`).
FORMAT = "relightable_textures.sun_study"
FORMAT_VERSION = 1
#: A study sun farther than this from every baked direction is blended from its neighbours'
#: shadows (warned): measured in docs/sun-studies.md, a 400-direction bake (suns up to 5.7
#: degrees from it) against one that holds the study's suns.
FAR_DEG = 1.0
#: The Sun's mean angular diameter (0.524-0.542 degrees over the year).
SUN_ANGLE_DEG = 0.533
#: Instants a study may have: a year every 5 minutes (105,120) and some.
MAX_INSTANTS = 120_000
#: Most dates of a study with a weather file (each date's 24 hours are 144 Sun positions).
WEATHER_DATES = 4 * 366
#: A weather file further than this from the study's place is said to be (its station's
#: sky is another place's).
WEATHER_FAR_KM = 100.0
#: Cells of a shadow-study sheet at most; a longer list of clock hours draws the sheet at
#: ``sheet_hours`` on at most ``SHEET_DATES`` of the dates.
MAX_SHEET_CELLS = 60
SHEET_DATES = 6


def bake_for(settings) -> str:
    """What to do about suns far from the bake's directions: the ``bake-textures --study``
    that adds this study's hours and paths (:mod:`.study_directions`; a run of dates as a
    range, whose bake adds the paths of up to ``MAX_DATES`` of them spread over their
    declinations)."""
    from .study_directions import MAX_DATES, spec_text

    text = spec_text(settings.latitude, settings.longitude, settings.tz, settings.dates,
                     settings.north_deg, settings.elevation_m)
    n = len(set(str(getattr(d, "isoformat", lambda: d)()) for d in settings.dates))
    what = ("hours and sun paths" if n <= MAX_DATES else
            f"sun paths on {MAX_DATES} of the dates, spread over their declinations")
    return f"bake with --study {text} to add the study's {what}"


@dataclass
class StudySettings:
    """What a study asks (the CLI's options). Dates: ISO strings or dates; ``hours`` clock
    hours of each date (each counts one hour) or ``step_minutes`` through the local
    ``window`` (start, end hours) of each date (each instant counts its step)."""

    latitude: float
    longitude: float
    tz: str
    dates: list
    hours: list | None = None
    step_minutes: float | None = None
    window: tuple = (0.0, 24.0)
    north_deg: float = 0.0
    elevation_m: float = 0.0
    sun_angle: float = SUN_ANGLE_DEG
    visibility: str = "threshold"
    sheet_hours: tuple = (9.0, 12.0, 15.0)
    radiation: bool = False          # also the clear-sky radiation map (lt_addon/sun/radiation.py)
    turbidity: float = 3.0           # its Linke turbidity (lt_addon/sun/clear_sky.py)
    weather: str | None = None       # an EPW file: the radiation of its hours instead of a
                                     # clear sky (lt_addon/sun/weather.py); implies radiation

    def validate(self) -> None:
        """InputError in one line for anything out of range."""
        def finite(name, v, lo, hi):
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise InputError(f"{name} must be a number, got {v!r}") from None
            if not (math.isfinite(x) and lo <= x <= hi):
                raise InputError(f"{name} must be in {lo:g}..{hi:g}, got {v}")
            return x
        finite("latitude", self.latitude, -90.0, 90.0)
        finite("longitude", self.longitude, -180.0, 180.0)
        finite("north", self.north_deg, -360.0, 360.0)
        finite("elevation", self.elevation_m, -500.0, 9000.0)
        finite("sun angle", self.sun_angle, 0.0, 5.0)
        finite("Linke turbidity", self.turbidity, 1.0, 10.0)
        if self.visibility not in sh.VISIBILITY:
            raise InputError(f"visibility must be one of {', '.join(sh.VISIBILITY)}")
        if (self.hours is None) == (self.step_minutes is None):
            raise InputError("give either clock hours (--hours) or a step (--step-minutes)")
        if not self.dates:
            raise InputError("a study needs at least one date")
        try:
            zone(self.tz)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        if self.step_minutes is not None:
            finite("step", self.step_minutes, 1.0, 1440.0)
            a, b = (finite("window start", self.window[0], 0.0, 24.0),
                    finite("window end", self.window[1], 0.0, 24.0))
            if not a < b:
                raise InputError(f"the window must start before it ends, got {a:g}-{b:g}")
            per_day = (b - a) * 60.0 / float(self.step_minutes) + 1
            if per_day * len(self.dates) > MAX_INSTANTS:
                raise InputError(f"{len(self.dates)} dates every {self.step_minutes:g} minutes "
                                 f"are over {MAX_INSTANTS} instants: take a longer step or "
                                 "fewer dates (--every-days)")
        else:
            for h in list(self.hours) + list(self.sheet_hours):
                finite("a clock hour", h, 0.0, 23.9999)
            if len(self.hours) * len(self.dates) > MAX_INSTANTS:
                raise InputError(f"over {MAX_INSTANTS} instants")
        for h in self.sheet_hours:
            finite("a sheet hour", h, 0.0, 23.9999)
        if self.weather and len(self.dates) > WEATHER_DATES:
            # its radiation places the Sun 144 times a date (weather.py): bounded here
            raise InputError(f"a study with a weather file takes up to {WEATHER_DATES} dates "
                             f"(four years of days; a weather file holds one), got "
                             f"{len(self.dates)}")


def output_names(stem: str, radiation: bool = False) -> dict:
    """The files one object's study writes, by role."""
    return {"hours_exr": f"{stem}_sunlight_hours.exr", "hours_png": f"{stem}_sunlight_hours.png",
            "sheet_png": f"{stem}_shadow_study.png",
            **({"radiation_exr": f"{stem}_radiation.exr",
                "radiation_png": f"{stem}_radiation.png"} if radiation else {})}


#: The files every study writes once.
CSV_NAME, REPORT_NAME = "sunlight_hours.csv", "sun_study.json"


def clock_hours(text: str) -> list:
    """``"9,12,15"`` or ``"9:30,12"`` -> clock hours as floats; InputError in one line."""
    out = []
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        try:
            if ":" in part:
                h, m = part.split(":", 1)
                out.append(int(h) + int(m) / 60.0)
            else:
                out.append(float(part))
        except ValueError:
            raise InputError(f"bad clock hour {part!r}: give hours like 9,12,15 or 9:30") \
                from None
    if not out:
        raise InputError("no clock hours given")
    return out


def _clock(h: float) -> str:
    s = int(round(float(h) * 3600.0))
    return f"{s // 3600:02d}:{s % 3600 // 60:02d}" + (f":{s % 60:02d}" if s % 60 else "")


def _times(s: StudySettings, dates, hours=None):
    if hours is not None:
        return study_times(dates, s.tz, hours=hours)
    if s.hours is not None:
        return study_times(dates, s.tz, hours=s.hours)
    return study_times(dates, s.tz, step_minutes=s.step_minutes, start_hour=s.window[0],
                       end_hour=s.window[1])


def _suns(s: StudySettings, times):
    return study_suns(times, s.latitude, s.longitude, s.elevation_m, north_deg=s.north_deg)


def _sheet_plan(s: StudySettings, times):
    """(times, suns, dates, hours, why) of the shadow-study sheet: the study's own instants
    when it lists clock hours and they are few, else ``sheet_hours`` on up to
    :data:`SHEET_DATES` of its dates (first and last included)."""
    dates = list(times.dates)
    if s.hours is not None and len(dates) * len(set(s.hours)) <= MAX_SHEET_CELLS:
        hours = sorted({float(h) for h in s.hours})
        why = "the study's dates and clock hours"
    else:
        hours = sorted({float(h) for h in s.sheet_hours})
        if len(dates) > SHEET_DATES:
            pick = np.unique(np.rint(np.linspace(0, len(dates) - 1, SHEET_DATES)).astype(int))
            dates = [dates[i] for i in pick]
        why = (f"clock hours {', '.join(_clock(h) for h in hours)} on {len(dates)} of the "
               f"study's {len(times.dates)} dates")
    st = _times(s, dates, hours)
    return st, _suns(s, st), dates, hours, why


def _grid(times, dates, hours):
    """Row-major (date, hour) -> instant index or None (a clock time the day skips)."""
    at = {}
    for i, (di, ch) in enumerate(zip(times.date_index, times.clock_h)):
        at[(int(di), int(round(float(ch) * 3600.0)))] = i
    return [[at.get((di, int(round(h * 3600.0)))) for h in hours] for di in range(len(dates))]


def _sheet_cells(times, suns, dates, hours) -> list:
    """The shadow-study sheet's cells, row-major (date, clock hour): captions, the Sun's
    elevation and compass azimuth (degrees; None for a clock time the day does not have) and
    its direction in the scene's frame (a unit 3-vector, None while the Sun is down)."""
    cells = []
    for di, line in enumerate(_grid(times, dates, hours)):
        for hi, i in enumerate(line):
            day = dates[di].isoformat()
            cell = {"date": day, "clock": _clock(hours[hi]), "local": None, "elevation": None,
                    "azimuth": None, "direction": None}
            if i is None:
                cell.update(line1=f"{day} {_clock(hours[hi])}", line2="no such time (DST)")
                cells.append(cell)
                continue
            loc = times.local[i]
            cell.update(local=loc.isoformat(), elevation=round(float(suns.elevation[i]), 4),
                        azimuth=round(float(suns.azimuth[i]), 4),
                        line1=f"{day} {_clock(hours[hi])} {loc.tzname() or ''}".rstrip())
            if suns.up[i]:
                cell["direction"] = [float(v) for v in suns.directions[suns.index[i]]]
                cell["line2"] = f"el {suns.elevation[i]:.1f} az {suns.azimuth[i]:.1f}"
            else:
                cell["line2"] = f"sun down (el {suns.elevation[i]:.1f})"
            cells.append(cell)
    return cells


def run_study(report_paths, settings: StudySettings, out_dir: str, *, force: bool = False,
              version: str = "", echo=None, camera=None) -> dict:
    """Run the study on each bake report of ``report_paths`` and write its files into
    ``out_dir`` (created; a folder that does not exist yet is made whole or not at all).
    Existing output files are refused without ``force``. ``echo(line)`` gets a line per
    object as it is done. ``camera(folder, cells, n_cols, title, warnings, textures)``,
    given, draws the sheet from a scene camera into the same folder before it commits (the
    bpy layer's :mod:`...operators.preview.study_camera`; ``textures``: per object its UV map
    and each cell's direct-light texture); its dict is the report's ``camera``. Returns
    the report (also written as :data:`REPORT_NAME`), its ``warnings`` a list of lines."""
    from ..io import atomic, exrio
    from ..io.contact_sheet import write_png
    from ..io.names import object_stem
    from ..transport.bundle import load_bake

    t_start = time.perf_counter()
    settings.validate()
    try:
        times = _times(settings, settings.dates)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    t0 = time.perf_counter()
    suns = _suns(settings, times)
    step_h = times.step_h if times.step_h is not None else 1.0
    wh = np.bincount(suns.index[suns.up], minlength=len(suns.directions)) * step_h
    sheet_times, sheet_suns, sheet_dates, sheet_hours, sheet_why = _sheet_plan(settings, times)
    irradiance, rad_suns, weather_info, sky = None, suns, None, None
    warnings = []
    if settings.weather:
        from . import weather as wx

        w = wx.read_epw(settings.weather)
        rad_suns, *irradiance, weather_info = wx.study_irradiance(
            w, list(times.dates), settings.latitude, settings.longitude, settings.elevation_m,
            settings.north_deg)
        away = wx.distance_km(w.latitude, w.longitude, settings.latitude, settings.longitude)
        weather_info = {"file": os.path.basename(settings.weather), **w.place(),
                        "km_from_study": round(away, 1), **weather_info}
        sky = (f"weather file {weather_info['file']} ({w.city}, {w.country}; hourly direct "
               "normal and diffuse horizontal)")
        if away > WEATHER_FAR_KM:
            warnings.append(f"the weather file is for {w.city} ({w.latitude:g}, "
                            f"{w.longitude:g}), {away:.0f} km from the study's place: its "
                            "sky is not this place's")
        if weather_info["dates_missing"]:
            warnings.append(f"the weather file has no records for {len(weather_info['dates_missing'])} "
                            f"of the study's dates ({', '.join(weather_info['dates_missing'][:3])}"
                            f"{' ...' if len(weather_info['dates_missing']) > 3 else ''}): "
                            "their radiation is 0")
        if weather_info["left_out_kwh_m2"]["beam"] > 0.0:
            warnings.append(f"{weather_info['left_out_kwh_m2']['beam']:g} kWh/m2 of the "
                            "weather file's direct light falls in hours when the Sun is below "
                            "this place's horizon all hour, and is left out (is the file for "
                            "another place or time zone?)")
        if any(weather_info["missing_values"].values()):
            warnings.append(f"the weather file marks {weather_info['missing_values']} of its "
                            "hours' radiation missing (9999): counted as 0")
    elif settings.radiation:
        from . import radiation as rad

        irradiance = rad.study_irradiance(suns, times, linke_turbidity=settings.turbidity,
                                          altitude_m=settings.elevation_m)
        sky = f"clear (Ineichen-Perez), Linke turbidity {settings.turbidity:g}"
    t_suns = time.perf_counter() - t0

    # the bakes: every one read (and refused) before anything is written
    t0 = time.perf_counter()
    loaded, stems = [], set()
    for path in report_paths:
        bake, store, rep = load_bake(path)
        stem = object_stem(bake.name)
        if stem.lower() in stems:
            raise InputError(f"{path}: object {bake.name!r} is given twice")
        stems.add(stem.lower())
        loaded.append((path, bake, store, rep, stem))
    t_load = time.perf_counter() - t0
    out_dir = os.path.abspath(out_dir)
    names = [CSV_NAME, REPORT_NAME] + [n for *_, stem in loaded
                                       for n in output_names(stem, True).values()]
    names += list(getattr(camera, "outputs", ()))    # the camera sheet's, when it draws one
    if os.path.isdir(out_dir) and not force:
        there = [n for n in names if os.path.lexists(os.path.join(out_dir, n))]
        if there:
            raise InputError(f"{out_dir} already holds a study ({there[0]}); use --force to "
                             "replace it or choose another --out")

    if len(times.skipped):
        warnings.append(f"{len(times.skipped)} clock time(s) do not exist in {settings.tz} "
                        f"(daylight saving), left out: "
                        + ", ".join(t.strftime("%Y-%m-%d %H:%M") for t in times.skipped[:4])
                        + (" ..." if len(times.skipped) > 4 else ""))
    if not suns.up.any():
        warnings.append("the Sun is below the horizon at every instant of the study: every "
                        "map is 0 hours")

    sheet_cells = _sheet_cells(sheet_times, sheet_suns, sheet_dates, sheet_hours)

    def build(folder):
        rows, objects, textures = [], [], {}
        for path, bake, store, rep, stem in loaded:
            t0 = time.perf_counter()
            kernel = str(rep.get("settings", {}).get("kernel", "linear"))
            result = sh.sunlight_hours(store, suns.directions, wh, albedo=bake.albedo,
                                       sun_angle_deg=settings.sun_angle, kernel=kernel,
                                       visibility=settings.visibility)
            t_hours = time.perf_counter() - t0
            near = sh.nearest_baked(store.directions, suns.directions)
            near_t = (np.where(suns.up, near[np.maximum(suns.index, 0)], np.nan) if len(near)
                      else np.full(len(suns.index), np.nan))
            far = near > FAR_DEG
            if far.any():
                warnings.append(
                    f"{bake.name}: {int(far.sum())} of the study's {len(near)} sun directions "
                    f"are more than {FAR_DEG:g} deg from every baked direction (up to "
                    f"{near.max():.1f} deg, median {np.median(near):.1f}): their shadows are "
                    "blended from the neighbouring directions', and texels near a shadow edge "
                    f"can be off by hours; {bake_for(settings)} (docs/sun-studies.md)")
            files = output_names(stem, irradiance is not None)
            radiation = None
            if irradiance is not None:
                from . import radiation as rad

                rmap = rad.radiation_map(store, rad_suns, *irradiance,
                                         sun_angle_deg=settings.sun_angle, kernel=kernel,
                                         covered=result.covered)
                radiation = rmap.summary()
                radiation["seconds"] = round(rmap.seconds, 4)
                exrio.write_exr(os.path.join(folder, files["radiation_exr"]),
                                {"Y": rmap.total, "beam": rmap.beam, "diffuse": rmap.diffuse,
                                 "sky_view": rmap.sky_view,
                                 "A": rmap.covered.astype(np.float32)},
                                {"format": "relightable_textures.radiation",
                                 "object": bake.name, "unit": "kWh/m^2",
                                 "sky": sky,
                                 "horizontal_kwh_m2": rmap.horizontal_kwh}, pixel_type="float")
                top = max(float(rmap.total.max()), rmap.horizontal_kwh["total"])
                write_png(os.path.join(folder, files["radiation_png"]),
                          study_images.hours_picture(
                              rmap.total, rmap.covered, top,
                              [f"{bake.name}: solar radiation, "
                               + ("weather file" if weather_info else "clear sky"),
                               _place(settings), _span(times, settings)],
                              legend=f"kWh/m2, sun + sky; open ground "
                                     f"{rmap.horizontal_kwh['total']:.4g}"))
            t0 = time.perf_counter()
            summary = result.summary()
            exrio.write_exr(os.path.join(folder, files["hours_exr"]),
                            {"Y": result.hours, "A": result.covered.astype(np.float32)},
                            {"format": "relightable_textures.sunlight_hours",
                             "object": bake.name, "unit": "hours",
                             "possible_h": result.possible_h,
                             "visibility": settings.visibility}, pixel_type="float")
            title = [f"{bake.name}: sunlight hours", _place(settings), _span(times, settings)]
            write_png(os.path.join(folder, files["hours_png"]),
                      study_images.hours_picture(result.hours, result.covered,
                                                 result.possible_h, title))
            cells = []
            for cell in sheet_cells:
                if cell["direction"] is not None:
                    img = sh.direct_light(store, np.asarray(cell["direction"]),
                                          settings.sun_angle, kernel)
                elif cell["elevation"] is not None:     # the sun is down
                    img = np.zeros((store.resolution,) * 2, np.float32)
                else:                                   # no such clock time
                    img = None
                cells.append((img, cell["line1"], cell["line2"]))
            if camera is not None:     # the camera sheet reprojects them; else not kept
                textures[bake.name] = {"uv_map": rep.get("uv_map"),
                                       "cells": [c[0] for c in cells]}
            write_png(os.path.join(folder, files["sheet_png"]),
                      study_images.sheet(cells, len(sheet_hours),
                                         [f"{bake.name}: direct sun, white surface",
                                          _place(settings)]))
            t_images = time.perf_counter() - t0
            rows.append({"object": bake.name, **{k: summary.get(k) for k in
                                                 ("texels", "min_h", "mean_h", "max_h", "p10_h",
                                                  "median_h", "p90_h", "possible_h")},
                         **({f"radiation_{k}": radiation.get(k) for k in
                             ("min_kwh_m2", "mean_kwh_m2", "max_kwh_m2")} if radiation else {})})
            objects.append({
                "object": bake.name, "report": os.path.abspath(path), "files": files,
                "hours": summary, "visibility": settings.visibility,
                **({"radiation": radiation} if radiation else {}),
                "normals": "fitted to T (lt_addon/sun/sunlight_hours.py fit_normals)",
                "directions": {"size": int(store.directions.size),
                               "spec": store.directions.spec, "kind": store.directions.kind},
                "kernel": kernel, "resolution": int(store.resolution),
                "nearest_baked_deg": {"max": float(near.max()) if len(near) else None,
                                      "median": float(np.median(near)) if len(near) else None,
                                      "far_suns": int(far.sum()), "far_deg": FAR_DEG},
                "nearest_baked_deg_per_instant": [None if np.isnan(v) else round(float(v), 3)
                                                  for v in near_t],
                "seconds": {**result.seconds, "count": round(t_hours, 4),
                            "images": round(t_images, 4)}})
            if echo:
                echo(f"{bake.name}: {summary.get('min_h', 0):.2f} / "
                     f"{summary.get('mean_h', 0):.2f} / {summary.get('max_h', 0):.2f} h "
                     f"(min / mean / max over {summary.get('texels', 0)} texels, of "
                     f"{result.possible_h:g} h of sun) in {t_hours:.2f} s")
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(rows[0].keys()), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})
        atomic.write_text(os.path.join(folder, CSV_NAME), buf.getvalue())
        report = {
            "kind": KIND, "format": FORMAT, "format_version": FORMAT_VERSION,
            "addon_version": version,
            "inputs": {**{k: v for k, v in asdict(settings).items() if k != "dates"},
                       "dates": [d.isoformat() for d in times.dates],
                       "reports": [os.path.abspath(p) for p, *_ in loaded],
                       "hour_counts": ("each listed clock hour counts one hour"
                                       if settings.hours is not None else
                                       f"each instant counts its step, {step_h:g} h")},
            "solar_position": suns.params,
            **({"radiation_sky": sky} if sky else {}),
            **({"weather": weather_info} if weather_info else {}),
            "instants": {"count": len(times), "sun_up": int(suns.up.sum()),
                         "unique_sun_directions": int(len(suns.directions)),
                         "possible_h": float(wh.sum()),
                         "skipped_clock_times": [t.isoformat() for t in times.skipped],
                         "ambiguous_clock_times": int(times.ambiguous.sum()),
                         "local": [t.isoformat() for t in times.local],
                         "utc": [str(u) + "Z" for u in times.utc],
                         "elevation_deg": [round(float(v), 4) for v in suns.elevation],
                         "azimuth_deg": [round(float(v), 4) for v in suns.azimuth]},
            "sheet": {"what": sheet_why, "dates": [d.isoformat() for d in sheet_dates],
                      "hours": sheet_hours, "space": "texture (UV) space, not a camera",
                      "shows": "direct sun on a white surface (cos x visibility), sRGB",
                      "cells": sheet_cells},
            "objects": objects, "warnings": list(warnings),
            "timings": {"suns": round(t_suns, 4), "load": round(t_load, 4),
                        "total": round(time.perf_counter() - t_start, 4)}}
        if camera is not None:   # pictures from the scene's camera, in the same folder
            t0 = time.perf_counter()
            report["camera"] = camera(folder, sheet_cells, len(sheet_hours),
                                      [_place(settings)], warnings, textures)
            report["warnings"] = list(warnings)
            report["timings"]["camera"] = round(time.perf_counter() - t0, 4)
            report["timings"]["total"] = round(time.perf_counter() - t_start, 4)
        atomic.write_json(os.path.join(folder, REPORT_NAME), report, default=_json_default)
        return report

    if os.path.isdir(out_dir):
        return build(out_dir)
    parent = os.path.dirname(out_dir)
    if not os.path.isdir(parent):
        raise InputError(f"the output folder's parent does not exist: {parent}")
    with atomic.staged_folder(out_dir) as stage:
        report = build(stage)
    return report


def _json_default(v):
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, (_dt.date, _dt.datetime)):
        return v.isoformat()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON: {type(v).__name__}")


def _place(s: StudySettings) -> str:
    return (f"{abs(s.latitude):.2f}{'N' if s.latitude >= 0 else 'S'} "
            f"{abs(s.longitude):.2f}{'E' if s.longitude >= 0 else 'W'} {s.tz}"
            + (f" north {s.north_deg:g}" if s.north_deg else ""))


def _span(times, s: StudySettings) -> str:
    d = times.dates
    days = d[0].isoformat() if len(d) == 1 else f"{len(d)} days {d[0]}..{d[-1]}"
    return days + (f", {len(s.hours)} hours" if s.hours is not None
                   else f", every {s.step_minutes:g} min")


def dates_from(dates=None, start=None, end=None, every_days: int = 1) -> list:
    """The study's dates: a list of ISO dates, or ``start``..``end`` every ``every_days``."""
    def one(text):
        try:
            return _dt.date.fromisoformat(str(text).strip())
        except ValueError as exc:
            raise InputError(f"bad date {str(text).strip()[:40]!r}: {exc} (ISO dates: "
                             "2026-06-21)") from None
    if dates is not None:
        return [one(d) for d in dates]
    try:
        return date_range(one(start), one(end), every_days)
    except ValueError as exc:
        raise InputError(str(exc)) from None
