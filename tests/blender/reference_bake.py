"""The tiny stored reference bake: bumps at test size, order 3, 16^2, 64 spp, 1 bounce, seed 0."""

import os

REFERENCE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data",
                         "bumps_tiny_reference.exr")
SETTINGS = dict(order=3, resolution=16, samples=64, bounces=1, env_height=32, storage="half")


def bake_reference():
    import bpy

    from relightable_textures import samples
    from relightable_textures.operators import steerable_bake as sb

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    samples.build("bumps", bpy.context.scene, "test")
    settings = sb.TextureBakeSettings(**SETTINGS)
    return sb.run(sb.bake_steerable_texture(bpy.context.scene, bpy.data.objects["Bumps"],
                                            settings)).texture
