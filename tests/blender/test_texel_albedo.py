"""The bake's albedo is each texel's mean colour, as a converged Cycles bake averages a texture
finer than a texel (texture_transport.ALBEDO_SAMPLES), not the colour at its centre.

Reference: Cycles' own 256-spp colour bake of the same texture (the texel's mean). Measured
2026-12-07 with bpy 5.0.1 on this checker (squares of 0.7 texels) at 32^2: the bake's albedo
(16 spp) 0.069 from it; Cycles' 1-spp colour bake (what the bake used before) 0.43. The bar,
0.12, is under a third of the centre's distance.
"""

import numpy as np


def test_a_checker_finer_than_a_texel_is_averaged(fresh_scene, tmp_path):
    import bpy

    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.bakes.texture_transport import (
        TransportTextureSettings, bake_transport_textures)
    from relightable_textures.samples.scene_setup import diffuse_material

    R = 32
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.active_object
    mat = diffuse_material("Checker", (0.5, 0.5, 0.5))
    nodes = mat.node_tree.nodes
    checker = nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 45.0            # 0.7 texels a square
    checker.inputs["Color1"].default_value = (0.9, 0.8, 0.7, 1.0)
    checker.inputs["Color2"].default_value = (0.1, 0.15, 0.2, 1.0)
    mat.node_tree.links.new(checker.outputs["Color"], nodes["Diffuse BSDF"].inputs["Color"])
    plane.data.materials.append(mat)
    ref = {}
    for spp in (1, 256):
        with EnvironmentBake(fresh_scene, [plane], R, spp, 0, (8, 16), mode="irradiance",
                             world_sampling="none", passes="color") as session:
            ref[spp] = session.bake_all(np.zeros((8, 16), np.float32))[0]
    s = TransportTextureSettings(directions="hemi:24:1.5", resolution=R, bounces=0,
                                 model="none", texel_sampling="centre")
    gen = bake_transport_textures(fresh_scene, [plane], s, str(tmp_path / "b"), resume=False)
    try:
        while True:
            next(gen)
    except StopIteration as stop:
        res = stop.value
    albedo = np.asarray(res.objects[0].albedo, np.float64)
    for b in res.objects:
        b.store.abort()

    def rel(a):
        return float(np.linalg.norm(a - ref[256]) / np.linalg.norm(ref[256]))

    assert rel(ref[1]) > 0.3                   # the centre is not the texel here
    assert rel(albedo) < 0.12, rel(albedo)
