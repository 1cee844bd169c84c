"""The panel's *Sun Study Map*: show a ``relight sun-study`` folder's maps on the objects
(bpy; :mod:`..preview.sun_study_preview`)."""

from __future__ import annotations

import os

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


class RELIGHT_OT_run_sun_study(bpy.types.Operator):
    """Run a sun study on the selected meshes' transport bakes: the place and dates of Sun
    Study (Advanced, as the bake takes them), at Hours or every few minutes; writes its maps
    and sheets into a new sun_study-<time> folder in the bake's Output folder and shows the
    map (relight sun-study does the same from the command line)"""

    bl_idname = "relight.run_sun_study"
    bl_label = "Run Sun Study"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        import time

        from ... import __version__
        from ...lt_addon.errors import InputError
        from ...lt_addon.io.untrusted import UntrustedFileError
        from ...lt_addon.sun import study_directions as sd
        from ...lt_addon.sun.sun_study import StudySettings, clock_hours, run_study
        from ..base import sun_position
        from ..base.blend_files import bake_file
        from ..base.cycles_bake import BakeInputError
        from ..preview import sun_study_preview
        from .bake_ops import _output_dir, show_in_viewport

        scene, props = context.scene, context.scene.relight
        try:
            if not props.study.strip():
                raise InputError("fill Sun Study (Bake > Advanced) with the place and dates, "
                                 "e.g. 51.5,-0.13,Europe/London,2026-06-21,2026-12-21 or "
                                 "scene,2026-06-21 (the Sun Position add-on's place)")
            spec = sd.parse(props.study)
            if spec.from_scene:
                values = sun_position.read(scene)
                if values is None:
                    raise InputError("Sun Study says 'scene', but the scene holds no Sun "
                                     "Position settings: set a place in that add-on, or type "
                                     "LAT,LON,ZONE")
                spec = sd.with_place(spec, sd.place_from_sun_position(values))
            meshes = [o for o in context.selected_objects if o.type == "MESH"]
            reports = []
            for o in meshes:
                try:
                    reports.append(bake_file(o, "transport_texture", "transport-texture"))
                except ValueError:
                    continue
            if not reports:
                raise InputError("select the meshes to study, baked with the Transport method "
                                 "(and Sun Study filled, so the bake holds the study's suns)")
            step = props.sun_study_step or None
            settings = StudySettings(
                latitude=spec.latitude, longitude=spec.longitude, tz=spec.tz,
                dates=list(spec.dates),
                hours=None if step else clock_hours(props.sun_study_hours),
                step_minutes=step, north_deg=spec.north_deg or 0.0,
                elevation_m=spec.elevation_m,
                radiation=props.sun_study_radiation or bool(props.sun_study_weather),
                weather=(bpy.path.abspath(props.sun_study_weather)
                         if props.sun_study_weather else None))
            out = _new_folder(_output_dir(props), time.strftime("sun_study-%Y%m%d-%H%M%S"))
            report = run_study(reports, settings, out, version=__version__)
            which = ("radiation" if props.sun_study_map == "radiation"
                     and settings.radiation else "hours")
            props.sun_study_folder = out
            info = sun_study_preview.show(scene, out, which)
        except (InputError, BakeInputError, UntrustedFileError, ValueError,
                FileNotFoundError, OSError) as exc:
            self.report({"ERROR"}, f"Run Sun Study: {exc}")
            return {"CANCELLED"}
        if not props.show_preview:
            props.show_preview = True
        show_in_viewport(context)
        n = report["instants"]
        self.report({"INFO"}, f"Sun study of {', '.join(info['objects'])}: {n['count']} "
                              f"instants, the Sun up at {n['sun_up']} ({n['possible_h']:g} h); "
                              f"{report['timings']['total']:.1f} s; wrote {out}")
        for line in report["warnings"]:
            self.report({"WARNING"}, line)
        return {"FINISHED"}


def _new_folder(parent: str, name: str) -> str:
    """``parent/name``, or ``name-2``, ``name-3``... when a run in the same second took it: each
    Run Sun Study writes a folder of its own."""
    out, k = os.path.join(parent, name), 1
    while os.path.lexists(out):
        k += 1
        out = os.path.join(parent, f"{name}-{k}")
    return out


CLASSES = (RELIGHT_OT_show_sun_study, RELIGHT_OT_run_sun_study)
