"""The scene's render visibility, as Cycles has it, in every stage of the ray bake (issue 59).

The scene: the statue sample (Suzanne on a 6 m ground), baked at 32^2 with the draft preset
(64 directions, the gathered indirect term at 16^2) and compared with Cycles' DIFFUSE radiance
bake of the same suns (:class:`operators.base.cycles_bake.EnvironmentBake`, 64 spp, the bake's
bounces). docs/bake-files.md "The scene's visibility flags" has the table these rows measure.
"""

import pathlib
import tempfile

import numpy as np
import pytest

from relight_cli import assert_refused, make_scene
from relightable_textures import samples
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

R = 32
LIGHTS = ((37.0, 30.0), (161.0, 20.0))


def _statue(**statue_flags):
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("statue", scene, "test")
    statue = bpy.data.objects["Statue"]
    for k, v in statue_flags.items():
        setattr(statue, k, v)
    bpy.context.view_layer.update()
    return scene


def _bake(scene, names):
    """The objects ``names`` baked together; per light (Cycles' bake, the relit texture) of
    each, over the texels Cycles covers, and the last report."""
    import bpy

    from relightable_textures.lt_addon.transport import bundle
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.base.jobs import run

    objs = [bpy.data.objects[n] for n in names]
    s = tx.settings_from_preset("draft", directions="hemi:64", resolution=R,
                                indirect_resolution=R // 2, bounces=2, sun_angle=2.0)
    out = run(tx.bake_job(scene, objs, s, tempfile.mkdtemp(prefix="relight-vis-"), truth=0,
                          compare=False, preview=False))
    loaded = [tx.load_bake(r["report"]) for r in out.reports]
    pairs = []
    with EnvironmentBake(scene, objs, R, 64, s.bounces, (8, 16), mode="radiance", seed=1,
                         world_sampling="none") as session:
        for az, el in LIGHTS:
            d = direction_from_az_el(az, el)
            truths = session.bake_sun_all(d, 1.0, s.sun_angle)
            pairs.append([(t, np.asarray(bundle.relight(b, st, d, s.sun_angle, 1.0,
                                                        source="transport")))
                          for t, (b, st, _) in zip(truths, loaded)])
    for _, st, _ in loaded:
        st.close()
    return pairs, loaded[-1][2]


def _rel(truth, got):
    m = truth.sum(-1) > 0
    return float(np.linalg.norm(got[m] - truth[m]) / np.linalg.norm(truth[m]))


def test_an_object_hidden_from_render_is_refused_in_one_line(tmp_path):
    """Cycles refuses to bake an object whose camera icon is off; the bake said nothing, baked
    it anyway (by switching the flag on for its Cycles stages), and its bounce light reached
    the ground though it cast no shadow (ground max 0.103 against Cycles' 0.112 with the statue
    shown, the ground's error 0.30 against 0.15). Refused, as is an object in a collection
    hidden from render or excluded from the view layer."""
    import bpy

    from relightable_textures.operators.base.cycles_bake import BakeInputError, check_bakeable

    blend = tmp_path / "s.blend"
    make_scene("statue", blend)
    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    bpy.data.objects["Statue"].hide_render = True
    bpy.ops.wm.save_mainfile(filepath=str(blend))
    assert_refused(tmp_path, "Statue is hidden from render (its camera icon is off)",
                   "bake-textures", blend, "--object", "Ground", "--object", "Statue",
                   "--preset", "draft", "--out", tmp_path / "out")
    for how in ("hide_render", "exclude"):
        scene = _statue()
        statue = bpy.data.objects["Statue"]
        coll = bpy.data.collections.new("Props")
        scene.collection.children.link(coll)
        coll.objects.link(statue)
        scene.collection.objects.unlink(statue)
        if how == "hide_render":
            coll.hide_render = True
        else:
            bpy.context.view_layer.layer_collection.children["Props"].exclude = True
        with pytest.raises(BakeInputError, match="Statue is in collection 'Props'"):
            check_bakeable(statue)


def test_an_occluder_hidden_from_render_casts_no_shadow_and_reflects_nothing():
    """The ground baked beside a statue hidden from render (its own flag, or its collection's)
    is the ground baked without the statue: no shadow, no bounce light (the same texture, to
    float rounding); and the material edits' rays (:func:`direct_rays.shadow_casters`) leave
    out an object of a collection hidden from render or excluded (before, only the object's own
    flag was read: the statue cast its shadow there)."""
    import bpy

    from relightable_textures.operators.base.direct_rays import shadow_casters

    scene = _statue()
    bpy.data.objects.remove(bpy.data.objects["Statue"])
    alone, _ = _bake(scene, ["Ground"])
    for how in ("object", "collection"):
        scene = _statue(hide_render=how == "object")
        if how == "collection":
            statue = bpy.data.objects["Statue"]
            coll = bpy.data.collections.new("Props")
            scene.collection.children.link(coll)
            coll.objects.link(statue)
            scene.collection.objects.unlink(statue)
            coll.hide_render = True
        assert [o.name for o in shadow_casters(scene)] == ["Ground"]
        pairs, rep = _bake(scene, ["Ground"])
        assert rep["indirect"]["method"] == "gathered"
        for (_, a), ((_, b),) in zip((p[0] for p in alone), pairs):
            assert np.allclose(a, b, atol=1e-4), (how, np.abs(a - b).max())
    scene = _statue()
    coll = bpy.data.collections.new("Props")
    scene.collection.children.link(coll)
    coll.objects.link(bpy.data.objects["Statue"])
    scene.collection.objects.unlink(bpy.data.objects["Statue"])
    bpy.context.view_layer.layer_collection.children["Props"].exclude = True
    assert [o.name for o in shadow_casters(scene)] == ["Ground"]


def test_an_occluder_invisible_to_diffuse_rays_casts_its_shadow_and_reflects_nothing():
    """A statue with Ray Visibility > Diffuse off casts its shadow on the ground and reflects
    no light onto it (Cycles: ground max 0.0796 and 0.0545, the unshadowed ground's; mean
    0.0772 and 0.0535, the shadow's). Measured 2026-12-06, bpy 5.0.1: baked with the ground,
    the gathered term added the statue's bounce light (ground max 0.098 and 0.075, error 0.136
    and 0.166) and its own (the statue's error 0.157 and 0.187); baked alone, the ground fell
    back to Cycles' steerable term (the statue's hits counted as objects not baked). Now the
    gather's rays pass through it: the ground's maximum within 3 % of Cycles', its error that
    of the ground baked alone beside a shown statue (about 0.15), and baked alone it keeps the
    gathered term."""
    # the errors every flag at its default has, same run (0.122 / 0.142 statue, 0.147 / 0.158
    # ground on 5.0.1): the bound, not a number measured on one Blender (5.1+ draw other
    # samples, 5.3 fills UV margins otherwise)
    plain, _ = _bake(_statue(), ["Statue", "Ground"])
    scene = _statue(visible_diffuse=False)
    pairs, rep = _bake(scene, ["Statue", "Ground"])
    assert rep["indirect"]["method"] == "gathered"
    for ((st_truth, st_got), (gr_truth, gr_got)), ((st_t0, st_g0), (gr_t0, gr_g0)) in zip(
            pairs, plain):
        m = gr_truth.sum(-1) > 0
        print("statue", _rel(st_truth, st_got), "ground", _rel(gr_truth, gr_got),
              gr_got[m].max(), gr_truth[m].max())
        assert gr_got[m].max() < 1.03 * gr_truth[m].max()
        assert _rel(gr_truth, gr_got) < 1.15 * _rel(gr_t0, gr_g0)
        assert _rel(st_truth, st_got) < 1.15 * _rel(st_t0, st_g0)
    scene = _statue(visible_diffuse=False)
    pairs, rep = _bake(scene, ["Ground"])
    assert rep["indirect"]["method"] == "gathered", rep["indirect"].get("why")
    for ((truth, got),), (_, (gr_t0, gr_g0)) in zip(pairs, plain):
        m = truth.sum(-1) > 0
        assert got[m].max() < 1.03 * truth[m].max()
        assert _rel(truth, got) < 1.15 * _rel(gr_t0, gr_g0)


def test_a_baked_holdout_or_shadow_catcher_is_a_plain_surface_with_a_warning():
    """Cycles' DIFFUSE bake of a holdout or a shadow catcher is black (measured, bpy 5.0.1: all
    zero), while the other objects' bakes see it as a plain surface. Before, the statue as a
    holdout baked black and its bounce light left the ground (ground max 0.078 against 0.112);
    the catcher ground alone lost its bounce light (mean 0.069 against 0.075). Now each is
    baked as a plain surface -- the same texture as without the flag -- and the report says so
    in one line (printed by the CLI as ``relight: warning:``)."""
    import bpy

    plain, _ = _bake(_statue(), ["Statue", "Ground"])
    scene = _statue(is_holdout=True)
    bpy.data.objects["Ground"].is_shadow_catcher = True
    pairs, rep = _bake(scene, ["Statue", "Ground"])
    assert any("Ground is a shadow catcher: baked as a plain surface" in w
               for w in rep["warnings"]), rep["warnings"]
    for p, q in zip(plain, pairs):
        for (_, a), (truth, b) in zip(p, q):
            assert truth.max() > 0.05
            assert np.allclose(a, b, atol=1e-4), np.abs(a - b).max()


def test_a_baked_object_that_casts_no_shadow_is_said_in_one_line():
    """Ray Visibility > Shadow off on a baked object: the bake leaves it out of every shadow
    ray, but its own texture is not as Cycles bakes it (the statue sample: 0.44 / 0.22 against
    0.12 / 0.14 with the flag on, 2026-12-06): the report says so, one warning line (the CLI
    prints it as ``relight: warning:``); the ground's report says nothing of it."""
    _, rep = _bake(_statue(visible_shadow=False), ["Statue", "Ground"])
    from relightable_textures.lt_addon.io.untrusted import read_json

    reports = {r: read_json(str(p)) for r, p in (
        ("Statue", pathlib.Path(rep["report"]).with_name("Statue_texture_report.json")),
        ("Ground", pathlib.Path(rep["report"]).with_name("Ground_texture_report.json")))}
    said = [w for w in reports["Statue"]["warnings"] if "casts no shadow" in w]
    assert len(said) == 1 and said[0].startswith("Statue casts no shadow"), reports["Statue"]
    assert not any("casts no shadow" in w for w in reports["Ground"]["warnings"])


@pytest.mark.parametrize("flag, said", [("visible_diffuse", "bounce rays pass through it"),
                                        ("visible_shadow", "casts no shadow but reflects light")])
def test_the_material_edits_gather_says_what_it_does_not_model(flag, said):
    """The material edits' bounce rays meet the shadow casters: an object whose Shadow and
    Diffuse ray visibility differ is not modelled there, and the bake's notes (its warnings)
    say so in one line naming it; with both flags alike there is no such line."""
    from relightable_textures.operators.bakes.bounce_rays import GatherScene

    assert not any("Ray Visibility" in n for n in GatherScene(_statue(), []).notes)
    notes = GatherScene(_statue(**{flag: False}), []).notes
    lines = [n for n in notes if "Ray Visibility" in n]
    assert len(lines) == 1 and lines[0].startswith("Statue: ") and said in lines[0], notes
