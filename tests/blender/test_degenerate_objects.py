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
