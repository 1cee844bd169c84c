"""Scene-level settings of the extension (``scene.relight``)."""

from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..lt_addon.steerable_texture import STORAGE_MODES
from ..samples import DESCRIPTIONS, SIZES
from .presets import PRESETS, settings_from_preset

_SETTING_NAMES = ("frame", "order", "resolution", "samples", "bounces", "storage", "mode",
                  "world_sampling")


def _apply_preset(self, context):
    preset = settings_from_preset(self.preset)
    for name in _SETTING_NAMES:
        setattr(self, name, getattr(preset, name))


def _sun_poll(self, obj):
    return obj.type == "LIGHT" and obj.data.type == "SUN"


class RelightSceneSettings(bpy.types.PropertyGroup):
    """Settings shown in the Relight sidebar tab."""

    sample_name: EnumProperty(
        name="Sample", description="Sample scene to add",
        items=[(k, k.capitalize(), v) for k, v in DESCRIPTIONS.items()], default="bumps")
    sample_size: EnumProperty(
        name="Size", description="Sample scene size",
        items=[(s, s.capitalize(), f"{s} size") for s in SIZES], default="test")

    preset: EnumProperty(
        name="Preset", description="Starting values for the bake settings (measured by make bench)",
        items=[(k, k.capitalize(), "") for k in PRESETS], default="balanced", update=_apply_preset)
    frame: EnumProperty(
        name="Frame", default="world", items=[
            ("world", "World", "Relight the object by a distant light over the world's upper "
                               "hemisphere"),
            ("tangent", "Tangent", "A tileable patch relit per pixel in a surface's UV tangent "
                                   "frame")])
    order: IntProperty(name="Order", description="Basis order N1: N = N1^2 Cycles bakes",
                       default=7, min=2, max=12)
    resolution: IntProperty(name="Resolution", description="Texture side in texels",
                            default=256, min=8, max=8192)
    samples: IntProperty(name="Samples", description="Cycles samples per texel per bake",
                         default=64, min=1, max=65536)
    bounces: IntProperty(name="Bounces", description="Diffuse bounces (0 = direct only)",
                         default=2, min=0, max=64)
    storage: EnumProperty(name="Storage", default="half",
                          items=[(s, s, "") for s in STORAGE_MODES])
    mode: EnumProperty(name="Bake", default="radiance", items=[
        ("radiance", "Radiance", "Albedo x light with interreflection (the paper)"),
        ("irradiance", "Light only", "Light without the albedo, so the albedo stays editable")])
    world_sampling: EnumProperty(name="World Sampling", default="importance", items=[
        ("importance", "Importance", "Lower noise at equal samples"),
        ("none", "None", "BSDF sampling only: exactly linear in the light")])
    output_dir: StringProperty(
        name="Output", subtype="DIR_PATH", default="//relight/",
        description="Folder for the EXR files and the JSON report ('//' = next to the .blend)")
    sun: PointerProperty(name="Sun", type=bpy.types.Object, poll=_sun_poll,
                         description="Sun lamp whose direction the preview follows")


CLASSES = (RelightSceneSettings,)


def settings_from_scene(props):
    """TextureBakeSettings from the panel's properties."""
    from .steerable_bake import TextureBakeSettings

    return TextureBakeSettings(**{name: getattr(props, name) for name in _SETTING_NAMES})


def register() -> None:
    bpy.types.Scene.relight = PointerProperty(type=RelightSceneSettings)


def unregister() -> None:
    del bpy.types.Scene.relight

