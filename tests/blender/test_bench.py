"""`relight bench`: the sweep machinery on tiny real bakes, and the quick transport sweep via
the CLI (the texture scenes' quick sweep takes minutes: `make bench`)."""

import json

import numpy as np
import pytest
from relight_cli import assert_refused, relight


def test_peak_memory_sees_a_numpy_allocation():
    from relightable_textures.devtools.bench import peak_memory

    with peak_memory() as mem:
        a = np.ones(25_000_000)                        # 200 MB (190.7 MiB), touched
        a.sum()
    del a
    assert 180.0 <= mem["peak_rss_mb"] <= 260.0


def test_upsampling_is_nearest_texel_and_refuses_non_multiples():
    from relightable_textures.devtools.bench import _upsample

    img = np.arange(4.0).reshape(2, 2, 1)
    np.testing.assert_array_equal(_upsample(img, 4)[:, :, 0],
                                  [[0, 0, 1, 1], [0, 0, 1, 1], [2, 2, 3, 3], [2, 2, 3, 3]])
    with pytest.raises(ValueError, match="not a multiple"):
        _upsample(img, 5)


def _point(order, storage, seconds, err, nbytes):
    return {"order": order, "samples": 16, "resolution": 64, "storage": storage, "bounces": 2,
            "bake_seconds": seconds, "rel_rmse": err, "psnr_db": 20.0, "stored_bytes": nbytes,
            "preview_madds": 3 * order * order, "peak_rss_mb": 1.0}


def test_presets_come_from_the_front_and_store_in_the_smallest_precision_within_1_percent():
    from relightable_textures.devtools.bench import choose_texture_presets

    pts = []
    for order, seconds, err in ((3, 1.0, 0.30), (5, 3.0, 0.15), (7, 9.0, 0.12), (9, 30.0, 0.2)):
        pts += [_point(order, "float", seconds, err, 4000),
                _point(order, "half", seconds, err * 1.005, 2000),
                _point(order, "u8", seconds, err * 1.05, 1000)]
    chosen = choose_texture_presets(pts)
    assert [chosen[n]["settings"]["order"] for n in ("draft", "balanced", "production")] == \
        [3, 5, 7]                                      # order 9 is dominated
    assert {c["settings"]["storage"] for c in chosen.values()} == {"half"}
    assert chosen["production"]["figures"]["stored_bytes"] == 2000
    assert "stored as half" in chosen["production"]["why"]


def test_texture_sweep_measures_every_storage_against_one_reference(fresh_scene, tmp_path):
    """A 2-sample / 8-sample, 8^2 / 16^2 grid at order 2 on the tiny bumps patch: 4 bakes x 3
    precisions; the reference is at 16^2; more samples bring every point closer to it; float and
    half relight alike (< 1e-3 apart in error) and half costs fewer bytes than float. (u8 keeps 8-bit
codes in half channels plus per-channel ranges, so it only wins above tiny sizes.)"""
    from relightable_textures import samples
    from relightable_textures.devtools import bench

    info = samples.build("bumps", fresh_scene, "test")
    obj = fresh_scene.objects[info["relight_object"]]
    sweep = bench.TextureSweep("test", (2,), (2, 8), (8, 16), 1, 64)
    ref = bench.texture_reference(fresh_scene, obj, sweep)
    assert ref["resolution"] == 16 and len(ref["images"]) == len(bench.REFERENCE_LIGHTS)
    pts = bench.texture_points(fresh_scene, obj, sweep, ref, str(tmp_path))
    assert len(pts) == 4 * 3 and not list(tmp_path.iterdir())
    by = {(p["samples"], p["resolution"], p["storage"]): p for p in pts}
    for res in (8, 16):
        assert by[(8, res, "float")]["rel_rmse"] < by[(2, res, "float")]["rel_rmse"]
        assert abs(by[(8, res, "half")]["rel_rmse"] - by[(8, res, "float")]["rel_rmse"]) < 1e-3
        assert by[(8, res, "half")]["stored_bytes"] < by[(8, res, "float")]["stored_bytes"]
    assert all(p["preview_madds"] == 12 and p["bake_calls"] == 4 for p in pts)
    assert all(0 <= p["own_seconds"] <= p["bake_seconds"] for p in pts)


def test_quick_transport_bench_via_the_cli(tmp_path):
    # Slow on purpose (~23 s): the whole quick sweep -- Cycles bakes at cube:4, 8 and 16, every
    # model, the charts -- because the ordering of its points and the Pareto flags are the test.
    from matplotlib.image import imread
    from relightable_textures.devtools.pareto import read_csv

    r = relight("bench", "--quick", "--scene", "statue", "--out", tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "statue.json").read_text())
    pts = rep["points"]
    assert len(read_csv(tmp_path / "statue.csv")) == len(pts)
    # Pareto flags against a brute-force dominance check
    for axis, key in (("time", "bake_seconds"), ("bytes", "stored_bytes"),
                      ("preview", "preview_madds")):
        for p in pts:
            dominated = any(q[key] <= p[key] and q["rel_rmse"] <= p["rel_rmse"]
                            and (q[key] < p[key] or q["rel_rmse"] < p["rel_rmse"]) for q in pts)
            assert p[f"pareto_{axis}"] == (not dominated)
        assert imread(str(tmp_path / f"statue_error_vs_{axis}.png")).shape[:2] == (420, 640)
    full = {p["direction_set"]: p for p in pts
            if p["model"] == "eigentransport" and p["d"] == max(
                q.get("d", 0) for q in pts if q["direction_set"] == p["direction_set"])}
    # finer direction sampling approaches the Cycles environment bake
    assert full["cube:16"]["rel_rmse"] < full["cube:8"]["rel_rmse"] < full["cube:4"]["rel_rmse"]
    for spec in ("cube:4", "cube:8", "cube:16"):
        eig = [p for p in pts if p["direction_set"] == spec and p["model"] == "eigentransport"]
        assert min(eig, key=lambda p: p["d"])["rel_rmse"] >= full[spec]["rel_rmse"] - 1e-9
    assert "Pareto front" in r.stdout


def test_presets_only_from_the_standard_sweep(tmp_path):
    assert_refused(tmp_path, "--write-presets needs the standard", "bench", "--quick",
                   "--write-presets", "--out", tmp_path / "b")
    assert_refused(tmp_path, "add --scene bumps", "bench", "--scene", "room",
                   "--write-presets", "--out", tmp_path / "b")
