"""The Relight panel as a newcomer reads it (issue 57): a Basic part of few controls before
Bake, the rest in a closed Advanced, labels on every line, the measured figure of the Sun Size
in use, Check vs Cycles a checkbox that still reads older files' counts, the last failure kept
until the next bake, Open Folder / Open Comparison confined to what this session baked, one
output-folder rule with the command line.

The panels are drawn into a recording layout (Blender's own UILayout needs a window's region),
which lists the controls in drawing order."""

import os
import types

import pytest

pytestmark = pytest.mark.blender


class _Layout:
    """Records what a panel's ``draw`` puts in it: ``(kind, name, text)`` in order."""

    def __init__(self, log):
        self.log = log
        self.enabled = self.active = True
        self.alert = self.use_property_split = self.use_property_decorate = False
        self.scale_y = 1.0

    def _sub(self, *a, **k):
        return _Layout(self.log)

    row = column = box = split = column_flow = grid_flow = _sub

    def prop(self, data, name, **k):
        self.log.append(("prop", name, k.get("text")))

    def operator(self, idname, **k):
        self.log.append(("op", idname, k.get("text")))
        return types.SimpleNamespace()

    def label(self, **k):
        self.log.append(("label", None, k.get("text")))

    def separator(self, **k):
        pass


def _draw(panel_cls, context) -> list:
    log = []
    panel_cls.draw(types.SimpleNamespace(layout=_Layout(log)), context)
    return log


def _before_bake(log) -> list:
    out = []
    for kind, name, _ in log:
        if kind == "op" and name == "relight.bake_textures":
            return out
        if kind in ("prop", "op"):
            out.append(name)
    raise AssertionError("no Bake button")


@pytest.fixture
def panel_scene():
    """The factory startup scene (the default cube selected and active), unsaved, with the
    extension registered."""
    import bpy

    import relightable_textures

    bpy.ops.wm.read_homefile(use_empty=False, use_factory_startup=True)
    relightable_textures.register()
    cube = bpy.data.objects["Cube"]
    bpy.context.view_layer.objects.active = cube
    cube.select_set(True)
    try:
        yield bpy.context.scene
    finally:
        relightable_textures.unregister()
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def test_the_basic_part_is_six_controls_and_the_rest_is_advanced(panel_scene):
    """Before Bake: Preset, Resolution, Check vs Cycles, Output, Save .blend First (unsaved
    only), Estimate -- 29 controls before issue 57. Every drawn property has a label of its
    own, not its identifier."""
    import bpy

    from relightable_textures.operators.ui import panel

    ctx = bpy.context
    basic = _before_bake(_draw(panel.VIEW3D_PT_relight_bake, ctx))
    assert basic == ["preset", "resolution", "check_vs_cycles", "output_dir",
                                 "wm.save_as_mainfile", "relight.estimate"]
    panel_scene.relight.check_vs_cycles = True       # the count shows once ticked
    assert "truth_lights" in _before_bake(_draw(panel.VIEW3D_PT_relight_bake, ctx))
    adv = panel.VIEW3D_PT_relight_bake_advanced
    assert adv.bl_parent_id == "VIEW3D_PT_relight_bake" and "DEFAULT_CLOSED" in adv.bl_options
    advanced = [n for k, n, _ in _draw(adv, ctx) if k == "prop"]
    for name in ("method", "directions", "scene_sun_size", "transport_indirect",
                 "transport_viewport", "device", "run_on"):
        assert name in advanced
    # the Sun Size is the scene's Sun's (the factory scene's light is a Point: 2 degrees),
    # the field only once Scene's Sun is off
    assert "sun_angle" not in advanced and any(
        t == "Sun Size: 2\u00b0 (the scene has no Sun)" for k, _, t in _draw(adv, ctx))
    panel_scene.relight.scene_sun_size = False
    assert "sun_angle" in [n for k, n, _ in _draw(adv, ctx) if k == "prop"]
    panel_scene.relight.scene_sun_size = True
    assert "transport_model" not in advanced        # only PCA previews live: not offered
    panel_scene.relight.transport_model = "blocks"   # (an older file's choice is shown, said)
    log = _draw(adv, ctx)
    assert ("prop", "transport_model", None) in log
    assert any("only PCA previews live" in (t or "") for _, _, t in log)
    rna = panel_scene.relight.bl_rna.properties
    for name in set(advanced + basic) & set(rna.keys()):
        assert rna[name].name and rna[name].name != name, name
    # the sample scenes are open, at the documentation's size
    assert "DEFAULT_CLOSED" not in getattr(panel.VIEW3D_PT_relight_samples, "bl_options", ())
    assert panel_scene.relight.sample_size == "demo"
    assert bpy.ops.relight.add_sample_scene.get_rna_type().properties["size"].default == "demo"


def test_lines_say_labels_and_the_figure_of_the_sun_size_in_use(panel_scene, monkeypatch):
    from relightable_textures.operators.bakes.presets import BY_METHOD, TRANSPORT
    from relightable_textures.operators.ui import panel

    props = panel_scene.relight
    fig = TRANSPORT.figures("balanced")
    assert props.sun_angle == 2.0 and props.scene_sun_size
    # Scene's Sun (the default): a Sun of Blender's default size gives its own figure, as
    # the bake takes that size from the scene
    import bpy

    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    panel_scene.collection.objects.link(sun)
    (line, _), = panel.preset_lines(props)
    assert f"{fig['rel_rmse_0526deg']:.3f}" in line and "0.526\u00b0 sun" in line
    bpy.data.objects.remove(sun)
    (line, _), = panel.preset_lines(props)            # no Sun: 2 degrees
    assert "2\u00b0 sun" in line
    props.scene_sun_size = False                      # the field from here on
    (line, _), = panel.preset_lines(props)
    assert f"{fig['rel_rmse_2deg']:.3f}" in line and "2\u00b0 sun" in line
    props.sun_angle = 10.0
    (line, _), = panel.preset_lines(props)
    assert f"{fig['rel_rmse']:.3f}" in line and "10\u00b0 sun" in line
    props.sun_angle = 4.0
    (line, _), = panel.preset_lines(props)
    assert "2\u00b0 sun" in line and "Sun Size is 4\u00b0" in line
    # Blender's default Sun (0.526 degrees) has a figure of its own
    props.sun_angle = 0.526
    (line, _), = panel.preset_lines(props)
    assert f"{fig['rel_rmse_0526deg']:.3f}" in line and "0.526\u00b0 sun" in line
    assert "Sun Size" not in line
    # a changed field -- also one the preset does not set -- is named by its label
    props.horizon_power = 2.5
    props.transport_viewport = "pca"
    text = " ".join(t for t, _ in panel.preset_lines(props))
    assert "Horizon Density" in text and "Viewport" in text and "_" not in text.split("(")[0]
    props.preset = "balanced"                        # choosing it again: the preset's values
    props.transport_viewport = "auto"
    assert panel.preset_lines(props)[0][1] == "INFO"
    # a preset without measured figures says so, not how to measure it
    monkeypatch.setattr(BY_METHOD["transport"], "figures", lambda name: {})
    (line, _), = panel.preset_lines(props)
    assert line == "This preset has no measured figures" and "make" not in line
    # every preset's tooltip says what it is for
    items = props.bl_rna.properties["preset"].enum_items
    assert [i.identifier for i in items] == ["draft", "balanced", "production"]
    assert all(len(i.description) > 40 for i in items)


def test_check_vs_cycles_is_a_checkbox_that_reads_older_counts(panel_scene):
    from relightable_textures.operators.ui.properties import truth_count

    props = panel_scene.relight
    assert not props.check_vs_cycles and truth_count(props) == 0 and props.truth_lights == 4
    props["truth_lights"] = 3                  # a file of an older version: the count alone
    assert props.check_vs_cycles and truth_count(props) == 3
    props["truth_lights"] = 0
    assert not props.check_vs_cycles
    props.check_vs_cycles = True               # ticking a zero count gives it the default
    assert props.truth_lights == 4 and truth_count(props) == 4
    props.check_vs_cycles = False
    assert truth_count(props) == 0 and props.truth_lights == 4


def test_the_output_folder_is_the_command_lines_and_an_unsaved_file_has_one(
        panel_scene, tmp_path, monkeypatch):
    import bpy

    from relightable_textures.operators.cli.common import check_output_dir
    from relightable_textures.operators.ui import bake_ops, panel

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setattr(bake_ops, "_UNSAVED_STAMP", ["s"])
    props = panel_scene.relight
    want = str(tmp_path / "home" / "relight" / "untitled-s_relight")
    assert bake_ops._output_dir(props) == want
    assert panel.output_lines(props)[0] == ("Bakes into ~/relight/untitled-s_relight",
                                            "FILE_FOLDER")
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert bake_ops._output_dir(props) == check_output_dir(None, str(blend)) == \
        str(tmp_path / "scene_relight")
    log = _draw(panel.VIEW3D_PT_relight_bake, bpy.context)
    assert "wm.save_as_mainfile" not in _before_bake(log)


def test_a_failure_stays_in_the_panel_until_the_next_bake(panel_scene, tmp_path, monkeypatch):
    import bpy

    from relightable_textures.operators.ui import bake_ops, panel

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    props = panel_scene.relight
    props.output_dir = "//relative/"           # an unsaved file has no '//'
    with pytest.raises(RuntimeError, match="relative to the .blend, which is not saved"):
        bpy.ops.relight.bake_textures()             # (an ERROR report raises in a script)
    wm = bpy.context.window_manager
    assert wm.relight_last_failure.startswith("Bake failed: the Output folder '//relative/'")
    texts = " ".join(t or "" for _, _, t in _draw(panel.VIEW3D_PT_relight_bake, bpy.context))
    assert "Bake failed: the Output folder" in texts
    # the next bake starts from a clean line (tiny: seconds)
    props.output_dir = ""
    props.preset = "draft"
    props.directions, props.resolution, props.device = 64, 16, "cpu"
    assert bpy.ops.relight.bake_textures() == {"FINISHED"}
    assert wm.relight_last_failure == ""


def test_open_folder_and_comparison_open_only_this_sessions_regular_files(tmp_path,
                                                                         monkeypatch):
    from relightable_textures.operators.ui import bake_ops

    monkeypatch.setattr(bake_ops, "_SESSION_BAKE", {})
    assert bake_ops.last_bake_folder() is None and bake_ops.last_comparison() is None
    folder = tmp_path / "bk"
    folder.mkdir()
    png = folder / "Cube_compare.png"
    png.write_bytes(b"\x89PNG")
    bake_ops.remember_bake(str(folder), str(png))
    assert bake_ops.last_bake_folder() == str(folder)
    assert bake_ops.last_comparison() == str(png)
    png.unlink()                                   # a link in its place is not opened
    os.symlink(tmp_path / "elsewhere.png", png)
    (tmp_path / "elsewhere.png").write_bytes(b"x")
    assert bake_ops.last_comparison() is None
    outside = tmp_path / "outside.png"             # nor a picture outside the bake folder
    outside.write_bytes(b"x")
    bake_ops.remember_bake(str(folder), str(outside))
    assert bake_ops.last_comparison() is None
    link = tmp_path / "link"                       # nor a folder that became a link
    os.symlink(folder, link)
    bake_ops.remember_bake(str(link))
    assert bake_ops.last_bake_folder() is None


def test_a_preview_of_an_older_version_is_made_render_safe(fresh_scene):
    """Before issue 57 the preview's output targeted All and was the active one (F12 rendered
    it): showing such a preview again leaves the user's output active and ours EEVEE's."""
    import bpy

    from relightable_textures.operators.preview import preview_nodes as pn

    mesh = bpy.data.meshes.new("m")
    obj = bpy.data.objects.new("Obj", mesh)
    fresh_scene.collection.objects.link(obj)
    mat = bpy.data.materials.new("Mine")
    mesh.materials.append(mat)
    tree = mat.node_tree
    (theirs,) = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    emission = tree.nodes.new("ShaderNodeEmission")
    legacy = tree.nodes.new("ShaderNodeOutputMaterial")
    for n in (emission, legacy):
        n["relight_preview"], n["relight_preview_kind"] = True, "transport_texture"
    tree.links.new(emission.outputs[0], legacy.inputs["Surface"])
    legacy.is_active_output = True
    assert not theirs.is_active_output
    assert pn.preview_kinds(obj) == ["transport_texture"]
    assert pn.activate_preview(obj, "transport_texture")
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    (ours,) = [n for n in outs if n.get("relight_preview")]
    assert ours.target == "EEVEE" and theirs.is_active_output and not ours.is_active_output
    assert pn.remove_preview(obj, fresh_scene) == 1
    assert sorted(n.name for n in tree.nodes) == ["Material Output", "Principled BSDF"]
    assert theirs.is_active_output
