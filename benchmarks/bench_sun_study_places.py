"""Benchmark: one courtyard, two latitudes (issue 58's "must show"), through the CLI as a
user runs it -- and what a year of hourly maps costs against the Cycles renders it replaces.

The scene: the courtyard of tests/blender/test_sun_study.py (three walls, 2 m and 1.5 m high,
on an 8 m ground) with a balcony slab on the north wall's courtyard side (1.6 x 1.0 x 0.1 m,
its top 1.25 m up) and a camera; every mesh baked. Two places: London (51.5 N, 0.13 W,
Europe/London) and Sydney (33.87 S, 151.21 E, Australia/Sydney). For each:

1. ``bake-textures --study PLACE,<equinox and solstices> --sun-path-step 1`` (400 directions
   plus the study's hourly suns and their paths) at ``--resolution``;
2. ``sun-study --hours 9,12,15 --camera --radiation``: the texture-space and camera shadow-study
   sheets, and the camera check cell against Cycles (the lowest Sun at least 5 deg up,
   ``--check-samples`` spp at twice ``--camera-size``);
3. ``sun-study --from 2026-01-01 --to 2026-12-31 --step-minutes 60 --radiation``: the year's
   sunlight-hours and clear-sky radiation maps (the year's suns are blended from the baked
   directions; the command says how far they are).

Then the cost: the ground alone baked at ``--cost-size`` (400 directions, direct light: what
the maps read), the year's hourly maps on it timed, and in the same run one Cycles render of
one hour from the camera at ``--cost-size`` px wide (the check cell of a one-hour study):
one render answers one hour, and a year has 4,461 hours of sun in London.

Usage: python benchmarks/bench_sun_study_places.py --out DIR [--resolution 256]
       [--camera-size 512] [--check-samples 128] [--cost-size 1024] [--pictures docs/bench]
       [--cost-only]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import time

DATES = "2026-03-20,2026-06-21,2026-12-21"
PLACES = {"london": ("51.5", "-0.13", "Europe/London"),
          "sydney": ("-33.87", "151.21", "Australia/Sydney")}
MESHES = ("Ground", "WallN", "WallW", "WallE", "Balcony")


def build(path: str) -> None:
    """The courtyard with a balcony and a camera, saved to ``path``."""
    import bpy

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "tests", "blender"))
    from test_sun_study import _courtyard

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    _courtyard(scene)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 1.3, 1.2))
    slab = bpy.context.object
    slab.name, slab.scale = "Balcony", (1.6, 1.0, 0.1)
    bpy.ops.object.transform_apply(scale=True)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location, cam.rotation_euler = (10.0, -10.0, 9.0), (0.93, 0.0, 0.785)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 800, 600
    bpy.ops.wm.save_as_mainfile(filepath=path)


def viewport_picture(blend: str, year: str, png: str, where: str, size: int = 800) -> dict:
    """The year's hours map as the viewport shows it (*Show Sun Study Map*): the .blend's
    camera, the previews rendered by Cycles (emission only, 16 samples), with the maps'
    legend under it."""
    import bpy
    import numpy as np

    from relightable_textures.lt_addon.io.contact_sheet import linear_to_srgb8, write_png
    from relightable_textures.lt_addon.sun import study_images
    from relightable_textures.operators.preview import compare_render, preview_nodes
    from relightable_textures.operators.preview import sun_study_preview

    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
    scene = bpy.context.scene
    info = sun_study_preview.show(scene, year, "hours")
    restore = compare_render.saved_render_settings(scene)
    r = scene.render
    f = size / max(r.resolution_x, r.resolution_y)
    r.resolution_x, r.resolution_y = round(r.resolution_x * f), round(r.resolution_y * f)
    r.resolution_percentage = 100
    scene.world = None
    scene.cycles.use_denoising = False
    undo = preview_nodes.render_previews(list(scene.objects), "CYCLES")
    try:
        img = compare_render.render_camera(scene, png + ".exr", 16)
    finally:
        for fn in undo:
            fn()
        restore()
    os.remove(png + ".exr")
    W = img.shape[1]
    strip = study_images.hours_picture(np.zeros((1, W)), np.ones((1, W), bool), info["top"],
                                       min_width=W)[1:]     # its legend, below the one row
    pic = np.concatenate([linear_to_srgb8(img[::-1]), strip], axis=0)
    title = f"{where}: hours of direct sun in 2026"
    write_png(png, study_images._titled(pic, title, 2))
    return info


def relight(argv) -> None:
    from relightable_textures.operators.cli.commands import run

    rc = run([str(a) for a in argv])
    if rc != 0:
        raise SystemExit(f"bench: relight {argv[0]} exited {rc}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--camera-size", type=int, default=512)
    ap.add_argument("--check-samples", type=int, default=128)
    ap.add_argument("--cost-size", type=int, default=1024)
    ap.add_argument("--pictures", help="copy the docs' pictures into this folder")
    ap.add_argument("--cost-only", action="store_true", help="only the cost measurement")
    args = ap.parse_args(argv)
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    figures = {"machine": f"{platform.machine()}, {os.cpu_count()} cores",
               "date": time.strftime("%Y-%m-%d %H:%M"), "places": {}}
    for place, (lat, lon, tz) in ({} if args.cost_only else PLACES).items():
        blend = os.path.join(out, f"{place}.blend")
        build(blend)
        study = f"{lat},{lon},{tz},{DATES}"
        where = ["--lat", lat, "--lon", lon, "--tz", tz]
        t0 = time.perf_counter()
        relight(["bake-textures", blend, *[a for m in MESHES for a in ("--object", m)],
                 "--resolution", args.resolution, "--study", study, "--sun-path-step", "1",
                 "--force"])
        t_bake = time.perf_counter() - t0
        reports = [os.path.join(out, f"{place}_relight", f"{m}_texture_report.json")
                   for m in MESHES]
        sheet = os.path.join(out, f"{place}_sheet")
        t0 = time.perf_counter()
        relight(["sun-study", *reports, *where, "--dates", DATES, "--hours", "9,12,15",
                 "--camera", blend, "--camera-size", args.camera_size, "--check-samples",
                 args.check_samples, "--radiation", "--out", sheet, "--force"])
        t_sheet = time.perf_counter() - t0
        year = os.path.join(out, f"{place}_year")
        t0 = time.perf_counter()
        relight(["sun-study", *reports, *where, "--from", "2026-01-01", "--to", "2026-12-31",
                 "--step-minutes", "60", "--radiation", "--out", year, "--force"])
        t_year = time.perf_counter() - t0
        rep = json.load(open(os.path.join(sheet, "sun_study.json")))
        yrep = json.load(open(os.path.join(year, "sun_study.json")))
        check = rep["camera"]["check"]
        figures["places"][place] = {
            "bake_s": round(t_bake, 1), "sheet_s": round(t_sheet, 1),
            "year_s": round(t_year, 1),
            "directions": json.load(open(reports[0])).get("directions"),
            "camera_seconds": rep["camera"]["seconds"],
            "check": {k: check[k] for k in ("date", "clock", "elevation", "azimuth", "size",
                                            "cycles_samples", "rel_rmse_baked_pixels",
                                            "seconds")},
            "year_sun_up": yrep["instants"]["sun_up"],
            "year": {o["object"]: {"hours": {k: o["hours"].get(k) for k in
                                             ("mean_h", "max_h", "possible_h")},
                                   "radiation": {k: o.get("radiation", {}).get(k) for k in
                                                 ("mean_kwh_m2", "max_kwh_m2",
                                                  "horizontal_kwh_m2")},
                                   "nearest_baked_deg": o["nearest_baked_deg"]}
                     for o in yrep["objects"]}}
        print(json.dumps({place: figures["places"][place]}, indent=1), flush=True)
        viewport_picture(blend, year, os.path.join(out, f"{place}_year_viewport.png"),
                         place.capitalize())
        if args.pictures:
            os.makedirs(args.pictures, exist_ok=True)
            for src, dst in [(os.path.join(sheet, "camera_sheet.png"), "camera-sheet"),
                             (os.path.join(sheet, "camera_check.png"), "camera-check"),
                             (os.path.join(year, "Ground_sunlight_hours.png"), "year-hours"),
                             (os.path.join(year, "Ground_radiation.png"), "year-radiation"),
                             (os.path.join(out, f"{place}_year_viewport.png"),
                              "year-hours-viewport")]:
                shutil.copyfile(src, os.path.join(args.pictures,
                                                  f"sun-study-{place}-{dst}.png"))

    # the cost: the ground alone at --cost-size (direct light: what the maps read), the
    # year's maps on it, and one Cycles render of one hour from the camera, in this run
    lat, lon, tz = PLACES["london"]
    blend = os.path.join(out, "london.blend")
    if not os.path.exists(blend):
        build(blend)
    cost = os.path.join(out, "cost_relight")
    where = ["--lat", lat, "--lon", lon, "--tz", tz]
    t0 = time.perf_counter()
    relight(["bake-textures", blend, "--object", "Ground", "--resolution", args.cost_size,
             "--bounces", "0", "--out", cost, "--force"])
    t_bake = time.perf_counter() - t0
    report = os.path.join(cost, "Ground_texture_report.json")
    t0 = time.perf_counter()
    relight(["sun-study", report, *where, "--from", "2026-01-01", "--to", "2026-12-31",
             "--step-minutes", "60", "--radiation", "--out", os.path.join(out, "cost_year"),
             "--force"])
    t_year = time.perf_counter() - t0
    relight(["sun-study", report, *where, "--dates", "2026-06-21", "--hours", "15",
             "--camera", blend, "--camera-size", args.cost_size // 2, "--check-samples",
             args.check_samples, "--out", os.path.join(out, "cost_render"), "--force"])
    check = json.load(open(os.path.join(out, "cost_render", "sun_study.json")))["camera"][
        "check"]
    yrep = json.load(open(os.path.join(out, "cost_year", "sun_study.json")))
    render_s = check["seconds"]["cycles_render"]
    hours = yrep["instants"]["sun_up"]
    figures["cost"] = {"size": args.cost_size, "bake_s": round(t_bake, 1),
                       "year_maps_s": round(t_year, 1), "hours_of_sun": hours,
                       "one_cycles_render_s": render_s, "render": check["size"],
                       "render_samples": check["cycles_samples"],
                       "renders_replaced_s": round(hours * render_s, 0),
                       "ratio": round(hours * render_s / (t_bake + t_year), 1)}
    print(json.dumps({"cost": figures["cost"]}, indent=1))
    with open(os.path.join(out, "sun_study_cost.json" if args.cost_only
                           else "sun_study_places.json"), "w") as f:
        json.dump(figures, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
