"""A newcomer's first bake, through the panel's operators only (issue 57).

Blender's factory scene as a new user has it -- unsaved, the default cube with its default
material, a Sun added -- and a second object of the user's that shares the cube's material and
is not baked. Each step's outcome is asserted: the bake lands in the folder the panel names
(an unsaved file has no '//'), the viewport is switched to Material Preview, the preview is
EEVEE's only (a Cycles F12 render equals the render before it, within noise), the shared
material is left alone (the cube's preview is on a copy), an EEVEE F12 render (the factory
engine) equals the render before the bake too (the preview steps aside for it; the bake locked
the interface so F12 from the UI may do that), Show Preview off/on, Remove Preview
puts back exactly what was there, and undo brings the preview back (Remove Preview is an undo
step) and takes the bake out (the bake is one)."""

import os
import threading

import numpy as np
import pytest

pytestmark = pytest.mark.blender


def _fingerprint(mat) -> dict:
    """The user's own nodes and links of ``mat`` (our tagged preview nodes left out), the
    active output and its target: what the preview must never change."""
    tree = mat.node_tree
    nodes = {}
    for n in tree.nodes:
        if n.get("relight_preview"):
            continue
        values = []
        for s in n.inputs:
            v = getattr(s, "default_value", None)
            values.append(tuple(v) if hasattr(v, "__len__") else v)
        nodes[n.name] = (n.bl_idname, tuple(n.location), tuple(values),
                         getattr(n, "target", None),
                         n.is_active_output if n.bl_idname == "ShaderNodeOutputMaterial" else None)
    links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name,
                    l.to_socket.identifier) for l in tree.links
                   if not l.from_node.get("relight_preview")
                   and not l.to_node.get("relight_preview"))
    return {"name": mat.name, "nodes": nodes, "links": links}


def _render(scene, path: str) -> np.ndarray:
    """F12 with Cycles, tiny and few samples, fixed seed: (H, W, 3) linear RGB (the project's
    own camera render, as Relight Compare renders). The scene's engine is put back."""
    from relightable_textures.operators.preview.compare_render import render_camera

    engine = scene.render.engine
    scene.cycles.device = "CPU"
    scene.cycles.seed = 3
    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.render.resolution_percentage = 100
    try:
        return render_camera(scene, path, 8)
    finally:
        scene.render.engine = engine


def _render_eevee(scene, path: str) -> np.ndarray:
    """F12 with EEVEE, the factory scene's engine (software GL here: tiny, 4 samples; EEVEE
    renders the same scene to the same pixels, measured: difference 0.0)."""
    from relightable_textures.operators.base import compat
    from relightable_textures.operators.preview.compare_render import render_camera

    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.render.resolution_percentage = 100
    return render_camera(scene, path, 4, engine=compat.EEVEE_ENGINE)


def test_a_newcomer_bakes_previews_renders_removes_and_undoes(tmp_path, monkeypatch):
    import bpy

    import relightable_textures
    from relightable_textures.operators.base import compat
    from relightable_textures.operators.preview import preview_nodes as pn
    from relightable_textures.operators.preview import render_guard
    from relightable_textures.operators.ui import bake_ops

    monkeypatch.setenv("HOME", str(tmp_path / "home"))   # the unsaved file's bake folder
    monkeypatch.setattr(bake_ops, "_UNSAVED_STAMP", ["test"])
    opened = []
    monkeypatch.setattr(bake_ops, "open_path", opened.append)
    bpy.ops.wm.read_factory_settings(use_empty=False)
    relightable_textures.register()
    try:
        scene = bpy.context.scene
        assert bpy.data.filepath == ""
        cube, mat = bpy.data.objects["Cube"], bpy.data.objects["Cube"].active_material
        # a default Sun, and the user's second object sharing the cube's material (not baked)
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.rotation_euler = (0.6, 0.2, 0.8)
        scene.collection.objects.link(sun)
        other = bpy.data.objects.new("Other", cube.data.copy())
        other.location = (0.0, 0.0, -2.2)
        scene.collection.objects.link(other)
        assert other.material_slots[0].material == mat
        before = _fingerprint(mat)
        assert scene.render.engine == compat.EEVEE_ENGINE    # the factory scene renders EEVEE
        assert not scene.render.use_lock_interface
        render_before = _render(scene, str(tmp_path / "before.exr"))
        assert render_before.mean() > 0.01
        eevee_before = _render_eevee(scene, str(tmp_path / "eevee-before.exr"))
        assert eevee_before.mean() > 0.01

        # 1. the panel's defaults for a first bake: no folder to choose, nothing to save
        props = scene.relight
        assert props.output_dir == "" and not props.check_vs_cycles
        want = str(tmp_path / "home" / "relight" / "untitled-test_relight")
        assert bake_ops._output_dir(props) == want
        props.preset = "draft"
        props.directions, props.resolution = 64, 16      # tiny: seconds, not the preset's
        props.check_vs_cycles = True                      # the README's tick
        assert props.truth_lights == 4
        props.truth_lights = 1
        props.device = "cpu"
        for o in scene.objects:
            o.select_set(o == cube)
        bpy.context.view_layer.objects.active = cube
        bpy.ops.ed.undo_push(message="the newcomer's scene")
        view3d = [a.spaces.active for a in bpy.context.screen.areas if a.type == "VIEW_3D"]
        assert view3d and all(v.shading.type == "SOLID" for v in view3d)

        # 2. Bake: into the folder the panel named, the view shows the preview
        # ('EXEC_DEFAULT', True): as a button press, the operator pushes its undo step
        assert bpy.ops.relight.bake_textures("EXEC_DEFAULT", True) == {"FINISHED"}
        files = os.listdir(want)
        assert "Cube_texture_report.json" in files and "Cube_compare.png" in files
        assert bpy.context.window_manager.relight_last_failure == ""
        assert all(v.shading.type == "MATERIAL" for v in view3d)
        lines = scene[bake_ops.LAST_BAKE_KEY].splitlines()
        assert lines[0].startswith("Baked Cube:") and "error vs Cycles" in lines[0]
        assert bake_ops.PREVIEW_NOTE in lines
        # EEVEE renders from the UI run on the render thread: the bake locked the interface
        # so the preview may step aside there, and said so
        assert scene.render.use_lock_interface and scene.get(render_guard.LOCKED_KEY)
        assert bake_ops.LOCK_NOTE in lines
        # the shared material is left alone: the cube's preview is on a copy, said so
        copy = cube.material_slots[0].material
        assert copy != mat and copy.get(pn.COPY_OF) == mat
        assert other.material_slots[0].material == mat
        assert any("copy of material 'Material'" in ln and "Other uses it too" in ln
                   for ln in lines), lines
        assert _fingerprint(mat) == before
        assert not [n for n in mat.node_tree.nodes if n.get("relight_preview")]
        # the copy's preview output is EEVEE's; the copy's own output stays the active one
        (ours,) = [n for n in copy.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"
                   and n.get("relight_preview")]
        assert ours.target == "EEVEE" and not ours.is_active_output
        assert {k: v for k, v in _fingerprint(copy).items() if k != "name"} == \
            {k: v for k, v in before.items() if k != "name"}
        assert pn.preview_kinds(cube) == ["transport_texture"] and pn.preview_shown(cube)
        # Open Folder / Open Comparison open what this session made
        assert bpy.ops.relight.open_bake_folder() == {"FINISHED"}
        assert bpy.ops.relight.open_comparison() == {"FINISHED"}
        assert opened == [want, os.path.join(want, "Cube_compare.png")]

        # 3. F12 with Cycles renders the user's materials, not the preview
        render_after = _render(scene, str(tmp_path / "after.exr"))
        assert np.abs(render_after - render_before).max() < 1e-4
        # (Cycles shown the preview -- what Relight Compare does -- is another picture)
        undo = pn.render_previews([cube], "CYCLES")
        shown = _render(scene, str(tmp_path / "shown.exr"))
        for f in undo:
            f()
        assert np.abs(shown - render_before).max() > 0.05
        assert ours.target == "EEVEE"

        # 3b. F12 with EEVEE, the factory engine: the preview steps aside for the render and
        # comes back after it (the same output node, target EEVEE)
        eevee_after = _render_eevee(scene, str(tmp_path / "eevee-after.exr"))
        assert np.abs(eevee_after - eevee_before).max() < 1e-4
        assert pn.preview_shown(cube) and pn._our_output(copy.node_tree).target == "EEVEE"
        undo = pn.render_previews([cube], compat.EEVEE_ENGINE)   # asked for: it shows
        eevee_shown = _render_eevee(scene, str(tmp_path / "eevee-shown.exr"))
        for f in undo:
            f()
        assert np.abs(eevee_shown - eevee_before).max() > 0.05
        # the rule for the UI's render thread: step aside only with the interface locked
        rule = {}
        for locked in (True, False):
            scene.render.use_lock_interface = locked
            t = threading.Thread(target=lambda k=locked: rule.__setitem__(
                k, render_guard.can_step_aside(scene)))
            t.start()
            t.join()
        assert rule == {True: True, False: False}
        assert render_guard.can_step_aside(scene)               # this (main) thread
        scene.render.use_lock_interface = True

        # 4. Show Preview off: EEVEE shows the user's material too; on: the preview again
        props.show_preview = False
        assert not pn.preview_shown(cube) and pn.preview_kinds(cube) == ["transport_texture"]
        assert not [n for n in copy.node_tree.nodes
                    if n.bl_idname == "ShaderNodeOutputMaterial" and n.get("relight_preview")]
        props.show_preview = True
        assert pn.preview_shown(cube)

        # 5. Remove Preview: exactly what was there
        assert bpy.ops.relight.remove_preview("EXEC_DEFAULT", True) == {"FINISHED"}
        assert cube.material_slots[0].material == mat
        assert "Material (Relight Cube)" not in bpy.data.materials
        assert _fingerprint(mat) == before
        assert not [k for k in ("relight_azimuth", "relight_elevation", "relight_color")
                    if k in scene]
        assert not [g for g in bpy.data.node_groups if g.get("relight_preview")]
        assert not [i for i in bpy.data.images if i.get("relight_preview")]
        assert mat.node_tree.animation_data is None
        assert np.abs(_render(scene, str(tmp_path / "removed.exr")) - render_before).max() < 1e-4
        assert not scene.render.use_lock_interface and render_guard.LOCKED_KEY not in scene

        # 6. Undo: Remove Preview was one step, so the preview is back; once more undoes the
        # bake (its preview and records), the files stay in the folder
        bpy.ops.ed.undo()
        cube = bpy.data.objects["Cube"]
        assert pn.preview_kinds(cube) == ["transport_texture"]
        assert cube.material_slots[0].material.name == "Material (Relight Cube)"
        assert bpy.data.objects["Other"].material_slots[0].material.name == "Material"
        assert bpy.context.scene.render.use_lock_interface
        bpy.ops.ed.undo()
        cube = bpy.data.objects["Cube"]
        assert "relightable_bakes" not in cube and pn.preview_kinds(cube) == []
        assert not bpy.context.scene.render.use_lock_interface
        assert cube.material_slots[0].material.name == "Material"
        assert _fingerprint(bpy.data.materials["Material"]) == before
        assert "Cube_texture_report.json" in os.listdir(want)
    finally:
        relightable_textures.unregister()
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
