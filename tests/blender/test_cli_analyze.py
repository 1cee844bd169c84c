"""`relight analyze`: Mahajan's cluster analysis of a real Cycles transport bake, via the CLI."""

import hashlib
import json

import numpy as np
import pytest
from relight_cli import assert_refused, make_scene, relight


@pytest.fixture(scope="module")
def analyzed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("analyze")
    blend = folder / "statue.blend"
    make_scene("statue", blend)
    before = hashlib.sha256(blend.read_bytes()).hexdigest()
    r = relight("analyze", blend, "--object", "Statue", "--directions", "cube:8", "--seeds", "4",
                "--out", folder / "an")
    assert r.returncode == 0, r.stderr[-2000:]
    return folder, blend, before, r


def test_analyze_writes_json_and_charts_and_leaves_the_blend_alone(analyzed):
    from matplotlib.image import imread

    folder, blend, before, r = analyzed
    assert hashlib.sha256(blend.read_bytes()).hexdigest() == before
    assert sorted(p.name for p in (folder / "an").iterdir()) == [
        "Statue_analysis.json", "Statue_cost.png", "Statue_dimensionality.png"]
    # running it again into the same folder is refused up front (exit 2, one line, nothing
    # changed); --force would replace it
    assert_refused(folder / "an", "use --force", "analyze", blend, "--object", "Statue",
                   "--directions", "cube:8", "--seeds", "4", "--out", folder / "an")
    rep = json.loads((folder / "an" / "Statue_analysis.json").read_text())
    assert rep["vertices"] == 507 and rep["samples"] == 384
    dim = rep["dimensionality"]
    # a cast-shadow statue: between the paper's step-edge (0.4-0.6) and convex (>= 0.8) slopes
    assert 0.4 <= dim["slope"] <= 1.0
    assert dim["mu"] == pytest.approx(2.0 ** -dim["slope"])
    assert dim["p_star"] == pytest.approx(rep["N"] * (2 * dim["mu"] - 1) / (1 - dim["mu"]))
    assert rep["predicted_clusters"] == round(507 / dim["p_star"])
    costs = [row["cost_per_vertex"] for row in rep["cost_curve"]]
    assert rep["optimum"]["cost_per_vertex"] == min(costs) < rep["global_pca"]["cost_per_vertex"]
    assert rep["adaptive"]["cost_per_vertex"] < rep["global_pca"]["cost_per_vertex"]
    assert rep["auto"]["start_clusters"] == max(8, rep["predicted_clusters"])
    assert rep["auto"]["cost_per_vertex"] < rep["global_pca"]["cost_per_vertex"]
    for name in ("Statue_cost.png", "Statue_dimensionality.png"):
        img = imread(str(folder / "an" / name))[..., :3]   # matplotlib: floats in 0..1
        assert img.shape == (420, 640, 3)
        assert 0.02 < np.mean(img.min(axis=2) < 200 / 255) < 0.5   # drawn, not blank, not a mess
    assert "predicted" in r.stdout and "adaptive" in r.stdout


def test_analysis_cost_agrees_with_a_one_cluster_cpca_bake(analyzed, tmp_path):
    """The analysis' one-cluster cost (its global PCA) against the cost recomputed from the
    sidecar of `bake-transport --clusters 1` of the same object and directions."""
    from relightable_textures.lt_addon.transport.cpca import model_from_arrays

    folder, blend, _, _ = analyzed
    rep = json.loads((folder / "an" / "Statue_analysis.json").read_text())
    r = relight("bake-transport", blend, "--object", "Statue", "--directions", "cube:8",
                "--energy", "0.999", "--clusters", "1", "--out", tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    with np.load(tmp_path / "Statue_transport.npz") as z:
        model = model_from_arrays(z)
    n = model.dims()[0]
    assert model.N == rep["N"]
    assert rep["global_pca"]["cost_per_vertex"] == pytest.approx(n * (507 + rep["N"]) / 507,
                                                                 rel=1e-9)
    # the bake kept its samples: analyze now reuses them instead of baking 384 directions again,
    # and finds what the fresh bake found (exact 1-sample bakes; half-float rounding only)
    r = relight("analyze", blend, "--object", "Statue", "--directions", "cube:8", "--seeds", "4",
                "--out", tmp_path / "again")
    assert r.returncode == 0, r.stderr[-2000:]
    again = json.loads((tmp_path / "again" / "Statue_analysis.json").read_text())
    assert again["transport_source"] == {"kind": "reused",
                                         "file": str(tmp_path / "Statue_transport_samples.npy"),
                                         "why": "same directions and bounces"}
    assert again["timings"]["bake_seconds"] == 0.0 and "reused" in r.stdout
    assert again["N"] == rep["N"] and again["optimum"]["clusters"] == rep["optimum"]["clusters"]
    assert again["dimensionality"]["slope"] == pytest.approx(rep["dimensionality"]["slope"],
                                                             abs=0.02)
    # --rebake bakes anyway
    r = relight("analyze", blend, "--object", "Statue", "--directions", "cube:8", "--seeds", "4",
                "--rebake", "--out", tmp_path / "rebaked")
    assert r.returncode == 0, r.stderr[-2000:]
    rebaked = json.loads((tmp_path / "rebaked" / "Statue_analysis.json").read_text())
    # ... by rays, as the vertex bake does
    assert rebaked["transport_source"] == {"kind": "baked", "why": "--rebake", "direct": "rays"}


@pytest.mark.parametrize("args, message", [
    (("--tol", "2"), "--tol must be in [0, 1]"),
    (("--seeds", "0"), "--seeds must be >= 1"),
    (("--directions", "ring:3"), "direction"),
])
def test_bad_analyze_input_exit_2(tmp_path, args, message):
    blend = tmp_path / "s.blend"
    make_scene("statue", blend)
    assert_refused(tmp_path, message, "analyze", blend, "--object", "Statue", *args)
