"""The tiny stored reference bake: bumps at test size, order 3, 16^2, 64 spp, 1 bounce, seed 0."""

import os

_DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data")
#: Baked with Blender 5.0.1 (4.5 LTS reproduces it to 0.02%).
REFERENCE = os.path.join(_DATA, "bumps_tiny_reference.exr")
#: Baked with Blender 5.2.3: from 5.1 on Cycles draws other samples from the same seed (4-7% RMS
#: from the 5.0.1 bake, like another seed), so those versions keep a reference of their own.
REFERENCE_52 = os.path.join(_DATA, "bumps_tiny_reference_5.2.exr")


def reference_for(version: tuple) -> str:
    """The stored reference that this Blender's Cycles (``bpy.app.version``) must reproduce."""
    return REFERENCE_52 if tuple(version) >= (5, 1, 0) else REFERENCE
SETTINGS = dict(order=3, resolution=16, samples=64, bounces=1, env_height=32, storage="half")


def bake_reference():
    import bpy

    from relightable_textures import samples
    from relightable_textures.operators.bakes import steerable_bake as sb

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    samples.build("bumps", bpy.context.scene, "test")
    settings = sb.TextureBakeSettings(**SETTINGS)
    return sb.run(sb.bake_steerable_texture(bpy.context.scene, bpy.data.objects["Bumps"],
                                            settings)).texture
