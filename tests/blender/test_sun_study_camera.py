"""The sun study's shadow-study sheet from the scene camera, and its cell against Cycles
(issue 58), end to end through the CLI: a courtyard .blend with a camera, baked with the
study's suns (``bake-textures --study``), then ``sun-study --camera``.

The check cell is the bake's direct sun on white surfaces next to Cycles' render of the same
hour (white diffuse override, direct light only, a Sun lamp of that direction). Measured here
(2026-12-06, bpy 5.0.1, the courtyard at 32^2, 48 directions plus the study's, the check at
128 px and 16 spp): 0.079 at 2026-06-21 15:00 (54 deg up), 0.129 at 2026-12-21 12:00 (15 deg);
the texels (25 cm) blur the shadow edges. With the texture read upside down (v flipped) the
same cell measured 0.544, so the bound of 0.12 tells a right sheet from a wrong one.
"""

from __future__ import annotations

import datetime
import json
import os
import sys

import numpy as np
import pytest

DATES = "2026-03-20,2026-06-21,2026-12-21"
STUDY = ["--lat", "51.5", "--lon", "-0.13", "--tz", "Europe/London", "--dates", DATES]


@pytest.fixture
def courtyard_blend(tmp_path):
    import bpy

    from test_sun_study import _courtyard

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    _courtyard(scene)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location, cam.rotation_euler = (10.0, -10.0, 9.0), (0.93, 0.0, 0.785)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 400, 300
    # settings of the user's that would corrupt the UV pass's numbers if it kept them
    scene.cycles.sample_clamp_direct, scene.cycles.film_exposure = 0.5, 2.0
    scene.render.use_border = True
    scene.render.border_max_x = 0.5
    path = str(tmp_path / "courtyard.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    return path


def test_the_camera_sheet_matches_cycles_at_its_check_cell(courtyard_blend, tmp_path, capsys):
    from relightable_textures.lt_addon.io.contact_sheet import read_png
    from relightable_textures.operators.cli.commands import run

    walls = ("Ground", "WallN", "WallW", "WallE")
    rc = run(["bake-textures", courtyard_blend, *[a for w in walls for a in ("--object", w)],
              "--directions", "hemi:48:1.5", "--resolution", "32", "--sun-path-step", "2",
              "--study", "51.5,-0.13,Europe/London," + DATES])
    assert rc == 0, capsys.readouterr().err     # (the one line says why, should CI see it)
    reports = [str(tmp_path / "courtyard_relight" / f"{w}_texture_report.json") for w in walls]
    mtime = os.path.getmtime(courtyard_blend)
    capsys.readouterr()
    out = tmp_path / "study"
    args = ["sun-study", *reports, *STUDY, "--hours", "9,12,15,21", "--camera",
            courtyard_blend, "--camera-size", "64", "--check-samples", "16", "--out", str(out)]

    # a check cell where the Sun is down: one line, exit 2, nothing written
    assert run(args + ["--check-cell", "2026-12-21,21:00"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("relight: error: --camera ") and "the Sun is down" in err
    assert err.count("\n") == 1 and not out.exists()

    assert run(args + ["--check-cell", "2026-06-21,15:00"]) == 0
    assert "vs Cycles: rel. RMSE" in capsys.readouterr().out
    rep = json.loads((out / "sun_study.json").read_text())
    cam = rep["camera"]
    assert cam["objects"] == list(walls) and cam["not_in_scene"] == []
    # 3 dates x 4 hours, a frame each (the sheet's order), 64 px on the longer side
    assert len(cam["frames"]) == 12 and cam["size"] == [64, 48]
    frames = [read_png(str(out / f)) for f in cam["frames"]]
    assert all(f.shape == (48, 64, 3) for f in frames)
    cells = rep["sheet"]["cells"]
    down = [i for i, c in enumerate(cells) if c["direction"] is None]
    assert [cells[i]["date"] + " " + cells[i]["clock"] for i in down] == \
        ["2026-03-20 21:00", "2026-12-21 21:00"]
    assert all(frames[i].max() == 0 for i in down)               # the Sun is down: black
    assert frames[1].mean() > 60 and not np.array_equal(frames[0], frames[2])  # shadows move
    assert read_png(str(out / "camera_sheet.png")).shape[1] >= 3 * 256
    check = cam["check"]
    assert (check["date"], check["clock"]) == ("2026-06-21", "15:00")
    assert check["size"] == [128, 96] and check["cycles_samples"] == 16
    assert check["rel_rmse_baked_pixels"] < 0.12, check
    assert read_png(str(out / "camera_check.png")).shape[1] >= 3 * 128
    assert os.path.getmtime(courtyard_blend) == mtime              # the .blend is not saved
    # the default check cell: the lowest Sun at least 5 degrees up (Dec 21, 15:00, 5.3 deg)
    assert run(args + ["--force", "--check-samples", "1"]) == 0
    check = json.loads((out / "sun_study.json").read_text())["camera"]["check"]
    assert (check["date"], check["clock"]) == ("2026-12-21", "15:00")


def test_the_study_takes_the_place_the_sun_position_add_on_holds(tmp_path, capsys):
    """A .blend whose scene holds Sun Position settings (stored under the add-on's own property
    names; the add-on is not enabled here): ``bake-textures --study scene,DATE`` and
    ``sun-study --place-from`` both take its place, zone and north; a file without them is one
    line, exit 2."""
    import math

    import bpy

    from relightable_textures.operators.base import sun_position
    from relightable_textures.operators.cli.commands import run
    from test_sun_study import _courtyard

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    _courtyard(bpy.context.scene)
    plain = str(tmp_path / "plain.blend")
    bpy.ops.wm.save_as_mainfile(filepath=plain)
    sun_position.write_for_tests(bpy.context.scene, latitude=-33.87, longitude=151.21,
                                 UTC_zone=10.0, use_daylight_savings=True,
                                 north_offset=math.radians(20.0))
    blend = str(tmp_path / "sydney.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    capsys.readouterr()

    bake = ["bake-textures", None, "--object", "Ground", "--directions", "hemi:16:1.5",
            "--resolution", "8", "--bounces", "0", "--study", "scene,2026-12-21",
            "--sun-path-step", "5"]
    bake[1] = plain
    assert run(bake) == 2
    err = capsys.readouterr().err
    assert err.startswith("relight: error: ") and "no Sun Position settings" in err
    bake[1] = blend
    assert run(bake) == 0
    rep = json.loads((tmp_path / "sydney_relight" / "Ground_texture_report.json").read_text())
    study = rep["direct"]["direction_set"]["study"]
    assert (study["latitude"], study["longitude"], study["tz"], study["north_deg"]) == \
        (-33.87, 151.21, "UTC+11:00", 20.0)
    assert study["place_from"] == "the scene's Sun Position add-on"
    # the same place by hand: the same directions
    assert run(["bake-textures", blend, "--object", "Ground", "--directions", "hemi:16:1.5",
                "--resolution", "8", "--bounces", "0", "--sun-path-step", "5", "--study",
                "-33.87,151.21,UTC+11:00,2026-12-21,north=20", "--out",
                str(tmp_path / "by_hand")]) == 0
    hand = json.loads((tmp_path / "by_hand" / "Ground_texture_report.json").read_text())
    assert hand["directions"] == rep["directions"]

    report = str(tmp_path / "sydney_relight" / "Ground_texture_report.json")
    out = tmp_path / "study"
    assert run(["sun-study", report, "--place-from", blend, "--dates", "2026-12-21",
                "--hours", "12", "--out", str(out)]) == 0
    inputs = json.loads((out / "sun_study.json").read_text())["inputs"]
    assert (inputs["latitude"], inputs["longitude"], inputs["tz"], inputs["north_deg"]) == \
        (-33.87, 151.21, "UTC+11:00", 20.0)
    capsys.readouterr()
    assert run(["sun-study", report, "--place-from", blend, "--lat", "1", "--dates",
                "2026-12-21", "--hours", "12", "--out", str(tmp_path / "x")]) == 2
    assert "drop --lat" in capsys.readouterr().err
    assert run(["sun-study", report, "--dates", "2026-12-21", "--hours", "12", "--out",
                str(tmp_path / "x")]) == 2
    assert "give --lat, --lon, --tz" in capsys.readouterr().err


def test_the_sunlight_hours_map_shows_on_the_objects_in_its_pictures_ramp(tmp_path, capsys):
    """*Show Sun Study Map* (the panel's operator) puts the study's hours map on the ground in
    the viridis ramp of its PNGs: a Cycles render of the preview from straight above, one pixel
    per texel centre, equals the ramp of the EXR's hours (linear interpolation of the ramp's
    stops, as Blender's Color Ramp does), dark grey where no texel; Remove Preview takes it
    out. A folder that is not a study is one line and nothing changes."""
    import bpy
    from render_check import render_rgb

    import relightable_textures
    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.sun import study_images
    from relightable_textures.operators.cli.commands import run
    from relightable_textures.operators.preview import preview_nodes as pn
    from relightable_textures.operators.preview import sun_study_preview as ssp
    from test_sun_study import _courtyard

    R = 16
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    _courtyard(bpy.context.scene)
    blend = str(tmp_path / "court.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    assert run(["bake-textures", blend, "--object", "Ground", "--directions", "hemi:48:1.5",
                "--resolution", str(R), "--bounces", "0", "--model", "none"]) == 0
    out = tmp_path / "study"
    assert run(["sun-study", str(tmp_path / "court_relight" / "Ground_texture_report.json"),
                *STUDY, "--hours", "9,12,15", "--out", str(out)]) == 0
    bpy.ops.wm.open_mainfile(filepath=blend)
    relightable_textures.register()
    try:
        scene = bpy.context.scene
        ground = bpy.data.objects["Ground"]
        props = scene.relight
        # Run Sun Study: the panel's own run of the same study (the place and dates of the
        # bake's Sun Study field) gives the CLI's map, and shows it
        with pytest.raises(RuntimeError, match="Run Sun Study: fill Sun Study"):
            bpy.ops.relight.run_sun_study()
        props.study = "51.5,-0.13,Europe/London," + DATES
        props.sun_study_hours, props.sun_study_radiation = "9,12,15", False
        for o in scene.objects:
            o.select_set(o == ground)
        assert bpy.ops.relight.run_sun_study() == {"FINISHED"}
        ran = props.sun_study_folder
        assert os.path.dirname(ran) == str(tmp_path / "court_relight")
        assert os.path.basename(ran).startswith("sun_study-")
        a, _ = exrio.read_exr(os.path.join(ran, "Ground_sunlight_hours.exr"))
        b, _ = exrio.read_exr(str(out / "Ground_sunlight_hours.exr"))
        assert np.array_equal(a["Y"], b["Y"]) and pn.preview_kinds(ground)[0] == ssp.KIND
        # a range in the field: the CLI's --from/--to/--every-days study
        props.study = "51.5,-0.13,Europe/London,2026-06-01..2026-06-30/7"
        assert bpy.ops.relight.run_sun_study() == {"FINISHED"}
        weekly = tmp_path / "weekly"
        assert run(["sun-study", str(tmp_path / "court_relight" / "Ground_texture_report.json"),
                    *STUDY[:6], "--from", "2026-06-01", "--to", "2026-06-30", "--every-days",
                    "7", "--hours", "9,12,15", "--out", str(weekly)]) == 0
        a, _ = exrio.read_exr(os.path.join(props.sun_study_folder, "Ground_sunlight_hours.exr"))
        b, _ = exrio.read_exr(str(weekly / "Ground_sunlight_hours.exr"))
        assert np.array_equal(a["Y"], b["Y"]) and a["Y"].max() == 15.0     # 5 dates x 3 h
        # a weather file (EPW): the panel's radiation from it equals the CLI's, whose place
        # comes from the file's LOCATION line when none is given
        sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..",
                                        "core"))
        from test_weather import ELEV, LAT, LON, write_epw   # tests/core: the EPW writer

        epw = write_epw(tmp_path / "w.epw", days=[datetime.date(2026, 6, d) for d in
                                                   (1, 8, 15, 22, 29)])
        props.study = f"{LAT},{LON},UTC,2026-06-01..2026-06-30/7,elevation={ELEV:g}"
        props.sun_study_weather, props.sun_study_map = str(epw), "radiation"
        assert bpy.ops.relight.run_sun_study() == {"FINISHED"}
        ssp_info = ssp.legend(scene)[1]
        assert ssp_info["unit"] == "kWh/m2"
        capsys.readouterr()
        assert run(["sun-study", str(tmp_path / "court_relight" / "Ground_texture_report.json"),
                    "--weather", str(epw), "--from", "2026-06-01", "--to", "2026-06-30",
                    "--every-days", "7", "--hours", "9,12,15", "--out",
                    str(tmp_path / "epw")]) == 0
        assert "the place of w.epw: Gatwick, 51.15, -0.18, UTC" in capsys.readouterr().out
        a, _ = exrio.read_exr(os.path.join(props.sun_study_folder, "Ground_radiation.exr"))
        b, meta = exrio.read_exr(str(tmp_path / "epw" / "Ground_radiation.exr"))
        assert np.array_equal(a["Y"], b["Y"]) and "w.epw" in meta["sky"]
        props.sun_study_weather, props.sun_study_map = "", "hours"
        bpy.context.view_layer.objects.active = ground
        assert bpy.ops.relight.remove_preview() == {"FINISHED"}
        props.sun_study_folder = str(tmp_path / "court_relight")     # a bake folder, no study
        with pytest.raises(RuntimeError, match="Sun study: .*sun_study.json"):
            bpy.ops.relight.show_sun_study()
        assert pn.preview_kinds(ground) == []
        props.sun_study_folder = str(out)
        assert bpy.ops.relight.show_sun_study() == {"FINISHED"}
        assert pn.preview_kinds(ground)[0] == ssp.KIND
        ramp, info = ssp.legend(scene)
        assert info["top"] == 9.0 and info["unit"] == "h" and len(ramp.color_ramp.elements) == 9

        cam = bpy.data.objects.new("Top", bpy.data.cameras.new("Top"))
        cam.data.type, cam.data.ortho_scale = "ORTHO", 8.0
        cam.location = (0.0, 0.0, 10.0)
        scene.collection.objects.link(cam)
        scene.camera = cam
        for o in scene.objects:         # the walls out of the way: the ground's texels only
            o.hide_render = o.type == "MESH" and o != ground
        img = render_rgb(scene, tmp_path, R)
        ch, _ = exrio.read_exr(str(out / "Ground_sunlight_hours.exr"))
        x = np.clip(ch["Y"] / 9.0, 0.0, 1.0)
        stops = ssp._srgb_to_linear(study_images.RAMP)
        t = x * (len(stops) - 1)
        i = np.minimum(np.floor(t).astype(int), len(stops) - 2)
        want = stops[i] + (stops[i + 1] - stops[i]) * (t - i)[..., None]
        want[ch["A"] < 0.5] = ssp._srgb_to_linear(study_images.UNCOVERED)
        assert x.min() < 0.5 < x.max()                 # shade and sun on the ground
        assert np.abs(img - want).max() < 2e-3, np.abs(img - want).max()
        bpy.context.view_layer.objects.active = ground
        assert bpy.ops.relight.remove_preview() == {"FINISHED"}
        assert pn.preview_kinds(ground) == [] and ssp.legend(scene) is None
    finally:
        relightable_textures.unregister()
