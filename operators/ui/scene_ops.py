"""Operators that manage scenes (bpy)."""

from __future__ import annotations

import bpy

from ... import samples


class RELIGHT_OT_add_sample_scene(bpy.types.Operator):
    """Add one of the paper sample scenes to this file as a new scene"""

    bl_idname = "relight.add_sample_scene"
    bl_label = "Add Sample Scene"
    bl_options = {"REGISTER", "UNDO"}

    name: bpy.props.EnumProperty(
        name="Sample",
        items=[(k, k.capitalize(), v) for k, v in samples.DESCRIPTIONS.items()],
        default="bumps",
    )
    size: bpy.props.EnumProperty(
        name="Size", items=[(s, s.capitalize(), "") for s in samples.SIZES], default="demo")

    def execute(self, context):
        scene = bpy.data.scenes.new(f"{self.name}-{self.size}")
        try:
            info = samples.build(self.name, scene, self.size)
        except Exception as exc:  # leave the file as it was
            bpy.data.scenes.remove(scene)
            self.report({"ERROR"}, f"Could not build sample {self.name}: {exc}")
            return {"CANCELLED"}
        if context.window is not None:
            context.window.scene = scene
        self.report({"INFO"}, f"Added scene {scene.name} (relight object {info['relight_object']})")
        return {"FINISHED"}


CLASSES = (RELIGHT_OT_add_sample_scene,)
