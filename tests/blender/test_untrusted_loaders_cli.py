"""The CLI on one real bake whose files were changed afterwards (issue 56): each command that
reads the bake stops with exit status 2 and one line ``relight: error: <file>: <cause>`` --
before, a T overwritten with finite garbage was relit to a mean of 3.06 (a good bake: ~0.12)
with exit 0, and an all-NaN T was exported with NaN in the export's files.

One bake (the test-size bumps at 16^2, 64 directions, draft preset: ~4 s), shared by the module;
each test restores the files it changed."""

import json
import pathlib
import shutil

import numpy as np
import pytest

from relight_cli import make_scene, our_lines, relight


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    root = tmp_path_factory.mktemp("untrusted")
    blend = make_scene("bumps", root / "bumps.blend")
    out = root / "bk"
    r = relight("bake-textures", blend, "--object", "Bumps", "--preset", "draft",
                "--directions", "hemi:64", "--resolution", "16", "--truth", "0",
                "--no-compare", "--seed", "1", "--out", out, "--force")
    assert r.returncode == 0, r.stderr[-3000:]
    report = out / "Bumps_texture_report.json"
    files = {k: out / pathlib.Path(v).name
             for k, v in json.loads(report.read_text())["files"].items()}
    return blend, out, report, files


@pytest.fixture
def restore(baked):
    """Keep a copy of the bake's files; put them back after the test."""
    _, out, _, _ = baked
    saved = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    yield
    for name, raw in saved.items():
        (out / name).write_bytes(raw)


def _one_error_line(r, path, cause):
    lines = our_lines(r.stderr)
    assert r.returncode == 2, (r.returncode, r.stdout[-500:], r.stderr[-2000:])
    errors = [ln for ln in lines if ln.startswith("relight: error:")]
    assert len(errors) == 1, lines
    assert str(path) in errors[0] and cause in errors[0], errors[0]
    assert "Traceback" not in r.stderr


def _relight_transport(blend):
    return relight("relight", blend, "--object", "Bumps", "--light", "30,45",
                   "--source", "transport")


def _t_data(path):
    """T's float16 values as a writable memory map (its NPY header kept)."""
    return np.load(path, mmap_mode="r+")


def test_the_good_bake_relights(baked):
    blend, _, _, _ = baked
    r = _relight_transport(blend)
    assert r.returncode == 0, r.stderr[-2000:]
    assert max(json.loads(r.stdout)["mean"]) < 1.0


def test_t_overwritten_with_finite_garbage_is_refused_naming_t(baked, restore):
    blend, _, report, files = baked
    T = _t_data(files["transport"])
    T[:] = np.random.default_rng(0).uniform(0, 60000, T.shape).astype(np.float16)
    T.flush()
    del T
    r = _relight_transport(blend)                      # the report's checksum tells
    _one_error_line(r, files["transport"], "does not match the checksum its report records")
    data = json.loads(report.read_text())              # a report from before checksums:
    del data["checksums"]                              # the range check tells
    report.write_text(json.dumps(data))
    r = _relight_transport(blend)
    _one_error_line(r, files["transport"], "transport values above")


def test_an_all_nan_t_is_not_exported(baked, restore, tmp_path):
    blend, _, report, files = baked
    T = _t_data(files["transport"])
    T[:] = np.nan
    T.flush()
    del T
    data = json.loads(report.read_text())
    del data["checksums"]
    report.write_text(json.dumps(data))
    r = relight("export", blend, "--object", "Bumps", "--format", "sh-l1", "--sun", "30,45",
                "--out", tmp_path / "exp")
    _one_error_line(r, files["transport"], "NaN")
    assert not (tmp_path / "exp").exists() or not any((tmp_path / "exp").iterdir())


@pytest.mark.parametrize("damage", ["not json", "truncated"])
def test_a_damaged_report_is_one_line_naming_it(baked, restore, damage):
    blend, _, report, _ = baked
    text = report.read_text()
    report.write_text("relight report?" if damage == "not json" else text[:len(text) // 3])
    r = _relight_transport(blend)
    _one_error_line(r, report, "is not valid JSON")
