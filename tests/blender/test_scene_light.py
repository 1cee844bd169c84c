"""The bake takes the scene's own Light Paths and Sun unless told otherwise (issue 55).

Blender's default scene renders 4 diffuse bounces (Total 12) and its Sun is 0.526 degrees wide;
the bake used 2 bounces and a 2-degree Sun whatever the scene said, and its truths were rendered
with those, so its report could not see the difference. Now -1 (the default of --bounces and
--sun-angle) takes them from the scene; the report says what it took (``from_scene``) and its
truths render with them.
"""

import tempfile

import numpy as np
import pytest

from relightable_textures import samples


def _statue(diffuse, total, sun_deg=None):
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("statue", scene, "test")
    scene.cycles.diffuse_bounces, scene.cycles.max_bounces = diffuse, total
    for o in [o for o in scene.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(o)
    if sun_deg is not None:
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.angle = np.radians(sun_deg)
        scene.collection.objects.link(sun)
    bpy.context.view_layer.update()
    return scene


@pytest.mark.parametrize("diffuse, total, sun_deg, bounces, angle", [
    (3, 12, 0.526, 3, 0.526),      # Diffuse decides; Blender's default Sun
    (4, 1, None, 1, 2.0),          # Total caps it; no Sun: 2 degrees
])
def test_the_bake_takes_the_scenes_bounces_and_sun(diffuse, total, sun_deg, bounces, angle):
    import bpy

    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    scene = _statue(diffuse, total, sun_deg)
    s = tx.settings_from_preset("draft", directions="hemi:24", resolution=16,
                                indirect_resolution=8)
    assert s.bounces == -1 and s.sun_angle == -1
    ground = bpy.data.objects["Ground"]
    out = run(tx.bake_job(scene, [bpy.data.objects["Statue"], ground], s,
                          tempfile.mkdtemp(prefix="relight-scene-"), truth=1, truth_samples=8,
                          compare=False, preview=False))
    rep = out.reports[0]
    assert rep["settings"]["bounces"] == bounces
    assert rep["settings"]["sun_angle"] == pytest.approx(angle, abs=1e-3)
    assert rep["from_scene"]["bounces"] == bounces
    assert rep["from_scene"]["sun_angle"] == pytest.approx(angle, abs=1e-3)
    assert rep["from_scene"].get("no_sun", False) == (sun_deg is None)
    assert rep["indirect"]["bounces"] == bounces
    assert rep["ground_truth"]["sun_angle"] == pytest.approx(angle, abs=1e-3)


def test_given_bounces_win_over_the_scenes():
    import bpy

    from relightable_textures.operators.bakes import texture_transport as tx

    scene = _statue(4, 12)
    s, taken = tx.scene_light_settings(scene, tx.settings_from_preset("draft", bounces=2,
                                                                      sun_angle=10.0))
    assert (s.bounces, s.sun_angle, taken) == (2, 10.0, {})
    s, taken = tx.scene_light_settings(scene, tx.settings_from_preset("draft"))
    assert (s.bounces, s.sun_angle) == (4, 2.0) and taken["no_sun"]
