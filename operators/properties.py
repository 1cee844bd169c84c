"""Scene-level settings of the extension (``scene.relight``)."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, PointerProperty

from ..samples import DESCRIPTIONS, SIZES


class RelightSceneSettings(bpy.types.PropertyGroup):
    """Settings shown in the Relight sidebar tab."""

    sample_name: EnumProperty(
        name="Sample",
        description="Sample scene to add",
        items=[(k, k.capitalize(), v) for k, v in DESCRIPTIONS.items()],
        default="bumps",
    )
    sample_size: EnumProperty(
        name="Size",
        description="Sample scene size",
        items=[(s, s.capitalize(), f"{s} size") for s in SIZES],
        default="test",
    )


CLASSES = (RelightSceneSettings,)


def register() -> None:
    bpy.types.Scene.relight = PointerProperty(type=RelightSceneSettings)


def unregister() -> None:
    del bpy.types.Scene.relight
