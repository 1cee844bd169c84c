"""The panel's Run On: Dask (issue 15): Bake Materials run through the real ``relight`` console
script on a real local cluster of 2 workers gives the in-process panel bake's tensors bit for
bit; interrupting that command (the job closed, as Esc does) keeps its finished chunks and the
next Bake resumes from them; an unsaved file and a missing command are one clear error. The
Relight Command is the add-on's preferences' (test_untrusted_blend_records.py: never the
.blend's)."""

import json
import os

import numpy as np
import pytest
from relight_cli import BIN

NAMES = ("Floor", "Box")


@pytest.fixture
def room(fresh_scene, tmp_path):
    """The test room saved to disk, Floor active with Box selected, the red and green walls
    editable, small direction sets; the extension registered."""
    import bpy

    import relightable_textures
    from relightable_textures import samples

    samples.build("room", fresh_scene, "test")
    relightable_textures.register()
    props = fresh_scene.relight
    props.material_samples, props.material_directions = 8, 40
    props.material_one_directions, props.material_two_directions = 20, 4
    props.material_anchor_directions = 20
    for name in ("RedMaterial", "GreenMaterial"):
        bpy.data.materials[name].relight_editable = True
    for o in bpy.data.objects:
        o.select_set(o.name in NAMES)
    bpy.context.view_layer.objects.active = bpy.data.objects["Floor"]
    path = tmp_path / "room.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    try:
        yield fresh_scene, path
    finally:
        entry = bpy.context.preferences.addons.get(relightable_textures.__name__)
        if entry is not None:
            bpy.context.preferences.addons.remove(entry)
        relightable_textures.unregister()


def _relight_command(path):
    """Set the Relight Command in the add-on's preferences (an entry as an enabled extension
    has; registered from a path there is none)."""
    import bpy

    import relightable_textures

    addons = bpy.context.preferences.addons
    entry = addons.get(relightable_textures.__name__)
    if entry is None:
        entry = addons.new()
        entry.module = relightable_textures.__name__
    entry.preferences.relight_command = str(path)


def _tensors(folder):
    from relightable_textures.lt_addon.transport import ptt

    return ptt.TransferTensors.load(str(folder / "Floor_materials.npz"))


def _same(a, b):
    return all(np.array_equal(getattr(a, k).view(np.uint8), getattr(b, k).view(np.uint8))
               for k in ("direct", "one", "two") + (("gloss",) if a.roughness else ()))


def test_bake_materials_on_dask_workers_from_the_panel(room, tmp_path):
    import bpy

    scene, path = room
    props = scene.relight
    props.material_anchors = "0.5"   # glossy anchor chunks travel to the workers too
    props.output_dir = str(tmp_path / "here")
    assert bpy.ops.relight.bake_materials() == {"FINISHED"}
    here = _tensors(tmp_path / "here")
    assert here.roughness == (0.5,) and here.gloss.any()

    props.output_dir = str(tmp_path / "dask")
    props.run_on, props.dask_workers = "WORKERS", 2
    _relight_command(tmp_path / "nowhere" / "relight")
    bpy.ops.wm.save_mainfile()
    with pytest.raises(RuntimeError, match="is not an executable file: set the Relight Command "
                                           "in Preferences"):
        bpy.ops.relight.bake_materials()
    _relight_command(BIN / "relight")
    assert not (tmp_path / "dask").exists()
    bpy.ops.wm.save_mainfile()   # (background Blender flags every file dirty: no check here)
    assert bpy.ops.relight.bake_materials() == {"FINISHED"}
    rep = json.loads((tmp_path / "dask" / "Floor_materials.json").read_text())
    # Cycles' check of the direct light by rays (8 of its 40 directions: 1 chunk), 2 glossy
    # per editable region (2) and 2 of bounce rays (378 origins, 256 a chunk)
    assert rep["distributed"]["chunks"] == rep["chunks_total"] == 1 + 4 + 2
    assert len(rep["distributed"]["workers"]) == 2
    assert _same(_tensors(tmp_path / "dask"), here)
    # the command saved the bake into the file: reopened, it is recorded there
    bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    from relightable_textures.operators.bakes import material_edit as me

    ((first, tensors),) = me.scene_bakes(bpy.context.scene)
    assert first.name == "Floor" and _same(tensors, here)
    from relightable_textures.operators.farm import external_bake as eb
    from relightable_textures.operators.base.cycles_bake import BakeInputError

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with pytest.raises(BakeInputError, match="save the .blend first"):
        eb.saved_blend()


def test_an_interrupted_dask_bake_keeps_its_chunks_and_the_next_bake_resumes(room, tmp_path):
    import bpy

    from relightable_textures.operators.farm import external_bake as eb

    scene, path = room
    props = scene.relight
    props.output_dir, props.run_on, props.dask_workers = str(tmp_path / "o"), "WORKERS", 2
    _relight_command(BIN / "relight")
    bpy.ops.wm.save_mainfile()
    cmd = [str(BIN / "relight"), "bake-materials", str(path), "--object", "Floor", "--object",
           "Box", "--region", "RedMaterial", "--region", "GreenMaterial", "--directions",
           "hemi:40:1.5", "--one-bounce-directions", "hemi:20", "--two-bounce-directions",
           "hemi:4", "--samples", "8", "--out", str(tmp_path / "o"), "--workers", "2"]
    job = eb.external_job(cmd, str(path))
    for step in job:                  # progress lines of the command: chunks finishing
        if step.done >= 40:
            break
    job.close()                       # Esc: SIGINT, the command keeps its chunks and exits
    kept = list((tmp_path / "o").glob(".relight_cache/Floor_materials/*/*_0*.npy"))
    assert kept and not (tmp_path / "o" / "Floor_materials.npz").exists()
    assert bpy.ops.relight.bake_materials() == {"FINISHED"}
    rep = json.loads((tmp_path / "o" / "Floor_materials.json").read_text())
    # the direct light's Cycles check (1 chunk) and 2 of bounce rays: the direct light by rays
    # is not a chunk (seconds)
    assert rep["chunks_total"] == 3 and rep["chunks_reused"] >= len(kept) > 0
    assert not os.path.exists(tmp_path / "o" / ".relight_cache")
