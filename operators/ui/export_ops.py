"""The panel's Export: the same job as ``relight export`` (bpy operators)."""

from __future__ import annotations

import os

import bpy

from .bake_ops import ModalBake
from ..base.cycles_bake import BakeInputError

#: Scene property holding the last export's summary lines, shown in the panel.
LAST_EXPORT_KEY = "relight_last_export"
#: The last RTI or sun-indirect export's page exported in this Blender session, for Open Web
#: Page: kept here, not in the .blend -- a page path a file carries (older versions saved it
#: as the scene property ``relight_last_export_page``) is never opened.
_SESSION_PAGE: dict = {}


def remember_page(path: str) -> None:
    """Keep ``path`` as the page this session exported last."""
    _SESSION_PAGE["page"] = os.path.abspath(path)


def last_export_page() -> str | None:
    """The page this session exported last, while it is still an ``.html`` regular file (not a
    link: lstat) at that path; else None."""
    import stat

    page = _SESSION_PAGE.get("page")
    if not page or not page.lower().endswith(".html"):
        return None
    try:
        return page if stat.S_ISREG(os.lstat(page).st_mode) else None
    except OSError:
        return None


def open_url(url: str) -> None:
    """Open ``url`` (a file:// URL of an exported .html page) in the web browser."""
    bpy.ops.wm.url_open(url=url)


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
    failure_word = "Export"

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
            remember_page(os.path.join(result.files["folder"], "index.html"))
        elif rep["format"] == "sun-indirect":
            what = (f"{rep['components']} basis lightmaps, {err:.1%} relative RMS at "
                    f"{rep['held_out_suns']} held-out suns")
            remember_page(result.files["page"])
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
    """Open the web page of the last RTI or sun-indirect export of this session in the web
    browser"""

    bl_idname = "relight.open_export_page"
    bl_label = "Open Web Page"

    @classmethod
    def poll(cls, context):
        return last_export_page() is not None

    def execute(self, context):
        import pathlib

        page = last_export_page()
        if page is None:
            self.report({"ERROR"}, "no web page exported in this session: Export first")
            return {"CANCELLED"}
        open_url(pathlib.Path(page).as_uri())
        return {"FINISHED"}


CLASSES = (RELIGHT_OT_export, RELIGHT_OT_open_export_page)
