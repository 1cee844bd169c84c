"""The panel's *Sun Study Map*: show a ``relight sun-study`` folder's maps on the objects
(bpy; :mod:`..preview.sun_study_preview`)."""

from __future__ import annotations

import bpy


class RELIGHT_OT_show_sun_study(bpy.types.Operator):
    """Show the sun study's sunlight-hours (or radiation) map on the objects it names, in the
    false-colour ramp of its pictures, in Material Preview; Remove Preview takes it out"""

    bl_idname = "relight.show_sun_study"
    bl_label = "Show Sun Study Map"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ...lt_addon.io.untrusted import UntrustedFileError
        from ..preview import sun_study_preview
        from .bake_ops import show_in_viewport

        props = context.scene.relight
        folder = bpy.path.abspath(props.sun_study_folder) if props.sun_study_folder else ""
        if not folder:
            self.report({"ERROR"}, "choose the folder relight sun-study wrote (Study)")
            return {"CANCELLED"}
        try:
            info = sun_study_preview.show(context.scene, folder, props.sun_study_map)
        except (UntrustedFileError, ValueError, OSError) as exc:
            self.report({"ERROR"}, f"Sun study: {exc}")
            return {"CANCELLED"}
        if not props.show_preview:
            props.show_preview = True
        show_in_viewport(context)
        self.report({"INFO"}, f"{info['title']} on {', '.join(info['objects'])} (0 to "
                              f"{info['top']:g} {info['unit']}); Material Preview shows it")
        if info["not_in_scene"]:
            self.report({"WARNING"}, "not in this scene: " + ", ".join(info["not_in_scene"]))
        return {"FINISHED"}


CLASSES = (RELIGHT_OT_show_sun_study,)
