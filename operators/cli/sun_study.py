"""The ``relight sun-study`` verb: parsing and printing only; the work is
:func:`...lt_addon.sun.sun_study.run_study` (bpy-free: it reads bake reports), and with
``--camera`` :func:`..preview.study_camera.camera_sheet` (bpy: the .blend's camera and
previews)."""

from __future__ import annotations

import json
import os
import sys


def _hours(text: str) -> list:
    """``"9,12,15"`` or ``"9:30,12"`` -> clock hours as floats (:func:`clock_hours`)."""
    from ...lt_addon.errors import InputError
    from ...lt_addon.sun.sun_study import clock_hours
    from .common import CliError

    try:
        return clock_hours(text)
    except InputError as exc:
        raise CliError(str(exc)) from None


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
                    "timings. Reads the bakes' reports (bake-textures --method transport); "
                    "with --camera also the baked .blend, for the sheet from its camera.")
    p.add_argument("reports", nargs="+", metavar="BAKE_REPORT.json",
                   help="an object's <object>_texture_report.json; several for several objects")
    p.add_argument("--lat", type=float, metavar="DEG",
                   help="latitude in degrees, north positive (required unless --place-from)")
    p.add_argument("--lon", type=float, metavar="DEG",
                   help="longitude in degrees, east positive (west negative)")
    p.add_argument("--tz", metavar="ZONE",
                   help="IANA time zone (Europe/London, Australia/Sydney; daylight saving "
                        "followed) or a fixed offset UTC+01:00")
    p.add_argument("--place-from", metavar="FILE.blend",
                   help="the place, zone and north of this .blend's Sun Position add-on "
                        "settings instead of --lat/--lon/--tz (its UTC zone, plus an hour "
                        "with its Daylight Savings, as a fixed offset)")
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
    p.add_argument("--north", type=float, default=None, metavar="DEG",
                   help="the scene's north: +Y turned by DEG towards +X (the Sun Position "
                        "add-on's North Offset; default 0, or --place-from's: north is +Y)")
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
    p.add_argument("--weather", metavar="FILE.epw",
                   help="the radiation map from this EnergyPlus weather file's hourly direct "
                        "normal and diffuse horizontal radiation instead of a clear sky "
                        "(implies --radiation; the study's dates by month and day); without "
                        "--lat/--lon/--tz or --place-from, the place and standard-time zone of "
                        "its LOCATION line")
    p.add_argument("--camera", metavar="FILE.blend",
                   help="also the sheet from this .blend's scene camera (the file the bake put "
                        "its previews in): camera_sheet.png, one frame a cell in "
                        "camera_frames/, and one cell next to Cycles (camera_check.png)")
    p.add_argument("--camera-size", type=int, default=320, metavar="PX",
                   help="the camera sheet's cells, longer side in pixels (default 320; the "
                        "Cycles check renders at twice that)")
    p.add_argument("--check-cell", metavar="DATE,HH:MM",
                   help="the sheet cell to render with Cycles too (default: the lowest Sun at "
                        "least 5 deg up)")
    p.add_argument("--check-samples", type=int, default=128, metavar="N",
                   help="Cycles samples of that render (default 128; 0: no Cycles render)")
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
    place = _place(args)
    if place.get("elevation_m") is not None and args.elevation_m == 0.0:
        args.elevation_m = place["elevation_m"]
    settings = ss.StudySettings(
        latitude=place["latitude"], longitude=place["longitude"], tz=place["tz"], dates=dates,
        hours=args.hours, step_minutes=args.step_minutes, window=args.window,
        north_deg=place["north_deg"], elevation_m=args.elevation_m, sun_angle=args.sun_angle,
        visibility=args.visibility, sheet_hours=tuple(args.sheet_hours),
        radiation=bool(args.radiation or args.weather), turbidity=args.turbidity,
        weather=os.path.abspath(args.weather) if args.weather else None)
    out = os.path.abspath(args.out)
    if os.path.exists(out) and not os.path.isdir(out):
        raise CliError(f"output exists and is not a folder: {out}")
    camera = _camera(args) if args.camera else None
    try:
        report = ss.run_study([os.path.abspath(r) for r in args.reports], settings, out,
                              force=args.force, version=__version__,
                              echo=None if args.json else print, camera=camera)
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
        check = report.get("camera", {}).get("check")
        if check:
            print(f"camera: {len(report['camera']['frames'])} frames in "
                  f"{report['camera']['seconds']['total']:.1f} s; {check['date']} "
                  f"{check['clock']} vs Cycles: rel. RMSE "
                  f"{check['rel_rmse_baked_pixels']:.3f} ({check['png']})")
    return EXIT_OK


def _place(args) -> dict:
    """``{latitude, longitude, tz, north_deg}`` from --lat/--lon/--tz/--north, or from
    --place-from's Sun Position settings (--north still wins when given)."""
    from .common import CliError, check_input_blend

    given = [f for f, v in (("--lat", args.lat), ("--lon", args.lon), ("--tz", args.tz))
             if v is not None]
    if not args.place_from and not given and args.weather:
        from ...lt_addon.errors import InputError
        from ...lt_addon.sun.weather import read_epw

        try:
            w = read_epw(args.weather)
        except InputError as exc:
            raise CliError(str(exc)) from None
        print(f"sun study: the place of {os.path.basename(args.weather)}: {w.city}, "
              f"{w.latitude:g}, {w.longitude:g}, {w.tz} (standard time), {w.elevation_m:g} m")
        return {"latitude": w.latitude, "longitude": w.longitude, "tz": w.tz,
                "north_deg": args.north if args.north is not None else 0.0,
                "elevation_m": w.elevation_m}
    if not args.place_from:
        if len(given) < 3:
            missing = [f for f in ("--lat", "--lon", "--tz") if f not in given]
            raise CliError(f"give {', '.join(missing)} (the place and its time zone), or "
                           "--place-from FILE.blend (its Sun Position add-on's place)")
        return {"latitude": args.lat, "longitude": args.lon, "tz": args.tz,
                "north_deg": args.north if args.north is not None else 0.0}
    if given:
        raise CliError(f"--place-from takes the place from the .blend: drop {given[0]}")
    import bpy

    from ...lt_addon.errors import InputError
    from ...lt_addon.sun.study_directions import place_from_sun_position
    from ..base import sun_position
    from ..base.blend_files import blender_log_to_stderr

    path = check_input_blend(args.place_from)
    with blender_log_to_stderr():
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    values = sun_position.read(bpy.context.scene)
    if values is None:
        raise CliError(f"{path}: its scene holds no Sun Position settings (set a place in the "
                       "Sun Position add-on, or give --lat, --lon and --tz)")
    try:
        place = place_from_sun_position(values)
    except InputError as exc:
        raise CliError(f"{path}: {exc}") from None
    if args.north is not None:
        place["north_deg"] = args.north
    return place


def _camera(args):
    """Open ``--camera``'s .blend (checked like every input .blend) and return the hook that
    draws the sheet from its camera into the study's folder (:func:`run_study`'s
    ``camera``)."""
    import bpy

    from ..base.blend_files import blender_log_to_stderr
    from ..base.cycles_bake import BakeInputError
    from ..preview import study_camera
    from .common import CliError, check_input_blend

    if not 16 <= args.camera_size <= 4096:
        raise CliError(f"--camera-size must be in 16..4096, got {args.camera_size}")
    if args.check_samples < 0:
        raise CliError(f"--check-samples must be >= 0, got {args.check_samples}")
    path = check_input_blend(args.camera)
    with blender_log_to_stderr():
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    scene = bpy.context.scene
    if scene.camera is None:
        raise CliError(f"{path}: scene {scene.name!r} has no camera for --camera")

    def draw(folder, cells, n_cols, title, warnings, textures):
        try:
            with blender_log_to_stderr():
                info = study_camera.camera_sheet(
                    scene, folder, cells, n_cols, title, textures, sun_angle=args.sun_angle,
                    size=args.camera_size, check=args.check_cell,
                    check_size=2 * args.camera_size, check_samples=args.check_samples)
        except (BakeInputError, ValueError) as exc:
            raise CliError(f"--camera {args.camera}: {exc}") from None
        if info["not_in_scene"]:
            warnings.append(f"--camera {args.camera}: not a mesh of its scene, left out of the "
                            f"camera sheet: {', '.join(info['not_in_scene'])}")
        return info

    draw.outputs = study_camera.output_names(args.check_samples > 0)
    return draw
