"""The venv CLI: real console script and ``python -m`` in subprocesses, real .blend files."""

import json
import os
import subprocess
import sys

import pytest
from relight_cli import BIN, assert_refused, our_lines, relight




def test_help_from_console_script_and_module():
    a = relight("--help")
    b = subprocess.run([sys.executable, "-m", "relightable_textures", "--help"],
                       capture_output=True, text=True, timeout=120)
    assert a.returncode == 0 and b.returncode == 0
    for verb in ("scene", "info", "validate"):
        assert verb in a.stdout
    assert a.stdout.replace("relightable_textures", "relight") == b.stdout.replace(
        "relightable_textures", "relight")


def test_scene_then_info_round_trip(tmp_path):
    out = tmp_path / "x.blend"
    r = relight("scene", "bumps", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "1089 vertices" in r.stdout
    r = relight("info", out, "--json")
    assert r.returncode == 0, r.stderr
    listing = json.loads(r.stdout)  # stdout carries only JSON (Blender's log goes to stderr)
    assert listing["sample"] == "bumps" and listing["sample_size"] == "test"
    (bumps,) = [o for o in listing["objects"] if o["name"] == "Bumps"]
    assert bumps["vertices"] == 1089 and bumps["faces"] == 1024
    assert bumps["uv_maps"] == ["UVMap"] and bumps["bakes"] == []
    text = relight("info", out)
    assert "Bumps: 1089 vertices" in text.stdout and "no relightable data" in text.stdout
    assert sorted(os.listdir(tmp_path)) == ["x.blend"]  # no temporaries or .blend1 left


def test_force_overwrites_atomically(tmp_path):
    out = tmp_path / "x.blend"
    assert relight("scene", "bumps", "--out", out).returncode == 0
    before = out.read_bytes()
    r = relight("scene", "statue", "--out", out)
    assert r.returncode == 2 and out.read_bytes() == before  # refused, untouched
    r = relight("scene", "statue", "--out", out, "--force")
    assert r.returncode == 0, r.stderr
    assert json.loads(relight("info", out, "--json").stdout)["sample"] == "statue"
    assert sorted(os.listdir(tmp_path)) == ["x.blend"]


@pytest.mark.version_sensitive
def test_json_stdout_stays_clean_when_blender_logs(tmp_path):
    """With ``$OCIO`` set (studios set it for ACES; bpy 5.2 sets it for its child processes)
    Blender logs ``color_management | Using OCIO=...`` (5.3: ``Using config from OCIO: ...``) to
    file descriptor 1 on 5.0 to 5.3: the
    CLI moves that descriptor to stderr, so ``--json`` stdout still parses and an error is
    still the last line of stderr."""
    import bpy

    ocio = os.path.join(bpy.utils.resource_path("LOCAL"), "datafiles", "colormanagement",
                        "config.ocio")
    assert os.path.isfile(ocio)
    env = dict(os.environ, OCIO=ocio)
    out = tmp_path / "x.blend"
    assert relight("scene", "bumps", "--out", out).returncode == 0
    r = subprocess.run([str(BIN / "relight"), "info", str(out), "--json"], capture_output=True,
                       text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["sample"] == "bumps"
    assert "color_management |" in r.stderr        # Blender did log: the test can fail
    r = subprocess.run([str(BIN / "relight"), "info", str(tmp_path / "nothere.blend")],
                       capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 2 and r.stdout == ""
    assert our_lines(r.stderr) == [f"relight: error: input file not found: "
                                   f"{tmp_path / 'nothere.blend'}"], r.stderr


@pytest.mark.parametrize("args, message", [
    (("scene", "castle", "--out", "{tmp}/a.blend"), "unknown scene 'castle'"),
    (("scene", "bumps", "--out", "{tmp}/missing-dir/a.blend"), "output directory does not exist"),
    (("scene", "bumps", "--out", "/proc/a.blend"), "not writable"),
    (("scene", "bumps", "--out", "{tmp}/a.txt"), "output must end in .blend"),
    (("scene", "bumps", "--out", "{tmp}/a.blend", "--size", "huge"), "invalid choice"),
    (("info", "{tmp}/nothere.blend"), "input file not found"),
    (("info", "{tmp}/notes.txt"), "must be a .blend file"),
    (("info", "{tmp}/fake.blend"), "not a Blender file"),
    (("info", "{tmp}"), "is a directory"),
    (("bogus",), "invalid choice"),
])
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, args, message):
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "fake.blend").write_text("not a blend file")
    r = assert_refused(tmp_path, message, *[a.format(tmp=tmp_path) for a in args])
    assert len(our_lines(r.stderr)) == 1, r.stderr  # no traceback, no other output


def test_existing_output_without_force_is_refused(tmp_path):
    out = tmp_path / "a.blend"
    out.write_bytes(b"BLENDER-user-data")
    r = relight("scene", "room", "--out", out)
    assert r.returncode == 2 and "use --force" in r.stderr
    assert out.read_bytes() == b"BLENDER-user-data"


@pytest.mark.parametrize("paper, key", [("ashikhmin2002", "w"), ("mahajan2007", "slope_step_shadow")])
def test_validate_prints_the_reproduced_figures_and_exits_0(paper, key):
    r = relight("validate", "--paper", paper)
    assert r.returncode == 0, r.stderr[-2000:]
    report = json.loads(r.stdout)
    assert report[key]["ok"] and all(entry["ok"] for entry in report.values())
