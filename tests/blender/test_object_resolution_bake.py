"""Per-object texture sides (issue 33: the ground under a low sun's long shadow at its own
size): objects of one side are baked as a group, every object still shadows every group.

Independent reference: Cycles' own 1-spp hard-sun bake of each object alone at its side (the
direct transport of a texel does not depend on what else is baked in the same call)."""

import json
import os

import numpy as np
from relight_cli import make_scene, our_lines, relight

from relightable_textures import samples
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
from relightable_textures.lt_addon.transport import texture as tt


def covered(o, R):
    """The texels the bakes sample (outside them only the margins, filled alike)."""
    from relightable_textures.lt_addon.rays.texels import texel_samples
    from relightable_textures.operators.base.meshes import uv_triangles

    m = np.zeros(R * R, bool)
    m[texel_samples(uv_triangles(o), R).texel] = True
    return m.reshape(R, R)


def sun_bake(scene, objects, direction, R):
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    with EnvironmentBake(scene, objects, R, 1, 0, (8, 16), mode="irradiance", seed=0,
                         world_sampling="none", passes="direct") as s:
        return [img[..., 0] for img in s.bake_sun_all(direction, 1.0, 0.0)]


def test_the_panel_bakes_the_ground_at_its_own_side_with_the_statues_shadow(fresh_scene,
                                                                            tmp_path):
    """Statue at the panel's 16^2, Ground's Object Resolution 32: two groups in one bake, each
    texture equal to Cycles' bake of that object alone at its side (to half floats), the
    statue's shadow on the 32^2 ground, one camera comparison of both, and the sides in both
    reports."""
    import bpy

    import relightable_textures

    scene = fresh_scene
    samples.build("statue", scene, "test")
    statue, ground = bpy.data.objects["Statue"], bpy.data.objects["Ground"]
    relightable_textures.register()
    try:
        props = scene.relight
        props.preset = "draft"
        props.directions, props.resolution, props.indirect_samples = 24, 16, 4
        props.truth_lights, props.device = 1, "cpu"
        props.texel_sampling = "centre"      # 1 spp: equal to Cycles' first sample
        props.output_dir = str(tmp_path) + os.sep
        ground.relight_resolution = 32
        for o in scene.objects:
            o.select_set(o in (statue, ground))
        bpy.context.view_layer.objects.active = statue
        assert bpy.ops.relight.bake_textures() == {"FINISHED"}
        reps = {n: json.loads((tmp_path / f"{n}_texture_report.json").read_text())
                for n in ("Statue", "Ground")}
        for n, side in (("Statue", 16), ("Ground", 32)):
            assert reps[n]["settings"]["resolution"] == side
            assert reps[n]["object_resolutions"] == {"Ground": 32, "Statue": 16}
            assert reps[n]["objects_baked_together"] == [n]
            assert reps[n]["ground_truth"]          # each group against its own truths
        # the camera comparison: once, after both groups, of both objects
        assert reps["Statue"]["comparison"] == reps["Ground"]["comparison"]
        # at the Sun size the groups took from the scene (Scene's Sun: none here, 2 degrees)
        assert reps["Statue"]["comparison"]["sun_angle"] == 2.0
        assert all(reps[n]["settings"]["sun_angle"] == 2.0 for n in reps)
        assert (tmp_path / "Statue_compare.png").exists()
        assert not (tmp_path / "Ground_compare.png").exists()
        stores = {n: tt.TransportStore.open(reps[n]["files"]["transport"])
                  for n in ("Statue", "Ground")}
        assert stores["Ground"].resolution == 32 and stores["Statue"].resolution == 16
        dirs = stores["Ground"].directions.directions
        d = dirs[dirs[:, 2] > 0][3]       # (a baked sun above the horizon: under it, it is off)
        for obj, side in ((ground, 32), (statue, 16)):
            alone = sun_bake(scene, [obj], d, side)[0]
            m = covered(obj, side)
            np.testing.assert_allclose(stores[obj.name].sun(d)[m], alone[m],
                                       atol=2.0 ** -11 * alone.max())
        statue.hide_render = True
        unshadowed = sun_bake(scene, [ground], d, 32)[0]
        statue.hide_render = False
        shadow = unshadowed - stores["Ground"].sun(d)
        assert shadow.max() > 0.5 * unshadowed.max()   # the statue's shadow is on the ground
        for s in stores.values():
            s.close()
    finally:
        relightable_textures.unregister()


def test_cli_object_resolution_estimates_per_group_and_refuses_bad_input(tmp_path):
    blend = make_scene("statue", tmp_path / "s.blend")
    base = ["bake-textures", blend, "--object", "Statue", "--object", "Ground", "--preset",
            "draft", "--resolution", "16", "--out", tmp_path / "o"]
    for extra, words in ((["--object-resolution", "Grond=32"],
                          "names Grond, which is not baked (baked: Statue, Ground)"),
                         (["--object-resolution", "Ground=3"], "must be in 4..8192"),
                         (["--object-resolution", "Ground"], "takes NAME=SIDE")):
        r = relight(*base, *extra)
        assert r.returncode == 2, r.stderr[-2000:]
        (line,) = our_lines(r.stderr)
        assert line.startswith("relight: error: ") and words in line, line
    assert not (tmp_path / "o").exists()
    r = relight(*base, "--object-resolution", "Ground=32", "--estimate")
    assert r.returncode == 0, r.stderr[-2000:]
    firsts = [ln for ln in r.stdout.splitlines() if ln.startswith("estimate for")]
    assert [ln.split(":")[0] for ln in firsts] == ["estimate for 1 object(s) at 32^2",
                                                  "estimate for 1 object(s) at 16^2"]
    assert not (tmp_path / "o").exists()


def test_cli_bakes_two_sides_and_prints_each_groups_figures(tmp_path):
    """The CLI's grouped bake: both objects at their sides in one folder, and each group's
    engine line and error against its own Cycles truths printed once (1 light each)."""
    blend = make_scene("statue", tmp_path / "s.blend")
    r = relight("bake-textures", blend, "--object", "Statue", "--object", "Ground", "--preset",
                "draft", "--directions", "hemi:24:1.5", "--resolution", "16",
                "--object-resolution", "Ground=32", "--truth", "1", "--no-compare", "--out",
                tmp_path / "o")
    assert r.returncode == 0, r.stderr[-2000:]
    out = r.stdout.splitlines()
    assert [ln.split(":")[0] for ln in out if ln.startswith("baked ")] == [
        "baked Ground", "baked Statue"]
    assert "at 32^2" in next(ln for ln in out if ln.startswith("baked Ground"))
    assert "at 16^2" in next(ln for ln in out if ln.startswith("baked Statue"))
    errors = [ln for ln in out if "error vs Cycles Sun" in ln]
    assert len(errors) == 2 and all("at 1 held-out lights" in ln for ln in errors), errors
    assert len([ln for ln in out if ln.strip().startswith("Direct light:")]) == 2
    # the gathered indirect light reads only T of the objects baked together: two groups take
    # the steerable term, and say why
    baked = [ln for ln in out if ln.startswith("baked ")]
    assert len(baked) == 2 and all("indirect (steerable)" in ln for ln in baked)
    for n, side in (("Statue", 16), ("Ground", 32)):
        rep = json.loads((tmp_path / "o" / f"{n}_texture_report.json").read_text())
        assert rep["settings"]["resolution"] == side
        assert rep["indirect"]["method"] == "steerable"
        assert "different texture sides" in rep["indirect"]["why"]
