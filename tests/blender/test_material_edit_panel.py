"""The panel's material edits: Bake Materials (the operator, run as a script would), the
live preview it installs, and the handler that re-shades when a colour or the Sun changes."""

import numpy as np
import pytest

#: Also run on 5.2 LTS by the matrix: the material gates' node trees (compat.ensure_node_tree),
#: the panel's properties (compat.path_options) and the depsgraph handler.
pytestmark = pytest.mark.version_sensitive


def _render_alone(scene, camera, path) -> np.ndarray:
    """What EEVEE's viewport shows from ``camera`` (which sees one object alone, far from the
    rest: hiding the rest would re-shade the material preview without its shadows): an EEVEE
    render with the previews shown (F12 itself never shows them), 32^2, 2 samples:
    (32, 32, 3) linear RGB."""
    import bpy

    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.operators.base import compat
    from relightable_textures.operators.preview import preview_nodes

    saved = scene.camera, scene.render.engine
    scene.camera, scene.render.engine = camera, compat.EEVEE_ENGINE
    scene.eevee.taa_render_samples = 2
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(path)
    undo = preview_nodes.render_previews(list(scene.objects), compat.EEVEE_ENGINE)
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        for f in undo:
            f()
        scene.camera, scene.render.engine = saved
    ch, _ = exrio.read_exr(str(path))
    return np.stack([ch["R"], ch["G"], ch["B"]], -1).astype(np.float64)


def test_bake_materials_operator_and_live_colour_edit(fresh_scene, tmp_path,
                                                     tmp_path_factory):
    import bpy

    import relightable_textures
    from relightable_textures import samples
    from relightable_textures.operators.bakes import material_bake as mb, material_edit as me
    from relightable_textures.operators.base.meshes import color_attribute

    scene = fresh_scene
    samples.build("room", scene, "test")
    names = ("Floor", "WallLeft", "WallRight", "WallBack", "Box")
    relightable_textures.register()
    try:
        props = scene.relight
        props.output_dir = str(tmp_path)
        props.material_samples, props.material_directions = 16, 16
        props.material_one_directions = props.material_two_directions = 4
        props.material_anchor_directions = 4
        red = bpy.data.materials["RedMaterial"]
        view_layer = bpy.context.view_layer
        # an object of the user's that shares the floor's material and is not baked (issue
        # 57): its EEVEE render must stay its own, and a camera that sees only it
        floor_mat = bpy.data.objects["Floor"].material_slots[0].material
        other = bpy.data.objects.new("Other", bpy.data.objects["Box"].data.copy())
        other.data.materials.clear()
        other.data.materials.append(floor_mat)
        other.location = (40.0, 0.0, 0.0)
        scene.collection.objects.link(other)
        cam = bpy.data.objects.new("OtherCam", bpy.data.cameras.new("OtherCam"))
        cam.location, cam.rotation_euler = (40.0, -6.0, 1.5), (1.45, 0.0, 0.0)
        scene.collection.objects.link(cam)
        renders = tmp_path_factory.mktemp("renders")     # the bake folder stays the bake's
        other_before = _render_alone(scene, cam, renders / "other-before.exr")
        assert other_before.mean() > 0.005
        for o in bpy.data.objects:
            o.select_set(o.name in names)
        view_layer.objects.active = bpy.data.objects["Floor"]
        # nothing editable: one clear error, nothing baked
        with pytest.raises(RuntimeError, match="mark at least one material Editable"):
            bpy.ops.relight.bake_materials()
        assert not any(tmp_path.iterdir())
        red.relight_editable = True
        assert bpy.ops.relight.bake_materials() == {"FINISHED"}
        assert (tmp_path / "Floor_materials.npz").is_file()
        assert "Baked 5 objects, 350 vertices" in scene[me.SUMMARY_KEY]
        ((first, tensors),) = me.scene_bakes(scene)
        assert first.name == "Floor" and tensors.regions == ["RedMaterial"]
        assert me.preview_light(scene) is not None   # the sample's (hidden) Sun lamp

        # the active object first, then the other selected meshes by name
        assert [n for n, _ in tensors.objects] == ["Floor", "Box", "WallBack", "WallLeft",
                                                   "WallRight"]

        def shown():   # stacked like the tensors' vertices
            return np.concatenate([color_attribute(
                bpy.data.objects[n].data.color_attributes[me.ATTRIBUTE])[:, :3]
                for n, _ in tensors.objects])

        from relightable_textures.operators.base.direct_rays import exact_direct

        def want(edits):   # the Sun's direct light from a shadow ray per vertex
            lamp = me.preview_light(scene)
            return tensors.shade(lamp, edits, direct=exact_direct(scene, tensors, lamp,
                                                                  everywhere=False))

        np.testing.assert_allclose(shown(), want({}), rtol=1e-5, atol=1e-7)
        # every receiver's material shows the preview in EEVEE (its output of target EEVEE);
        # the user's own output stays the active one, what Cycles renders (issue 57)
        for n in names:
            mat = bpy.data.objects[n].material_slots[0].material
            outs = [x for x in mat.node_tree.nodes if x.bl_idname == "ShaderNodeOutputMaterial"]
            (ours,) = [x for x in outs if x.get("relight_preview")]
            assert ours.get("relight_preview_kind") == mb.KIND and ours.target == "EEVEE"
            assert [x.is_active_output for x in outs if not x.get("relight_preview")] == [True]
        # the object that shares the floor's material and was not baked keeps its own look:
        # the preview is gated by a mark only the receivers carry
        from relightable_textures.operators.preview import preview_nodes as pn
        assert all(bpy.data.objects[n].get(pn.RECEIVER) == 1.0 for n in names)
        assert pn.RECEIVER not in other
        other_after = _render_alone(scene, cam, renders / "other-after.exr")
        assert np.abs(other_after - other_before).max() < 1e-4
        other[pn.RECEIVER] = 1.0           # marked, it shows the preview (no attribute: black)
        gated_off = _render_alone(scene, cam, renders / "other-marked.exr")
        del other[pn.RECEIVER]
        assert np.abs(gated_off - other_before).max() > 0.01
        before = shown().copy()
        # a colour edit in the material re-shades through the depsgraph handler
        socket = mb.material_colour_socket(red)
        socket.default_value = (0.1, 0.2, 0.9, 1.0)
        view_layer.update()
        after = shown()
        np.testing.assert_allclose(after, want({"RedMaterial": (0.1, 0.2, 0.9)}), rtol=1e-5,
                                   atol=1e-7)
        sl = tensors.object_slices()
        # the floor took on less red and more blue from the wall; the box too
        assert after[sl["Floor"], 0].sum() < before[sl["Floor"], 0].sum()
        assert after[sl["Floor"], 2].sum() > before[sl["Floor"], 2].sum()
        # moving the Sun re-shades too
        sun = next(o for o in scene.objects if o.type == "LIGHT")
        sun.rotation_euler[2] += 0.5
        view_layer.update()
        np.testing.assert_allclose(shown(), want({"RedMaterial": (0.1, 0.2, 0.9)}),
                                   rtol=1e-5, atol=1e-7)
        assert not np.allclose(shown(), after)
        # Remove Preview on every receiver: no preview node and no receiver mark is left
        for n in names:
            view_layer.objects.active = bpy.data.objects[n]
            assert bpy.ops.relight.remove_preview() == {"FINISHED"}
        assert not [o.name for o in bpy.data.objects if pn.RECEIVER in o]
        assert not [m.name for m in bpy.data.materials if m.node_tree is not None
                    and any(x.get("relight_preview") for x in m.node_tree.nodes)]
    finally:
        relightable_textures.unregister()


def test_panel_bake_with_roughness_anchors_follows_a_metallic_edit(fresh_scene, tmp_path):
    """Roughness Anchors in the panel bake glossy anchors; the Principled wall's Metallic and
    Roughness then re-shade the preview live, as the tensors' own shading of that finish."""
    import bpy

    import relightable_textures
    from relightable_textures import samples
    from relightable_textures.operators.bakes import material_bake as mb, material_edit as me
    from relightable_textures.operators.base.direct_rays import exact_direct
    from relightable_textures.operators.base.meshes import color_attribute
    from relightable_textures.samples.scene_setup import make_principled

    scene = fresh_scene
    samples.build("room", scene, "test")
    red = bpy.data.materials["RedMaterial"]
    make_principled(red)
    names = ("Floor", "WallLeft", "WallRight", "WallBack", "Box")
    relightable_textures.register()
    try:
        props = scene.relight
        props.output_dir = str(tmp_path)
        props.material_samples, props.material_directions = 16, 16
        props.material_one_directions = props.material_two_directions = 4
        props.material_anchor_directions = 4
        props.material_bounces = 1
        props.material_anchors = "0.3, x"
        for o in bpy.data.objects:
            o.select_set(o.name in names)
        bpy.context.view_layer.objects.active = bpy.data.objects["Floor"]
        red.relight_editable = True
        with pytest.raises(RuntimeError, match="roughness anchors must be numbers"):
            bpy.ops.relight.bake_materials()
        props.material_anchors = "0.3, 0.7"
        assert bpy.ops.relight.bake_materials() == {"FINISHED"}
        ((_, tensors),) = me.scene_bakes(scene)
        assert tensors.roughness == (0.3, 0.7)
        # Cycles: the direct light's check (8 of its 16 directions) and 2 anchors x 4
        # directions; the direct light and the bounces by rays
        assert tensors.metadata["bake_calls"] == 8 + 4 * 2
        assert tensors.metadata["direct"]["engine"] == "rays"
        assert tensors.metadata["gather"]["rays_per_origin"] == props.material_rays == 512

        def shown():
            return np.concatenate([color_attribute(
                bpy.data.objects[n].data.color_attributes[me.ATTRIBUTE])[:, :3]
                for n, _ in tensors.objects])

        def want(finish):
            lamp = me.preview_light(scene)
            return tensors.shade(lamp, {}, direct=exact_direct(scene, tensors, lamp,
                                                               everywhere=False), finish=finish)

        knobs = mb.finish_sockets(red)
        before = shown().copy()
        np.testing.assert_allclose(before, want({"RedMaterial": (0.0, 0.5)}), rtol=1e-5,
                                   atol=1e-7)
        knobs["metallic"].default_value = 1.0
        knobs["roughness"].default_value = 0.4
        bpy.context.view_layer.update()
        after = shown()
        np.testing.assert_allclose(after, want({"RedMaterial": (1.0, 0.4)}), rtol=1e-5,
                                   atol=1e-7)
        sl = tensors.object_slices()
        assert np.abs(after[sl["WallLeft"]]).max() == 0      # a metal has no diffuse colour
        assert not np.allclose(after[sl["Floor"]], before[sl["Floor"]])
    finally:
        relightable_textures.unregister()
