"""The ``relight sun-study`` verb: parsing and printing only; the work is
:func:`...lt_addon.sun.sun_study.run_study` (bpy-free: the verb reads bake reports, never a
.blend)."""

from __future__ import annotations

import json
import os
import sys


def _hours(text: str) -> list:
    """``"9,12,15"`` or ``"9:30,12"`` -> clock hours as floats."""
    from .common import CliError

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
            raise CliError(f"bad clock hour {part!r}: give hours like 9,12,15 or 9:30") from None
    if not out:
        raise CliError("no clock hours given")
    return out


def _window(text: str) -> tuple:
    from .common import CliError

    got = _hours(text)
    if len(got) != 2:
        raise CliError(f"--window takes START,END clock hours (e.g. 6,20), got {text!r}")
    return tuple(got)


def add_parsers(sub) -> None:
    from ...lt_addon.sun import sun_study as ss

    p = sub.add_parser(
        "sun-study", help="sunlight hours and a shadow-study sheet from transport-texture bakes "
        "for a place and dates (NumPy)",
        description="For a place, dates and clock hours (or a step through each day) in an "
                    "IANA time zone: the Sun's positions by NREL's SPA, then per baked object "
                    "the hours of direct sun of every texel (the texel's visibility of each "
                    "sun from its transport T) as an EXR in hours, a PNG in false colour with "
                    "a legend, a shadow-study sheet (the relit texture per date and hour, in "
                    "texture space) and a CSV of min / mean / max hours; sun_study.json "
                    "records the suns, how far each is from the bake's directions, and the "
                    "timings. Reads the bakes' reports (bake-textures --method transport), "
                    "never the .blend.")
    p.add_argument("reports", nargs="+", metavar="BAKE_REPORT.json",
                   help="an object's <object>_texture_report.json; several for several objects")
    p.add_argument("--lat", type=float, required=True, metavar="DEG",
                   help="latitude in degrees, north positive")
    p.add_argument("--lon", type=float, required=True, metavar="DEG",
                   help="longitude in degrees, east positive (west negative)")
    p.add_argument("--tz", required=True, metavar="ZONE",
                   help="IANA time zone (Europe/London, Australia/Sydney; daylight saving "
                        "followed) or a fixed offset UTC+01:00")
    when = p.add_mutually_exclusive_group(required=True)
    when.add_argument("--dates", metavar="D,D,...",
                      help="local dates, ISO: 2026-06-21,2026-12-21")
    when.add_argument("--from", dest="date_from", metavar="DATE",
                      help="first date of a range (with --to)")
    p.add_argument("--to", dest="date_to", metavar="DATE", help="last date of the range")
    p.add_argument("--every-days", type=int, default=1, metavar="N",
                   help="with --from/--to: every N days (default 1)")
    step = p.add_mutually_exclusive_group(required=True)
    step.add_argument("--hours", type=_hours, metavar="H,H,...",
                      help="local clock hours of each date (9,12,15 or 9:30); each counts one "
                           "hour of sun; the sheet shows them")
    step.add_argument("--step-minutes", type=float, metavar="M",
                      help="an instant every M minutes of real time through each day (each "
                           "counts M minutes): sunlight hours over whole days")
    p.add_argument("--window", type=_window, default=(0.0, 24.0), metavar="START,END",
                   help="with --step-minutes: the local hours of each day (default 0,24)")
    p.add_argument("--north", type=float, default=0.0, metavar="DEG",
                   help="the scene's north: +Y turned by DEG towards +X (the Sun Position "
                        "add-on's North Offset; default 0: north is +Y)")
    p.add_argument("--elevation-m", type=float, default=0.0, metavar="M",
                   help="the site's height above sea level (SPA's parallax; default 0)")
    p.add_argument("--sun-angle", type=float, default=ss.SUN_ANGLE_DEG, metavar="DEG",
                   help=f"the Sun's angular diameter (default {ss.SUN_ANGLE_DEG:g})")
    p.add_argument("--visibility", choices=("threshold", "fraction"), default="threshold",
                   help="threshold: a texel counts each instant it sees the sun (its "
                        "visibility from T at least 0.5) wholly (default, the closer to a ray "
                        "count on average); fraction: the part it sees (shadow edges and "
                        "texels half under a wall count part)")
    p.add_argument("--sheet-hours", type=_hours, default=(9.0, 12.0, 15.0), metavar="H,H,...",
                   help="the sheet's clock hours when --step-minutes is given or --hours lists "
                        "too many cells (default 9,12,15; then on up to 6 of the dates)")
    p.add_argument("--radiation", action="store_true",
                   help="also the solar radiation map in kWh/m2 under a clear sky (beam from "
                        "T at each instant's Sun, the sky's diffuse light from the texel's view "
                        "of it; Ineichen-Perez): <object>_radiation.exr and .png")
    p.add_argument("--turbidity", type=float, default=3.0, metavar="TL",
                   help="the clear sky's Linke turbidity with --radiation (2: clean mountain "
                        "air, 3: rural, the default, 4-6: cities, summer haze)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created; its study files replaced only with --force)")
    p.add_argument("--force", action="store_true", help="replace an earlier study in --out")
    p.add_argument("--json", action="store_true",
                   help="print the report's objects and warnings as JSON")
    p.set_defaults(func=_cmd_sun_study)


def _cmd_sun_study(args) -> int:
    from ... import __version__
    from ...lt_addon.errors import InputError
    from ...lt_addon.sun import sun_study as ss
    from .common import EXIT_OK, CliError

    try:
        if args.dates is not None:
            if args.date_to is not None:
                raise CliError("--to goes with --from, not with --dates")
            dates = ss.dates_from([d for d in args.dates.split(",") if d.strip()])
        else:
            if args.date_to is None:
                raise CliError("--from needs --to (the last date of the range)")
            if args.every_days < 1:
                raise CliError(f"--every-days must be >= 1, got {args.every_days}")
            dates = ss.dates_from(start=args.date_from, end=args.date_to,
                                  every_days=args.every_days)
    except InputError as exc:
        raise CliError(str(exc)) from None
    settings = ss.StudySettings(
        latitude=args.lat, longitude=args.lon, tz=args.tz, dates=dates,
        hours=args.hours, step_minutes=args.step_minutes, window=args.window,
        north_deg=args.north, elevation_m=args.elevation_m, sun_angle=args.sun_angle,
        visibility=args.visibility, sheet_hours=tuple(args.sheet_hours),
        radiation=bool(args.radiation), turbidity=args.turbidity)
    out = os.path.abspath(args.out)
    if os.path.exists(out) and not os.path.isdir(out):
        raise CliError(f"output exists and is not a folder: {out}")
    try:
        report = ss.run_study([os.path.abspath(r) for r in args.reports], settings, out,
                              force=args.force, version=__version__,
                              echo=None if args.json else print)
    except InputError as exc:
        raise CliError(str(exc)) from None
    for line in report["warnings"]:
        print(f"relight: warning: {line}", file=sys.stderr)
    if args.json:
        print(json.dumps({"out": out, "objects": [
            {k: o[k] for k in ("object", "files", "hours", "nearest_baked_deg", "seconds")}
            for o in report["objects"]], "warnings": report["warnings"],
            "timings": report["timings"]}))
    else:
        n = report["instants"]
        print(f"sun study: {n['count']} instants, the Sun up at {n['sun_up']} "
              f"({n['possible_h']:g} h of sun), {report['timings']['total']:.2f} s; wrote {out}")
    return EXIT_OK
