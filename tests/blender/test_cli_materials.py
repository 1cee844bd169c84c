"""bake-materials / relight-materials from the venv console script: files, report, the
record in the .blend, the NumPy relight of an edit, and one clear line for bad input."""

import json

import numpy as np
import pytest
from relight_cli import folder_state, make_scene, our_lines, relight

OBJECTS = ("Floor", "WallLeft", "WallRight", "WallBack", "Box")


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    folder = tmp_path_factory.mktemp("materials")
    blend = folder / "room.blend"
    make_scene("room", blend)
    args = ["bake-materials", blend]
    for name in OBJECTS:
        args += ["--object", name]
    args += ["--region", "RedMaterial", "--region", "GreenMaterial", "--directions", "hemi:16",
             "--truth", "--truth-samples", "64"]
    r = relight(*args)
    assert r.returncode == 0, r.stderr[-2000:]
    return folder, blend, r, args


def test_bake_writes_tensors_report_and_record(baked):
    folder, blend, r, _ = baked
    out = folder / "room_relight"
    assert sorted(p.name for p in out.iterdir()) == ["Floor_materials.json",
                                                     "Floor_materials.npz"]
    rep = json.loads((out / "Floor_materials.json").read_text())
    assert rep["vertices"] == 350 and rep["regions"] == ["RedMaterial", "GreenMaterial"]
    # the direct light and the bounces by rays (the default): Cycles bakes only its check of
    # the direct light, 8 of the 16 directions, which the rays equal (one corner where two
    # walls' edges meet may differ: the intersection's tie-break)
    assert rep["bake_calls"] == 8 and rep["bounce_bake"] == "rays" and rep["samples"] is None
    d = rep["direct"]
    assert d["engine"] == "rays" and d["checked_directions"] == 8 and d["rays"] > 0
    assert d["vs_cycles"]["values_apart"] <= 1 / 350   # measured: 2 of 2,800 values
    assert "direct light by rays (embreex" in r.stdout
    assert rep["timings"]["direct_seconds"] > 0 and rep["timings"]["direct_check_seconds"] > 0
    g = rep["gather"]
    assert g["rays_per_origin"] == rep["rays"] == 512 and g["origins"] >= 350
    assert rep["timings"]["bounce_rays_seconds"] > 0
    shares = rep["energy_shares"]
    assert sum(shares.values()) == pytest.approx(1.0, abs=1e-4)
    assert 0.5 < shares["direct"] < 1.0 and shares["two_bounce"] > 0
    gt = rep["ground_truth"]
    assert gt["noise_floor"] > 0 and gt["rel_error"] > 0 and gt["samples"] == 64
    # measured: 0.8x the two truth seeds' difference at 64 spp (their noise dominates)
    assert gt["rel_error"] < 1.5 * gt["noise_floor"], gt
    assert rep["timings"]["wall_total"] >= rep["timings"]["bake_seconds"]
    assert f"{rep['bake_calls']} Cycles bakes + 512 rays from each of {g['origins']} points" \
        in r.stdout
    listing = json.loads(relight("info", blend, "--json").stdout)
    (floor,) = [o for o in listing["objects"] if o["name"] == "Floor"]
    assert floor["bakes"][0]["kind"] == "material_tensors"
    assert floor["bakes"][0]["path"] == "//room_relight/Floor_materials.npz"


def test_relight_materials_applies_the_edit(baked, tmp_path):
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import ptt

    folder, blend, _, _ = baked
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    r = relight("relight-materials", blend, "--object", "Floor", "--sun", "30,50", "--out", a)
    assert r.returncode == 0, r.stderr
    r = relight("relight-materials", blend, "--object", "Floor", "--sun", "30,50",
                "--set", "RedMaterial.color=0.1,0.1,0.9", "--out", b)
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["edits"]["RedMaterial"] == pytest.approx([0.1, 0.1, 0.9])
    assert info["direct"] == "rays"
    t = ptt.TransferTensors.load(str(folder / "room_relight" / "Floor_materials.npz"))
    sun = ptt.Sun(tuple(direction_from_az_el(30, 50)))
    import bpy

    from relightable_textures.operators.base.direct_rays import exact_direct

    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    exact = exact_direct(bpy.context.scene, t, sun)      # a shadow ray per vertex
    np.testing.assert_allclose(np.load(a), t.shade(sun, {}, direct=exact), rtol=1e-6)
    np.testing.assert_allclose(np.load(b), t.shade(sun, {"RedMaterial": (0.1, 0.1, 0.9)},
                                                   direct=exact), rtol=1e-6)
    # --direct baked: the bake's directions blended, as before the rays
    r = relight("relight-materials", blend, "--object", "Floor", "--sun", "30,50", "--direct",
                "baked", "--out", tmp_path / "d.npy")
    assert r.returncode == 0 and json.loads(r.stdout)["direct"] == "baked"
    np.testing.assert_allclose(np.load(tmp_path / "d.npy"), t.shade(sun, {}), rtol=1e-6)
    # without --sun / --env: the scene's Sun lamp
    r = relight("relight-materials", blend, "--object", "Floor", "--out", tmp_path / "c.npy")
    assert r.returncode == 0 and json.loads(r.stdout)["sun"] == "the scene's Sun lamp"


@pytest.mark.parametrize("extra, message", [
    (["--set", "Nope.color=1,1,1"], "'Nope' is not an editable region of this bake"),
    (["--set", "RedMaterial.roughness=0.5"], "has only the diffuse anchor"),
    (["--set", "RedMaterial.metallic=2"], "must be in 0..1"),
    (["--set", "RedMaterial.color=1,1"], "expected R,G,B"),
    (["--sun", "30,95"], "elevation must be in [-90, 90]"),
])
def test_relight_materials_refuses_bad_input_in_one_line(baked, tmp_path, extra, message):
    _, blend, _, _ = baked
    r = relight("relight-materials", blend, "--object", "Floor", *extra,
                "--out", tmp_path / "x.npy")
    assert r.returncode == 2
    (line,) = our_lines(r.stderr)
    assert line.startswith("relight: error:") and message in line
    assert not (tmp_path / "x.npy").exists()


def test_bake_materials_refuses_without_force_and_bad_regions(baked):
    folder, blend, _, args = baked
    before = folder_state(folder / "room_relight")
    r = relight(*args)
    assert r.returncode == 2 and "exists" in r.stderr and "--force" in r.stderr
    r = relight("bake-materials", blend, "--object", "Floor", "--region", "Nope", "--force",
                "--directions", "hemi:4", "--one-bounce-directions", "hemi:4",
                "--two-bounce-directions", "hemi:4", "--samples", "4")
    assert r.returncode == 2
    (line,) = our_lines(r.stderr)
    assert "uses material 'Nope'" in line and "nothing was written" in line
    r = relight("bake-materials", blend, "--object", "Floor", "--region", "RedMaterial",
                "--anchors", "roughness:0.01", "--force")
    assert r.returncode == 2 and "0.05..1" in r.stderr
    assert folder_state(folder / "room_relight") == before


def test_compare_renders_the_edit_before_and_after(baked, tmp_path):
    from relightable_textures.lt_addon.io.contact_sheet import read_png

    _, blend, _, _ = baked
    png = tmp_path / "edit.png"
    r = relight("relight-materials", blend, "--object", "Floor", "--set",
                "RedMaterial.color=0.1,0.2,0.8", "--compare", png, "--compare-samples", "16",
                "--out", tmp_path / "s.npy")
    assert r.returncode == 0, r.stderr[-2000:]
    cmp = json.loads(r.stdout)["compare"]
    img = read_png(str(png))
    assert img.shape[0] > 2 * 192 and img.shape[1] > 3 * 256   # 2 rows x 3 captioned panels
    # test size (9 x 9 vertices per wall, a 26-vertex box): per-vertex shading is coarse;
    # measured 0.33 / 0.32 at 64 spp. A wrong light direction or vertex order errs ~1.
    assert 0 < cmp["rel_rmse_before"] < 0.6 and 0 < cmp["rel_rmse_after"] < 0.6
    r = relight("relight-materials", blend, "--object", "Floor", "--sun", "30,40", "--compare",
                tmp_path / "x.png", "--out", tmp_path / "x.npy")
    assert r.returncode == 2 and "drop --sun" in r.stderr


def test_glossy_anchors_from_the_cli_edit_metallic_and_roughness(tmp_path):
    """A bake with one glossy anchor; relight-materials applies --set metallic / roughness
    as the tensors do, and --compare renders the metal edit next to Cycles."""
    from relightable_textures.lt_addon.io.contact_sheet import read_png
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import ptt

    import bpy

    blend = tmp_path / "room.blend"
    make_scene("room", blend)
    # the sample's walls are Diffuse BSDFs: make the red one a Principled BSDF, whose Metallic
    # and Roughness a user edits
    from relightable_textures.samples.scene_setup import make_principled

    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    make_principled(bpy.data.materials["RedMaterial"])
    bpy.ops.wm.save_mainfile(filepath=str(blend))
    args = ["bake-materials", blend]
    for name in OBJECTS:
        args += ["--object", name]
    r = relight(*args, "--region", "RedMaterial", "--anchors", "roughness:0.5", "--bounces",
                "1", "--directions", "hemi:16", "--one-bounce-directions", "hemi:4",
                "--anchor-directions", "hemi:4")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "anchors roughness:0.5" in r.stdout
    # 4 one-bounce directions: the bake warns that a sun between them blends coarsely
    (warning,) = [ln for ln in our_lines(r.stderr) if "one-bounce directions" in ln]
    assert warning.startswith("relight: warning: 4 one-bounce directions") and "6.7x" in warning
    rep = json.loads((tmp_path / "room_relight" / "Floor_materials.json").read_text())
    # Cycles bakes the direct light's check (8 directions) and the glossy anchor (one region,
    # 4 directions); the direct light and the diffuse bounce are by rays
    assert rep["bake_calls"] == 8 + 4 and rep["anchors"] == "roughness:0.5"
    assert rep["anchor_samples"] == 64 and rep["anchor_directions"] == "hemi:4"
    out = tmp_path / "m.npy"
    png = tmp_path / "metal.png"
    r = relight("relight-materials", blend, "--object", "Floor", "--sun", "30,50",
                "--set", "RedMaterial.metallic=1", "--set", "RedMaterial.roughness=0.5",
                "--out", out)
    assert r.returncode == 0, r.stderr[-2000:]
    info = json.loads(r.stdout)
    assert info["finish"]["RedMaterial"] == {"metallic": 1.0, "roughness": 0.5}
    t = ptt.TransferTensors.load(str(tmp_path / "room_relight" / "Floor_materials.npz"))
    from relightable_textures.operators.base.direct_rays import exact_direct

    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    sun = ptt.Sun(tuple(direction_from_az_el(30, 50)))
    exact = exact_direct(bpy.context.scene, t, sun)
    metal = t.shade(sun, {}, direct=exact, finish={"RedMaterial": (1.0, 0.5)})
    np.testing.assert_allclose(np.load(out), metal, rtol=1e-6)
    # a metal wall has no diffuse colour: its own vertices go black in the preview
    sl = t.object_slices()["WallLeft"]
    assert np.abs(metal[sl]).max() == 0 and np.abs(t.shade(sun, {}, direct=exact)[sl]).max() > 0
    r = relight("relight-materials", blend, "--object", "Floor", "--set",
                "RedMaterial.metallic=1", "--compare", png, "--compare-samples", "16",
                "--out", tmp_path / "c.npy")
    assert r.returncode == 0, r.stderr[-2000:]
    cmp = json.loads(r.stdout)["compare"]
    assert cmp["finish"] == {"RedMaterial": {"metallic": 1.0}}
    assert read_png(str(png)).shape[1] > 3 * 256
    # as coarse as the colour edit's comparison above; a metal wall lit as diffuse errs more
    assert 0 < cmp["rel_rmse_before"] < 0.6 and 0 < cmp["rel_rmse_after"] < 0.6
