"""The panel's Export: the same job as ``relight export`` (bpy operators)."""

from __future__ import annotations

import os

import bpy

from .bake_ops import ModalBake
from ..base.cycles_bake import BakeInputError

#: Scene property holding the last export's summary lines, shown in the panel.
LAST_EXPORT_KEY = "relight_last_export"
#: Scene property holding the last RTI export's page, for Open Web Page.
LAST_PAGE_KEY = "relight_last_export_page"


def settings_from_scene(scene):
    """ExportSettings from the panel's properties and the Preview Light sliders."""
    from ..bakes.export import LIGHTMAPS, ExportSettings

    props = scene.relight
    fmt = props.export_format
    kw = {}
    if fmt in LIGHTMAPS:
        if props.export_light == "ENV":
            if not props.export_env:
                raise BakeInputError("choose an environment EXR (or light it by the Preview "
                                     "Light)")
            env = bpy.path.abspath(props.export_env)
            if not os.path.isfile(env):
                raise BakeInputError(f"environment not found: {env}")
            kw.update(env=env, rotate=props.export_env_rotation)
        else:
            kw.update(sun=(float(scene.get("relight_azimuth", 30.0)),
                           float(scene.get("relight_elevation", 45.0))),
                      strength=float(scene.get("relight_intensity", 1.0)),
                      color=tuple(scene.get("relight_color", (1.0, 1.0, 1.0)))[:3])
    return ExportSettings(format=fmt, terms=int(props.export_terms) if fmt == "rti-hsh"
                          else None, godot=props.export_godot, **kw)


class RELIGHT_OT_export(ModalBake, bpy.types.Operator):
    """Export the active object's transport-texture bake as an RTI model with a relightable
    web page, or as a directional lightmap for a game engine, and report its error against
    our own relight (Esc cancels)"""

    bl_idname = "relight.export"
    bl_label = "Export"
    bl_options = {"REGISTER"}

    def _prepare(self, context):
        from ..bakes.export import export_job

        settings = settings_from_scene(context.scene)
        settings.validate()
        stage = self._make_out_dir(context.scene.relight)
        return export_job(context.scene, context.active_object, settings, stage,
                          force=context.scene.relight.export_force)

    def _finish(self, context, result):
        rep = result.report
        err = rep["error_vs_our_relight"]
        if rep["format"].startswith("rti"):
            what = (f"RMSE {err['rmse_mean']:.3f} ({err['psnr_mean_db']:.1f} dB) at "
                    f"{err['held_out_lights']} held-out lights")
            page = os.path.join(result.files["folder"], "index.html")
            context.scene[LAST_PAGE_KEY] = page
        elif rep["format"] == "sun-indirect":
            what = (f"{rep['components']} basis lightmaps, {err:.1%} relative RMS at "
                    f"{rep['held_out_suns']} held-out suns")
            context.scene[LAST_PAGE_KEY] = result.files["page"]
        else:
            what = "irradiance error " + ", ".join(
                f"{v:.3f}" for v in err.values() if v is not None) + " at 0/15/30/45 deg tilts"
        lines = [f"Exported {rep['object']} as {rep['format']}: {rep['bytes_per_texel']} B per "
                 f"texel, {rep['timings']['wall_total']:.1f} s",
                 f"vs our relight: {what}"]
        for line in lines:
            self.report({"INFO"}, line)
        context.scene[LAST_EXPORT_KEY] = "\n".join(lines)


class RELIGHT_OT_open_export_page(bpy.types.Operator):
    """Open the last RTI or sun-indirect export's web page in the system browser"""

    bl_idname = "relight.open_export_page"
    bl_label = "Open Web Page"

    @classmethod
    def poll(cls, context):
        page = context.scene.get(LAST_PAGE_KEY)
        return bool(page) and os.path.isfile(page)

    def execute(self, context):
        page = context.scene[LAST_PAGE_KEY]
        bpy.ops.wm.url_open(url="file://" + page)
        return {"FINISHED"}


CLASSES = (RELIGHT_OT_export, RELIGHT_OT_open_export_page)
