"""The preview node group in EEVEE (software EGL here): 49 atlas lookups through one sampler
compile and compute the same numbers as NumPy. Tiny (16^2), and the pixels are checked: EEVEE
can fail silently.

Interpolation is set to Closest for the check so each pixel reads exactly its texel: with
Linear, EEVEE's own pixel sample positions and texture filtering differ from Cycles' at tile
scale (measured: image mean equal to 0.04%, single pixels up to 24% of the peak at 16^2)."""

import numpy as np
from render_check import render_rgb

from relightable_textures import samples
from relightable_textures.lt_addon.hemisphere import direction_from_az_el


def test_eevee_renders_the_preview_group_like_numpy(fresh_scene, tmp_path):
    import bpy

    from relightable_textures.operators import compat, preview_nodes, steerable_bake as sb

    samples.build("bumps", fresh_scene, "test")
    obj = bpy.data.objects["Bumps"]
    r = 16
    s = sb.TextureBakeSettings(order=7, resolution=r, samples=16, bounces=1, storage="float")
    result = sb.run(sb.bake_steerable_texture(fresh_scene, obj, s))
    report = sb.write_bake(result, obj, str(tmp_path), s)
    info = preview_nodes.install_preview(fresh_scene, obj, report["exr"], result.texture)
    group = bpy.data.node_groups[info["group"]]
    lookups = [n for n in group.nodes if n.bl_idname == "ShaderNodeTexImage"]
    assert len(lookups) == 49 and len({n.image.name for n in lookups}) == 1  # one sampler
    for n in lookups:
        n.interpolation = "Closest"
    fresh_scene["relight_azimuth"], fresh_scene["relight_elevation"] = 40.0, 35.0
    img = render_rgb(fresh_scene, tmp_path, r, engine=compat.EEVEE_ENGINE)
    want = result.texture.relight(direction_from_az_el(40.0, 35.0)).astype(np.float64)
    assert want.max() > 0.1
    assert np.abs(img - want).max() <= 2.0 ** -10 * want.max()  # half-float atlas precision
