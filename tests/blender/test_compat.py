"""operators/base/compat.py on the running Blender (the suite runs on 5.0.1 in `make test`, on the
newest 3.13 bpy in CI's matrix, and was run on 4.2 / 4.5): the same calls work on every
version, without deprecation or blend-relative warnings."""

import warnings

import pytest

#: Also run on 5.2 LTS by the matrix: every branch of operators/base/compat.py.
pytestmark = pytest.mark.version_sensitive


def test_new_material_and_world_have_their_default_nodes(fresh_scene):
    import bpy

    from relightable_textures.operators.base.compat import ensure_node_tree

    mat, world = bpy.data.materials.new("M"), bpy.data.worlds.new("W")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # Blender 5: reading/writing use_nodes warns
        mat_tree, world_tree = ensure_node_tree(mat), ensure_node_tree(world)
        assert ensure_node_tree(mat) == mat_tree  # idempotent
    assert mat_tree == mat.node_tree and world_tree == world.node_tree
    assert "Principled BSDF" in mat_tree.nodes and "Material Output" in mat_tree.nodes
    assert "Background" in world_tree.nodes


def test_output_dir_takes_a_blend_relative_path_without_warning(fresh_scene):
    import relightable_textures

    relightable_textures.register()
    try:
        props = fresh_scene.relight
        assert props.output_dir == ""   # the default folder, <file>_relight (issue 57)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # Blender 5 warns for '//' unless the flag is set
            props.output_dir = "//elsewhere/"
        assert props.output_dir == "//elsewhere/"
    finally:
        relightable_textures.unregister()
