"""Benchmark: sun studies from a transport bake (issue 58) -- sunlight hours against a
brute-force ray count, and the time of a year of hourly suns.

The scene: a courtyard of three walls (2 m and 1.5 m high) on an 8 m ground (Blender
primitives), the ground and the north wall baked by the product's bake (rays, footprint texels
unless said). The study: London (51.5 N, 0.13 W, Europe/London), the March equinox and both
solstices, every ``--step`` minutes. The reference casts a ray from every texel centre towards
every sun of the study with the project's engine (lt_addon/rays: Occluder, direct_rows;
receiver points without footprints) and counts the hours lit. Bakes compared: 48 and 400
directions (hemi:N:1.5), 400 plus the study's hourly suns (with_study), plus their paths at 2,
1 and 0.5 degrees; footprint and centre texels. Then ``relight sun-study`` over a year of hourly
suns on the 400-direction bake of the ground at each ``--year-sizes`` side, with its clear-sky
radiation map (``--radiation``), timed, and (with
``--pictures``) the docs' pictures at 256^2.

Usage: python benchmarks/bench_sun_study.py [--resolution 32] [--step 10]
       [--year-sizes 256,1024] [--pictures docs/bench] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time

import numpy as np

DATES = ["2026-03-20", "2026-06-21", "2026-12-21"]
PLACE = dict(latitude=51.5, longitude=-0.13)
TZ = "Europe/London"
CLI_PLACE = ["--lat", "51.5", "--lon", "-0.13", "--tz", TZ]


def courtyard():
    """A fresh factory scene with the courtyard of tests/blender/test_sun_study.py (its own
    builder); returns [ground, north wall]."""
    import bpy

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "tests", "blender"))
    from test_sun_study import _courtyard

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return _courtyard(bpy.context.scene)


def bake(scene, objects, out, R, dset=None, **kw):
    """The product's bake (direct light only) with direction set ``dset`` when given (put where
    the scene's animated Sun's path would go: bake-textures cannot take a study yet)."""
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    settings = tx.TransportTextureSettings(directions="hemi:400:1.5", resolution=R, bounces=0,
                                           model="none", **kw)
    orig = tx.resolve_directions
    if dset is not None:
        tx.resolve_directions = lambda scene, settings: (dset, None)
    try:
        t0 = time.perf_counter()
        res = run(tx.bake_transport_textures(scene, objects, settings, str(out), False))
        return res, time.perf_counter() - t0
    finally:
        tx.resolve_directions = orig


def _brute_force(R: int, dates, step: float):
    """The courtyard, the study's instants every ``step`` minutes of ``dates`` at London, and
    per baked object (texel indices, hours lit) by a ray from every texel centre to every sun:
    ``(objects, scene, times, suns, hour weights, brute)``."""
    import bpy
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.lt_addon.sun import study_times as st
    from relightable_textures.operators.base import ray_scene

    objects = courtyard()
    scene = bpy.context.scene
    times = st.study_times(dates, TZ, step_minutes=step)
    suns = st.study_suns(times, **PLACE)
    wh = np.bincount(suns.index[suns.up], minlength=len(suns.directions)) * times.step_h
    with ray_scene.RenderGeometry(scene) as depsgraph:
        V, T, _ = ray_scene.casters(depsgraph)
        occluder = Occluder(V, T)
        points = [ray_scene.receiver_points(o, depsgraph, R, None, footprint=False)
                  for o in objects]
    brute = [(smp.texel, wh @ (direct_rows(occluder, pts, suns.directions) > 0))
             for smp, pts in points]
    return objects, scene, times, suns, wh, brute


def accuracy(R: int, step: float) -> list:
    from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
    from relightable_textures.lt_addon.sun import study_times as st
    from relightable_textures.lt_addon.sun import sunlight_hours as sh

    t0 = time.perf_counter()
    objects, scene, times, suns, wh, brute = _brute_force(R, DATES, step)
    t_brute = time.perf_counter() - t0
    hourly = st.study_times(DATES, TZ, step_minutes=60)
    hourly_suns = st.study_suns(hourly, **PLACE)
    base = parse_direction_spec("hemi:400:1.5")
    sets = {"hemi:48:1.5": parse_direction_spec("hemi:48:1.5"), "hemi:400:1.5": base,
            "hemi:400:1.5 + hourly suns": st.with_study(base, hourly_suns, hourly)}
    for step_deg in (2.0, 1.0, 0.5):
        sets[f"hemi:400:1.5 + paths {step_deg:g} deg"] = st.with_study(
            base, hourly_suns, hourly, step_deg=step_deg)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for sampling in ("footprint", "centre"):
            for name, dset in sets.items():
                res, t_bake = bake(scene, objects, os.path.join(tmp, "b"), R, dset,
                                   texel_sampling=sampling)
                for ob, (texel, count) in zip(res.objects, brute):
                    near = sh.nearest_baked(ob.store.directions, suns.directions)
                    for vis in sh.VISIBILITY:
                        t1 = time.perf_counter()
                        got = sh.sunlight_hours(ob.store, suns.directions, wh, albedo=ob.albedo,
                                                sun_angle_deg=0.533, visibility=vis)
                        t_hours = time.perf_counter() - t1
                        d = np.abs(got.hours.reshape(-1)[texel] - count)
                        rows.append({
                            "texels": sampling, "directions": name,
                            "size": int(ob.store.directions.size), "object": ob.name,
                            "visibility": vis, "mean_h": round(float(d.mean()), 3),
                            "p95_h": round(float(np.percentile(d, 95)), 2),
                            "worst_h": round(float(d.max()), 2),
                            "texels_over_1h": int((d > 1.0).sum()), "of_texels": int(d.size),
                            "possible_h": round(float(wh.sum()), 2),
                            "nearest_baked_deg_median": round(float(np.median(near)), 2),
                            "nearest_baked_deg_max": round(float(near.max()), 2),
                            "bake_s": round(t_bake, 2), "hours_s": round(t_hours, 3),
                            "brute_force_s": round(t_brute, 3)})
                        print(json.dumps(rows[-1]), flush=True)
    return rows


def year_range(R: int) -> list:
    """A year of hourly suns against the brute-force ray count from texel centres: the
    400-direction bake, and the bake of the study as a range (``--study
    51.5,-0.13,Europe/London,2026-01-01..2026-12-31``: the paths of 24 dates spread over the
    year's declinations, at 1 degree), both with centre texels (as the rays) and the default
    footprint texels; hours per texel off the ray count, bake times."""
    from relightable_textures.lt_addon.sun import study_times as st
    from relightable_textures.lt_addon.sun import sunlight_hours as sh

    objects, scene, times, suns, wh, brute = _brute_force(
        R, st.date_range("2026-01-01", "2026-12-31"), 60)
    study = "51.5,-0.13,Europe/London,2026-01-01..2026-12-31"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for sampling in ("centre", "footprint"):
            for name, kw in (("hemi:400:1.5", {}),
                             ("+ the year as a range at 1 deg", {"study": study,
                                                                 "sun_path_step": 1.0})):
                res, t_bake = bake(scene, objects, os.path.join(tmp, "b"), R,
                                   texel_sampling=sampling, **kw)
                for ob, (texel, count) in zip(res.objects, brute):
                    near = sh.nearest_baked(ob.store.directions, suns.directions)
                    got = sh.sunlight_hours(ob.store, suns.directions, wh, albedo=ob.albedo,
                                            sun_angle_deg=0.533, visibility="threshold")
                    d = np.abs(got.hours.reshape(-1)[texel] - count)
                    rows.append({"texels": sampling, "directions": name,
                                 "size": int(ob.store.directions.size), "object": ob.name,
                                 "mean_h": round(float(d.mean()), 2),
                                 "p95_h": round(float(np.percentile(d, 95)), 1),
                                 "worst_h": round(float(d.max()), 1),
                                 "possible_h": round(float(wh.sum()), 1),
                                 "nearest_baked_deg_median": round(float(np.median(near)), 2),
                                 "nearest_baked_deg_max": round(float(near.max()), 2),
                                 "bake_s": round(t_bake, 1)})
                    print(json.dumps(rows[-1]), flush=True)
    return rows


def weather_year(R: int) -> dict:
    """A year's radiation from a real weather file against the clear sky: pvlib's bundled TMY3
    of Greensboro, NC (36.1 N, 79.95 W; measured and modelled hours of 1976-1990) written as an
    EPW with the tests' writer, ``relight sun-study --weather`` on the courtyard's 400-direction
    bake at R^2, then the same study under the clear sky. The open ground's total is checked
    against the file's own global horizontal sum (independent of our suns: GHI = DNI cos z +
    DHI, measured)."""
    import pvlib
    from relightable_textures.operators.cli.commands import run

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "tests", "core"))
    objects = courtyard()
    tmy, meta = pvlib.iotools.read_tmy3(os.path.join(pvlib.__path__[0], "data",
                                                     "723170TYA.CSV"), map_variables=True)
    out = {"file": "pvlib data/723170TYA.CSV (TMY3) as EPW", "place": meta["Name"].strip('"'),
           "file_ghi_kwh_m2": round(float(tmy["ghi"].sum()) / 1000.0, 1),
           "file_dni_kwh_m2": round(float(tmy["dni"].sum()) / 1000.0, 1),
           "file_dhi_kwh_m2": round(float(tmy["dhi"].sum()) / 1000.0, 1), "resolution": R}
    with tempfile.TemporaryDirectory() as tmp:
        epw = os.path.join(tmp, "greensboro.epw")
        head = [f"LOCATION,Greensboro,NC,USA,TMY3,723170,{meta['latitude']},"
                f"{meta['longitude']},{meta['TZ']},{meta['altitude']}"] + [
            "DESIGN CONDITIONS,0", "TYPICAL/EXTREME PERIODS,0", "GROUND TEMPERATURES,0",
            "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0", "COMMENTS 1,", "COMMENTS 2,",
            "DATA PERIODS,1,1,Data,Sunday, 1/ 1,12/31"]
        rows = []
        for _, r in tmy.iterrows():       # TMY3's hours end at their time, as EPW's
            month, day, year_ = (int(x) for x in r["Date (MM/DD/YYYY)"].split("/"))
            hour = int(r["Time (HH:MM)"].split(":")[0])
            rows.append(",".join(str(v) for v in [
                year_, month, day, hour, 60, "?", 10, 5, 70, 101325, 0, 0,
                300, int(r["ghi"]), int(r["dni"]), int(r["dhi"])] + ["0"] * 19))
        with open(epw, "w") as fh:
            fh.write("\n".join(head + rows) + "\n")
        import bpy

        blend = os.path.join(tmp, "court.blend")
        bpy.ops.wm.save_as_mainfile(filepath=blend)
        t0 = time.perf_counter()
        assert run(["bake-textures", blend, "--object", "Ground", "--object", "WallN",
                    "--method", "transport", "--resolution", str(R), "--bounces", "0",
                    "--model", "none", "--out", os.path.join(tmp, "bake")]) == 0
        out["bake_s"] = round(time.perf_counter() - t0, 1)
        reports = [os.path.join(tmp, "bake", f"{o}_texture_report.json")
                   for o in ("Ground", "WallN")]
        when = ["--from", "2026-01-01", "--to", "2026-12-31", "--step-minutes", "60"]
        place = ["--lat", str(meta["latitude"]), "--lon", str(meta["longitude"]), "--tz",
                 "UTC-05:00", "--elevation-m", str(meta["altitude"])]
        for name, extra in (("weather", ["--weather", epw]), ("clear sky", place
                                                              + ["--radiation"])):
            t0 = time.perf_counter()
            folder = os.path.join(tmp, name.replace(" ", "_"))
            assert run(["sun-study", *reports, *when, *extra, "--out", folder]) == 0
            rep = json.load(open(os.path.join(folder, "sun_study.json")))
            out[name] = {"seconds": round(time.perf_counter() - t0, 1),
                         "open_ground_kwh_m2": {k: round(v, 1) for k, v in rep["objects"][0][
                             "radiation"]["horizontal_kwh_m2"].items()},
                         **{o["object"]: o["radiation"]["mean_kwh_m2"]
                            for o in rep["objects"]},
                         **({"weather": {k: rep["weather"][k] for k in (
                             "records_used", "left_out_kwh_m2", "missing_values")}}
                            if "weather" in rep else {})}
    print(json.dumps(out), flush=True)
    return out


def year(R: int, pictures: str | None) -> dict:
    """A year of hourly suns on the ground's 400-direction bake at R^2, by the CLI, timed."""
    import bpy
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.cli.commands import run as cli

    objects = courtyard()
    with tempfile.TemporaryDirectory() as tmp:
        res, t_bake = bake(bpy.context.scene, objects[:1], tmp, R)
        report = tx.write_bake(res, objects[:1], tmp)[0]["report"]
        t0 = time.perf_counter()
        rc = cli(["sun-study", report, *CLI_PLACE, "--from", "2026-01-01", "--to", "2026-12-31",
                  "--step-minutes", "60", "--radiation", "--out", os.path.join(tmp, "year")])
        wall = time.perf_counter() - t0
        rep = json.load(open(os.path.join(tmp, "year", "sun_study.json")))
        if pictures and rc == 0:
            shutil.copy(os.path.join(tmp, "year", "Ground_sunlight_hours.png"),
                        os.path.join(pictures, "sun-study-courtyard-year.png"))
            shutil.copy(os.path.join(tmp, "year", "Ground_radiation.png"),
                        os.path.join(pictures, "sun-study-courtyard-year-radiation.png"))
            rc2 = cli(["sun-study", report, *CLI_PLACE, "--dates", ",".join(DATES), "--hours",
                       "9,12,15", "--out", os.path.join(tmp, "sheet")])
            if rc2 == 0:
                shutil.copy(os.path.join(tmp, "sheet", "Ground_shadow_study.png"),
                            os.path.join(pictures, "sun-study-courtyard-sheet-400.png"))
    out = {"resolution": R, "rc": rc, "bake_s": round(t_bake, 1), "wall_s": round(wall, 2),
           "instants": rep["instants"]["count"], "sun_up": rep["instants"]["sun_up"],
           "timings": rep["timings"], "object_seconds": rep["objects"][0]["seconds"],
           "radiation": rep["objects"][0].get("radiation")}
    print(json.dumps(out), flush=True)
    return out


def sheet_with_paths(pictures: str) -> None:
    """The docs' sheet from a 256^2 bake that holds the sheet's suns and their paths at 1
    degree (hemi:400:1.5 + with_study)."""
    import bpy
    from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
    from relightable_textures.lt_addon.sun import study_times as st
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.cli.commands import run as cli

    objects = courtyard()
    times = st.study_times(DATES, TZ, hours=[9, 12, 15])
    dset = st.with_study(parse_direction_spec("hemi:400:1.5"), st.study_suns(times, **PLACE),
                         times, step_deg=1.0)
    with tempfile.TemporaryDirectory() as tmp:
        res, _ = bake(bpy.context.scene, objects[:1], tmp, 256, dset)
        report = tx.write_bake(res, objects[:1], tmp)[0]["report"]
        if cli(["sun-study", report, *CLI_PLACE, "--dates", ",".join(DATES), "--hours",
                "9,12,15", "--out", os.path.join(tmp, "sheet")]) == 0:
            shutil.copy(os.path.join(tmp, "sheet", "Ground_shadow_study.png"),
                        os.path.join(pictures, "sun-study-courtyard-sheet-paths.png"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--step", type=float, default=10.0, help="minutes between instants")
    ap.add_argument("--year-sizes", default="256,1024",
                    help="texture sides of the timed year of hourly suns ('' for none)")
    ap.add_argument("--pictures", metavar="DIR", help="write the docs' pictures here")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args(argv)
    out = {"date": time.strftime("%Y-%m-%d %H:%M"), "machine": platform.platform(),
           "cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
           "resolution": args.resolution, "step_minutes": args.step,
           "accuracy": accuracy(args.resolution, args.step),
           "year_range": year_range(args.resolution),
           "weather_year": weather_year(64),
           "year": [year(int(r), args.pictures if int(r) == 256 else None)
                    for r in args.year_sizes.split(",") if r.strip()]}
    if args.pictures:
        sheet_with_paths(args.pictures)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
