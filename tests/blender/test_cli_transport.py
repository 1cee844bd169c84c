"""bake-transport / relight-vertices from the venv console script."""

import json
import os

import numpy as np
import pytest
from relight_cli import assert_refused, make_scene, relight




@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    folder = tmp_path_factory.mktemp("transport")
    blend = folder / "statue.blend"
    make_scene("statue", blend)
    r = relight("bake-transport", blend, "--object", "Statue", "--directions", "cube:4",
                "--coeffs", "12", "--truth")
    assert r.returncode == 0, r.stderr[-2000:]
    return folder, blend, r


def test_bake_transport_writes_sidecar_report_and_record(baked):
    folder, blend, r = baked
    out = folder / "statue_relight"
    assert sorted(os.listdir(out)) == ["Statue_transport.json", "Statue_transport.npz",
                                       "Statue_transport_samples.npy"]
    rep = json.loads((out / "Statue_transport.json").read_text())
    assert rep["vertices"] == 507 and rep["directions"] == 96 and rep["d"] == 12
    t = rep["timings"]   # the wall time covers the fit and the truth bake too
    assert t["wall_total"] >= t["total_bake_seconds"] + t["fit_seconds"]
    assert f"{t['wall_total']:.2f} s in all" in r.stdout
    assert rep["timings"]["directions_per_second"] > 0
    # by rays (the default), and the line says how close Cycles' check came
    d = rep["direct"]
    assert d["engine"] == "rays" and d["checked_directions"] == 8
    assert (f"direct light by rays ({d['library']}, {d['ray_seconds']:.2f} s); Cycles' bake of "
            f"8 of its directions: relative difference {d['vs_cycles']['rel_difference']:.2g}"
            in r.stdout)
    assert "workers_unused" not in d and "warning" not in r.stderr
    assert rep["bytes"]["paper_runtime"] == 4 * 12 * (507 + 1)
    per_d = rep["ground_truth"]["per_d"]
    assert per_d[-1]["d"] == 12 and per_d[-1]["rel_rms_error"] < per_d[0]["rel_rms_error"]
    listing = json.loads(relight("info", blend, "--json").stdout)
    (statue,) = [o for o in listing["objects"] if o["name"] == "Statue"]
    assert statue["bakes"][0]["kind"] == "eigentransport"
    assert statue["bakes"][0]["path"] == "//statue_relight/Statue_transport.npz"


def test_relight_vertices_rotation_and_point_light(baked, tmp_path):
    folder, blend, _ = baked
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    assert relight("relight-vertices", blend, "--object", "Statue", "--out", a).returncode == 0
    r = relight("relight-vertices", blend, "--object", "Statue", "--rotate", "360", "--out", b)
    assert r.returncode == 0, r.stderr
    # a full turn changes nothing
    np.testing.assert_allclose(np.load(b), np.load(a), rtol=1e-5, atol=1e-7)
    assert np.load(a).shape == (507, 3)
    inside = tmp_path / "inside.npy"
    r = relight("relight-vertices", blend, "--object", "Statue", "--point-light", "0,0,1,100",
                "--out", inside)
    assert r.returncode == 0 and "inside the convex hull" in r.stderr.lower()
    r = relight("relight-vertices", blend, "--object", "Statue", "--point-light", "0,-6,4,100",
                "--out", tmp_path / "outside.npy")
    assert r.returncode == 0 and "convex hull" not in r.stderr.lower()


def test_cpca_bakes_shade_like_the_full_eigentransport(tmp_path):
    """--clusters 3 --energy 1.0 (every cluster at full rank) and the unclustered --energy 1.0
    are two exact models of the same deterministic bake: relight-vertices must agree to float32
    round-off. --clusters auto records its subdivision tree and Mahajan's cost."""
    blend = tmp_path / "statue.blend"
    make_scene("statue", blend)
    common = ("--object", "Statue", "--directions", "cube:4")
    out = {}
    for name, extra in (("pca", ()), ("cpca", ("--clusters", "3"))):
        r = relight("bake-transport", blend, *common, "--energy", "1.0", *extra,
                    "--out", tmp_path / name)
        assert r.returncode == 0, r.stderr[-2000:]
        out[name] = tmp_path / f"{name}.npy"
        r = relight("relight-vertices", blend, "--object", "Statue", "--out", out[name])
        assert r.returncode == 0, r.stderr[-2000:]
    a, b = np.load(out["pca"]), np.load(out["cpca"])
    np.testing.assert_allclose(b, a, rtol=0, atol=2e-5 * np.abs(a).max())
    rep = json.loads((tmp_path / "cpca" / "Statue_transport.json").read_text())
    assert rep["model"] == "cpca" and rep["cpca"]["clusters"] == 3
    assert rep["relative_rms_error"] < 1e-6
    r = relight("bake-transport", blend, *common, "--energy", "0.999", "--clusters", "auto",
                "--out", tmp_path / "auto")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "CPCA" in r.stdout and "multiply-adds per vertex" in r.stdout
    rep = json.loads((tmp_path / "auto" / "Statue_transport.json").read_text())
    fit = rep["cpca"]["fit"]
    assert fit["adaptive"] and fit["cost"] <= fit["initial_cost"]
    assert rep["cpca"]["clusters"] == fit["n_clusters"] >= fit["start_clusters"]
    assert rep["relative_rms_error"] <= np.sqrt(1e-3) + 1e-9


@pytest.mark.parametrize("args, message", [
    (("bake-transport", "{blend}", "--object", "Statue", "--clusters", "0"), "positive integer"),
    (("bake-transport", "{blend}", "--object", "Statue", "--clusters", "many"),
     "positive integer"),
    (("bake-transport", "{blend}", "--object", "Statue", "--clusters", "100000"),
     "exceeds Statue's 507 vertices"),
    (("bake-transport", "{blend}", "--object", "Statue", "--clusters", "auto", "--coeffs", "3"),
     "use --energy instead"),
    (("bake-transport", "{blend}", "--object", "Statue", "--directions", "sphere:9"), "direction"),
    (("bake-transport", "{blend}", "--object", "Statue", "--energy", "1.5"), "--energy"),
    (("bake-transport", "{blend}", "--object", "Camera"), "not a mesh"),
    (("relight-vertices", "{blend}", "--object", "Statue", "--out", "{tmp}/s.npy"),
     "no eigentransport bake"),
    (("relight-vertices", "{blend}", "--object", "Statue", "--env", "{tmp}/none.exr",
      "--out", "{tmp}/s.npy"), "not found"),
    (("relight-vertices", "{blend}", "--object", "Statue", "--env", "{blend}",
      "--out", "{tmp}/s.npy"), "not a readable OpenEXR image"),   # was a traceback
    (("relight-vertices", "{blend}", "--object", "Statue", "--point-light", "1,2,3",
      "--out", "{tmp}/s.npy"), "X,Y,Z,POWER"),
])
def test_bad_transport_input_exit_2(tmp_path, args, message):
    blend = tmp_path / "s.blend"
    make_scene("statue", blend)
    assert_refused(tmp_path, message, *[x.format(blend=blend, tmp=tmp_path) for x in args])


def test_bake_verbs_refuse_to_replace_a_bake_without_force(tmp_path):
    """bake-transport and the lobes bake-textures refuse an existing bake of the same object in
    --out (one line, exit 2, nothing changed) before any work; --force replaces it. Slow on
    purpose (~12 s): 8 runs of the real console script, ~1.3 s of Blender start-up each."""
    blend = tmp_path / "statue.blend"
    make_scene("statue", blend)
    runs = [("bake-transport", blend, "--object", "Statue", "--directions", "cube:2",
             "--out", tmp_path / "t"),
            ("bake-textures", blend, "--object", "Statue", "--method", "lobes", "--order", "2",
             "--resolution", "8", "--samples", "2", "--out", tmp_path / "l")]
    for args in runs:
        r = relight(*args)
        assert r.returncode == 0, r.stderr[-2000:]
        out = args[-1]
        assert_refused(out, "exists", *args)
        assert_refused(tmp_path, "--force", *args)   # the .blend is not touched either
        r = relight(*args, "--force")
        assert r.returncode == 0, r.stderr[-2000:]
