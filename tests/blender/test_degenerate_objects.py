"""Objects that bake nothing are refused in one line naming them (issue 56): a mesh whose faces
have no area baked an all-zero texture with exit 0 and no warning; a UV map with every UV on one
point ended in a raw ``ValueError`` from the gathered bounces. Real ``relight`` runs on .blend
files built here with bpy (a quad, a Sun)."""

import subprocess
import sys

import pytest

from relight_cli import assert_refused

_MAKE = r'''
import bpy, sys
kind, path = sys.argv[-2:]
bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
sc = bpy.context.scene
me = bpy.data.meshes.new("M")
line = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)]
quad = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
me.from_pydata(line if kind == "flat" else quad, [], [(0, 1, 2, 3)])
uv = me.uv_layers.new(name="UVMap")
corners = {"flat": [(0, 0), (1, 0), (1, 1), (0, 1)], "uv-point": [(0.5, 0.5)] * 4,
           "tiny-uv": [(0.51, 0.51), (0.511, 0.51), (0.511, 0.511), (0.51, 0.511)]}[kind]
for loop, c in zip(uv.data, corners):
    loop.uv = c
ob = bpy.data.objects.new("Thing", me)
sc.collection.objects.link(ob)
sc.collection.objects.link(bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN")))
sc.render.engine = "CYCLES"
bpy.ops.wm.save_as_mainfile(filepath=path)
'''


@pytest.mark.parametrize("kind, message", [
    ("flat", "Thing: its faces have no area"),
    ("uv-point", "Thing: its UV map covers no area"),
    ("tiny-uv", "Thing: its UV map covers no texel centre at 16^2"),
])
def test_an_object_that_bakes_nothing_is_refused_in_one_line(tmp_path, kind, message):
    blend = tmp_path / f"{kind}.blend"
    subprocess.run([sys.executable, "-c", _MAKE, kind, str(blend)], check=True,
                   capture_output=True, timeout=120)
    out = tmp_path / "bk"
    out.mkdir()
    assert_refused(out, message, "bake-textures", blend, "--object", "Thing", "--preset",
                   "draft", "--resolution", "16", "--out", out, "--force")
    assert list(out.iterdir()) == []


_NAMES = r'''
import bpy, sys
path = sys.argv[-1]
bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
sc = bpy.context.scene
sc.render.engine = "CYCLES"
bpy.ops.mesh.primitive_plane_add()
bpy.context.active_object.name = "Thing"
sc.collection.objects.link(bpy.data.objects.new("Inst", None))
props = bpy.data.collections.new("Props")
sc.collection.children.link(props)
me = bpy.data.meshes.new("H")
me.from_pydata([(0, 0, 1), (1, 0, 1), (1, 1, 1)], [], [(0, 1, 2)])
props.objects.link(bpy.data.objects.new("Hidden", me))
bpy.context.view_layer.layer_collection.children["Props"].exclude = True
bpy.ops.wm.save_as_mainfile(filepath=path)
'''


def test_objects_that_are_not_meshes_or_not_rendered_are_named_plainly(tmp_path):
    """Issue 59's small ones: an empty is "an empty", the hint for an unknown name lists only
    meshes a view layer renders (not one in an excluded collection), and a second object only in
    an excluded collection is said to be so (it was "not in scene")."""
    blend = tmp_path / "names.blend"
    subprocess.run([sys.executable, "-c", _NAMES, str(blend)], check=True, capture_output=True,
                   timeout=120)
    out = tmp_path / "bk"
    out.mkdir()
    base = ["bake-textures", blend, "--preset", "draft", "--resolution", "16", "--out", out]
    assert_refused(out, "Inst is an empty, not a mesh", *base, "--object", "Inst")
    r = assert_refused(out, "mesh objects: Thing", *base, "--object", "Nope")
    assert "Hidden" not in r.stderr
    assert_refused(out, "'Hidden' is only in collections excluded from view layer", *base,
                   "--object", "Thing", "--object", "Hidden")
