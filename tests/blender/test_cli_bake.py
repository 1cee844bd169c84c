"""bake-textures / relight / light-env from the venv console script, on real .blend files."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from relight_cli import assert_refused, make_scene, relight

from relightable_textures.lt_addon.io import exrio

TINY = ["--method", "lobes", "--resolution", "16", "--samples", "4", "--order", "3",
        "--bounces", "0"]



@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bake")
    blend = folder / "bumps.blend"
    make_scene("bumps", blend)
    t0 = time.perf_counter()
    r = relight("bake-textures", blend, "--object", "Bumps", *TINY, "--truth", "2")
    r.stopwatch = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr[-2000:]
    return folder, blend, r


def test_bake_writes_exr_report_atlas_and_records_a_relative_path(baked):
    folder, blend, r = baked
    out = folder / "bumps_relight"
    assert sorted(os.listdir(out)) == ["Bumps_steerable.exr", "Bumps_steerable.json",
                                       "Bumps_steerable_atlas.exr",
                                       "Bumps_steerable_compare.png"]
    assert "[9/10]" in r.stderr  # progress: 9 bakes + the solve
    report = json.loads((out / "Bumps_steerable.json").read_text())
    t = report["timings"]
    assert t["bake_calls"] == 9 and 0 < t["cycles_bake_seconds"] <= t["total_seconds"]
    # the wall time covers everything the verb did, truth bakes included, and a stopwatch
    # around the process (Python and bpy start-up on top) is never shorter
    assert t["wall_total"] >= t["total_seconds"] + t["truth_seconds"] + t["compare_seconds"]
    assert t["truth_seconds"] > 0 and t["compare_seconds"] > 0
    assert report["comparison"]["png"] == str(out / "Bumps_steerable_compare.png")
    assert f"camera comparison {t['compare_seconds']:.2f} s" in r.stdout
    assert r.stopwatch >= t["wall_total"]
    assert f"{t['wall_total']:.2f} s in all" in r.stdout
    assert report["bytes"]["exr_file"] == os.path.getsize(out / "Bumps_steerable.exr")
    assert len(report["ground_truth"]["directions"]) == 2
    for row in report["ground_truth"]["directions"]:
        assert set(row["errors"]) == {"same_light", "same_light_4x", "sun"}
    # one headline, recomputed here from the per-light figures, and said on stdout
    gt = report["ground_truth"]
    rel = [row["errors"]["sun"]["rel_fro"] for row in gt["directions"]]
    assert gt["headline_of"] == "sun"
    assert gt["headline_rel_rmse"] == pytest.approx(np.sqrt(np.mean(np.square(rel))), rel=1e-12)
    assert "held-out light directions" in gt["headline_meaning"]
    assert f"error: {gt['headline_rel_rmse']:.3f} (relative RMSE" in r.stdout
    _, meta = exrio.read_exr(str(out / "Bumps_steerable.exr"))
    for key in ("order", "w", "a", "frame", "centres", "calibration", "resolution", "settings"):
        assert key in meta
    assert meta["settings"]["samples"] == 4 and meta["settings"]["seed"] == 0
    assert meta["settings"]["addon_version"] and meta["settings"]["bounces"] == 0
    listing = json.loads(relight("info", blend, "--json").stdout)
    (bumps,) = [o for o in listing["objects"] if o["name"] == "Bumps"]
    (rec,) = bumps["bakes"]
    assert rec["kind"] == "steerable_texture" and rec["path"] == "//bumps_relight/Bumps_steerable.exr"


def test_preview_survives_save_and_reopen(baked, tmp_path):
    """The saved .blend references the atlas by a relative path; reopened, the image loads."""
    folder, blend, _ = baked
    script = (
        "import bpy, sys; bpy.ops.wm.open_mainfile(filepath=sys.argv[1]);"
        "img=[i for i in bpy.data.images if i.get('relight_preview')][0];"
        "print('PATH', img.filepath, img.size[0], img.size[1], img.has_data or img.pixels[0] >= -1e30);"
        "m=bpy.data.objects['Bumps'].active_material.node_tree;"
        "print('GROUP', any(n.bl_idname=='ShaderNodeGroup' for n in m.nodes))")
    r = subprocess.run([sys.executable, "-c", script, str(blend)], capture_output=True,
                       text=True, timeout=300)
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("PATH")][0]
    assert line.split()[1] == "//bumps_relight/Bumps_steerable_atlas.exr"
    assert int(line.split()[2]) > 16 and line.split()[4] == "True"
    assert "GROUP True" in r.stdout


def test_relight_and_light_env_write_float_exrs(baked, tmp_path):
    from relightable_textures.lt_addon.steerable.calibration import make_calibration
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el, hemisphere_to_disk
    from relightable_textures.lt_addon.steerable.basis import environment_image, paper_basis

    folder, blend, _ = baked
    out = tmp_path / "relit.exr"
    r = relight("relight", blend, "--object", "Bumps", "--light", "30,40", "--out", out)
    assert r.returncode == 0, r.stderr
    ch, meta = exrio.read_exr(str(out))
    assert ch["R"].shape == (16, 16) and meta["light_elevation"] == 40.0
    assert json.loads(r.stdout)["mean"][0] == pytest.approx(float(ch["R"].mean()), rel=1e-5)

    env_path = tmp_path / "env.exr"
    r = relight("light-env", "--order", "5", "--light", "30,40", "--height", "32", "--out", env_path)
    assert r.returncode == 0, r.stderr
    ch, meta = exrio.read_exr(str(env_path))
    d = direction_from_az_el(30.0, 40.0)
    basis = paper_basis(5)
    gain, _ = make_calibration(basis).gain_offset(d)
    want = environment_image(basis, hemisphere_to_disk(d), 32, 64, row_order="bottom_first",
                             dtype=np.float64) * gain
    np.testing.assert_allclose(ch["G"], want, rtol=1e-6, atol=1e-7)
    # the brightest texel points at the light: column of azimuth 30 deg, row of elevation 40 deg
    row, col = np.unravel_index(np.argmax(ch["R"]), ch["R"].shape)
    assert abs((row + 0.5) / 32 * 180 - 90 - 40) < 180 / 32 * 1.5
    assert abs((0.5 - (col + 0.5) / 64) * 360 - 30) < 360 / 64 * 1.5


@pytest.mark.parametrize("args, message", [
    (("bake-textures", "{blend}", "--object", "Nope"), "no object 'Nope'"),
    (("bake-textures", "{blend}", "--object", "Sun"), "not a mesh"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--method", "lobes", "--order", "20"),
     "order must be in 2..12"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--method", "lobes", "--resolution", "0"),
     "resolution must be in 1..16384"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--resolution", "0"),
     "resolution must be in 4..8192"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--method", "lobes", "--samples", "0"),
     "samples must be >= 1"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--samples", "4"),
     "--samples apply to --method lobes"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--directions", "hemi:4"),
     "at least 8 upper-hemisphere directions"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--directions", "fib:40"),
     "bad direction spec"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--sun-angle", "45"),
     "sun angle must be in 0..30"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--object", "Nope"), "no object 'Nope'"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--target-error", "2"),
     "--target-error must be in (0, 1)"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--method", "lobes", "--object",
      "Bumps2"), "--method lobes bakes one object"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--bounces", "65"),
     "bounces must be in 0..64"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--out", "/proc/x"), "not writable"),
    (("bake-textures", "{blend}", "--object", "Bumps", "--preset", "ultra"), "invalid choice"),
    (("relight", "{blend}", "--object", "Bumps", "--light", "30"), "expected AZ,EL"),
    (("relight", "{blend}", "--object", "Bumps", "--light", "30,95"), "elevation must be"),
    (("relight", "{blend}", "--object", "Bumps", "--light", "30,40"), "no steerable texture"),
    (("light-env", "--light", "0,45", "--out", "{tmp}/env.png"), "must end in .exr"),
])
def test_bad_bake_input_exit_2_and_nothing_changes(tmp_path, args, message):
    blend = tmp_path / "b.blend"
    make_scene("bumps", blend)
    assert_refused(tmp_path, message, *[a.format(blend=blend, tmp=tmp_path) for a in args])
