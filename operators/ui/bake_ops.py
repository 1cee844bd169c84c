"""Operators: bake relightable textures and per-vertex transport (modal, progress, Esc to
cancel), follow a Sun, remove the preview (bpy).

The modal operator drives the same generator as the CLI (:mod:`.steerable_bake`), one Cycles
bake per timer tick, so the UI stays responsive between bakes and Esc cancels cleanly: closing
the generator restores the scene and nothing is written, so the previous bake, its files and the
material stay as they were. ``execute`` (used from scripts and in background mode) runs the
same generator to completion.
"""

from __future__ import annotations

import os

import bpy

from ...lt_addon.settings import to_argv
from ...lt_addon.transport.bundle import direct_summary
from ..base import jobs
from ..preview import preview_nodes, render_guard
from ..bakes import steerable_bake
from ..base.cycles_bake import BakeInputError, check_bakeable
from .properties import (VERTEX_FIELDS, VERTEX_PROPS, preview_sun_angle, settings_from_scene,
                         truth_count)
from .settings_props import values


def _inside(path: str, folder: str) -> bool:
    """``path`` is ``folder`` or below it, after resolving '..' and links on both."""
    path, folder = os.path.realpath(path), os.path.realpath(folder)
    try:
        return os.path.commonpath([path, folder]) == folder
    except ValueError:    # another drive (Windows)
        return False


#: The stamp of this session's unsaved-file bake folder, made at its first use.
_UNSAVED_STAMP: list = []


def default_output_dir() -> str:
    """The folder an empty Output field bakes into: ``<file>_relight`` next to the saved .blend,
    as the command line writes (:func:`...lt_addon.io.names.output_folder`); for an unsaved
    file ``~/relight/untitled-<date-time>_relight``, one per Blender session (the panel shows
    it and offers to save the .blend first)."""
    import time

    from ...lt_addon.io.names import output_folder

    if bpy.data.filepath:
        return output_folder(bpy.data.filepath)
    if not _UNSAVED_STAMP:
        _UNSAVED_STAMP.append(time.strftime("%Y%m%d-%H%M%S"))
    return output_folder("", stamp=_UNSAVED_STAMP[0])


def _output_dir(props) -> str:
    """The folder a panel bake writes into, from the Output field (empty: the default folder,
    :func:`default_output_dir`).

    The field is saved in the .blend, and a bake sweeps, retires and removes files in its
    folder, so a received .blend could aim that at any folder of the user's (``//../..``). The
    rule: a folder the .blend names is used only when it lies inside the .blend's own folder
    (after normalising '..' and resolving links); any other folder only when the user set the
    Output field in this Blender session (``properties.CONFIRMED_OUTPUT_DIRS``). Otherwise
    BakeInputError, one line asking to choose the Output folder again. The default folder is
    the code's own choice, never the file's."""
    from .properties import CONFIRMED_OUTPUT_DIRS

    raw = props.output_dir
    if not raw.strip():
        return default_output_dir()
    path = bpy.path.abspath(raw)
    if path.startswith("//") or not os.path.isabs(path):  # unsaved file: no '//' base
        raise BakeInputError(f"the Output folder {raw!r} is relative to the .blend, which is "
                             "not saved: save the .blend, or clear Output to bake into "
                             f"{default_output_dir()}")
    if os.path.normpath(path) in CONFIRMED_OUTPUT_DIRS:
        return path
    if bpy.data.filepath and _inside(path, os.path.dirname(bpy.data.filepath)):
        return path
    raise BakeInputError(f"the Output folder {raw!r} ({os.path.normpath(path)}) is outside "
                         "this .blend's folder and was not chosen in this session: choose the "
                         "Output folder again (a bake writes, replaces and removes files there)")


def transport_objects(context):
    """The active mesh plus every other selected mesh (baked in the same Cycles calls)."""
    active = context.active_object
    others = [o for o in context.selected_objects if o.type == "MESH" and o != active]
    return [active] + sorted(others, key=lambda o: o.name)


def object_resolutions(objects) -> dict:
    """{name: side} of the objects with their own texture side (Object Resolution > 0)."""
    return {o.name: int(o.relight_resolution) for o in objects
            if o.relight_resolution > 0}


#: Scene property holding the last texture bake's summary lines, shown in the panel.
LAST_BAKE_KEY = "relight_last_bake"


def _finish(operator, scene, result):
    """Report what a texture bake job did (it wrote everything already) -- a
    :class:`.texture_transport.TextureBakeOutput` or a :class:`.steerable_bake.LobesBakeOutput`
    -- and keep the lines for the panel."""
    reports = result.reports if hasattr(result, "reports") else [result.report]
    lines, warned = [], []
    for rep in reports:
        t, gt = rep["timings"], rep.get("ground_truth") or {}
        size = rep["bytes"].get("total", rep["bytes"].get("exr_file", 0))
        lines.append(f"Baked {rep['object']}: {t['wall_total']:.1f} s in all, "
                     f"{size / 2**20:.1f} MiB"
                     + (f", error vs Cycles {gt['headline_rel_rmse']:.3f}"
                        if "headline_rel_rmse" in gt else ""))
        if rep.get("glossy", {}).get("materials"):
            operator.report({"WARNING"}, rep["glossy"]["note"])
        for warning in rep.get("warnings", ()):   # the report's caveats, each once
            if warning not in warned:
                warned.append(warning)
        direct = rep.get("direct")
        if direct and rep is reports[0]:
            lines.append(direct_summary(direct, rep["directions"]))
        fid = rep.get("model_vs_T") or {}
        if "headline" in fid:
            via = {"transport": "all directions", "blocks": "block PCA",
                   "horizon": "horizons"}.get(fid.get("viewport"), "PCA")
            lines.append(f"{rep['object']}: the preview ({via}) is {fid['headline']:.3f} from "
                         f"the bake itself (worst {fid['worst']['rel']:.3f} at "
                         f"{fid['worst']['elevation']:g} deg)")
    cmp = reports[0].get("comparison", {})
    if "png" in cmp:
        lines.append(f"Camera comparison: {os.path.basename(cmp['png'])} (rel. RMSE "
                     f"{cmp['rel_rmse_covered_pixels']:.3f})")
    baked = [o for o in (bpy.data.objects.get(rep.get("object", "")) for rep in reports)
             if o is not None]
    for obj in baked:   # a material other objects share: the preview is on a copy
        lines += preview_nodes.copy_notes(obj)
    if any(preview_nodes.preview_kinds(o) for o in baked):
        lines.append(PREVIEW_NOTE)
    else:
        lines.append("No live preview: only the PCA model previews in the viewport "
                     "(Advanced > Model)")
    for line in lines:
        operator.report({"INFO"}, line)
    report_warnings(operator, warned)
    scene[LAST_BAKE_KEY] = "\n".join(lines + [WARNING_PREFIX + w for w in warned])
    folder = getattr(operator, "out_dir", None)
    if folder:
        remember_bake(folder, cmp.get("png"))


#: The last line of a bake's summary: where the preview shows and what renders keep.
PREVIEW_NOTE = ("The preview shows in Material Preview (EEVEE); renders (F12) keep your "
                "materials (EEVEE: with Lock Interface, in Preview Light)")

#: The bake folder and comparison picture of this session's last texture bake (Open Folder,
#: Open Comparison): kept here, never read from the .blend, so a received file cannot make the
#: panel open a path of its choosing.
_SESSION_BAKE: dict = {}


def remember_bake(folder: str, comparison: str | None = None) -> None:
    """Keep the folder this session's bake committed into and its comparison picture."""
    _SESSION_BAKE.clear()
    _SESSION_BAKE["folder"] = os.path.abspath(folder)
    if comparison:
        _SESSION_BAKE["comparison"] = os.path.abspath(comparison)


def last_bake_folder() -> str | None:
    """This session's last bake folder while it is still a real folder (not a link); else
    None."""
    from ...lt_addon.io import untrusted

    folder = _SESSION_BAKE.get("folder")
    try:
        return folder if folder and untrusted.real_folder(folder) else None
    except untrusted.UntrustedFileError:
        return None


def last_comparison() -> str | None:
    """This session's last comparison picture while it is a regular ``.png`` file directly in
    that bake's folder (``lstat``: no link followed); else None."""
    from ...lt_addon.io import untrusted

    folder, png = last_bake_folder(), _SESSION_BAKE.get("comparison")
    if not folder or not png or not png.lower().endswith(".png") \
            or os.path.dirname(png) != folder:
        return None
    try:
        path = untrusted.confined(folder, os.path.basename(png), must_exist=True, folder=False)
        untrusted.regular_file(path)
    except untrusted.UntrustedFileError:
        return None
    return path


def open_path(path: str) -> None:
    """Open ``path`` (a folder or a file) with the system's default application."""
    bpy.ops.wm.path_open(filepath=path)


def show_in_viewport(context) -> int:
    """Switch the 3D views of the current screen that are in Solid or Wireframe shading to
    Material Preview, where the preview shows (EEVEE); returns how many were switched."""
    screen = getattr(context, "screen", None)
    switched = 0
    for area in (screen.areas if screen is not None else ()):
        if area.type != "VIEW_3D":
            continue
        for space in area.spaces:
            if space.type == "VIEW_3D" and space.shading.type in ("SOLID", "WIREFRAME"):
                space.shading.type = "MATERIAL"
                switched += 1
    return switched


def after_preview(operator, context) -> None:
    """After a bake installed a preview: Show Preview on, and Solid views switched to Material
    Preview (said in one line), so the result is what the viewport shows."""
    obj = context.active_object
    if obj is None or not preview_nodes.preview_kinds(obj):
        return
    props = context.scene.relight
    if not props.show_preview:
        props.show_preview = True
    if show_in_viewport(context):
        operator.report({"INFO"}, "Switched the 3D view to Material Preview to show the "
                                  "relit preview")
    if render_guard.lock_for_renders(context.scene):
        operator.report({"INFO"}, LOCK_NOTE)
        scene = context.scene
        if LAST_BAKE_KEY in scene:
            scene[LAST_BAKE_KEY] = scene[LAST_BAKE_KEY] + "\n" + LOCK_NOTE


#: Said when a bake turned Lock Interface on so EEVEE renders keep the user's materials.
LOCK_NOTE = ("Turned on Render > Lock Interface: EEVEE renders (F12) then use your own "
             "materials (Remove Preview turns it back off)")


#: A line of the last-bake box that is a warning (the panel draws it with a warning icon).
WARNING_PREFIX = "Warning: "


def report_warnings(operator, warnings) -> None:
    """Each of a bake report's ``warnings`` as a WARNING report, but those the bake already said
    while it ran (a progress step ``warning: ...``: :class:`ModalBake` keeps them)."""
    said = getattr(operator, "_warned", None) or set()
    for warning in warnings:
        if warning not in said:
            operator.report({"WARNING"}, warning)


def _fault_line(exc, op) -> str:
    """The panel's one line for a bake that failed (:func:`...lt_addon.errors.one_line`)."""
    from ...lt_addon.errors import one_line

    folder = getattr(op, "out_dir", None)
    return "Bake failed: " + one_line(exc, f"panel bake into {folder}",
                                      f"nothing was replaced in {folder}" if folder else "")


def _set_failure(context, text: str) -> None:
    wm = getattr(context, "window_manager", None) or bpy.context.window_manager
    if wm is not None and hasattr(wm, "relight_last_failure"):
        wm.relight_last_failure = text


class ModalBake:
    """A bake job driven one step per timer tick (progress, status text, Esc cancels), or to
    completion by ``execute`` (scripts, background mode). Subclasses give ``_prepare`` (the
    job generator) and ``_finish`` (write and preview). A mixin, not an Operator: Blender
    cannot subclass a registered operator class."""

    _timer = None
    _gen = None
    #: what the panel's failure line calls this operator's run
    failure_word = "Bake"

    def _fail(self, context, text: str) -> None:
        """Report a failure and keep its line for the panel until the next bake starts (the
        window manager's ``relight_last_failure``: this session's, not saved, not undone)."""
        self.report({"ERROR"}, text)
        line = text.removeprefix("Bake failed: ")
        _set_failure(context, f"{self.failure_word} failed: {line}")

    def _started(self, context) -> None:
        """A new bake (or estimate) clears the last failure's line."""
        _set_failure(context, "")

    def _say_warning(self, text: str) -> None:
        """A warning a bake step gave, reported now and kept so that the report's own list
        (:func:`report_warnings`) does not say it twice."""
        if not isinstance(getattr(self, "_warned", None), set):
            self._warned = set()
        if text not in self._warned:
            self._warned.add(text)
            self.report({"WARNING"}, text)

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH"

    def _prepare(self, context):
        raise NotImplementedError

    def _cancel_note(self, context) -> str:
        """What a cancelled run of this operator keeps for the next one."""
        return ""

    def _finish(self, context, result):
        raise NotImplementedError

    def _job(self, context):
        """``_prepare``'s job with its Cycles bakes on the panel's Device (resolved here, before
        any bake: Device GPU without a GPU is one error line); the device is shown in the
        panel (*Baked On*). Run On Dask passes the Device to the command, whose workers'
        machines resolve it, not this one."""
        from ..base import cycles_device

        props = context.scene.relight
        if props.run_on != "HERE":
            return self._prepare(context)
        device = cycles_device.resolve(props.device, context.scene)
        render = context.scene.render   # Render > Performance: a Fixed thread count is kept
        fixed = render.threads if render.threads_mode == "FIXED" else 0
        if props.mix_devices or fixed:   # (mix: reuse another device's kept chunks)
            import dataclasses

            device = dataclasses.replace(device, mix_devices=props.mix_devices, threads=fixed)
        gen = self._prepare(context)
        props.device_used = device.describe() + (f" ({device.note})" if device.note else "")
        if device.note:
            self.report({"INFO"}, f"Baking on {device.describe()}: {device.note}")
        return cycles_device.stepped(gen, device)

    txn = None

    def _make_out_dir(self, props) -> str:
        """The bake's output folder, and its transaction (:mod:`...lt_addon.io.transaction`):
        returns the staging folder the job writes into; :meth:`_done` swaps it in whole, a
        cancel or a failure removes it and the folder stays as it was."""
        from ...lt_addon.io.transaction import BakeTransaction
        from ..base.blend_files import BAKES_KEY, _plain

        self.out_dir = _output_dir(props)
        # the session's bake records as they were: a failed bake puts them back
        self._records = {o.name: _plain(o.get(BAKES_KEY)) for o in bpy.data.objects}
        self.txn = BakeTransaction(self.out_dir).begin()
        refused = self.txn.swept.get("refused")
        if refused:   # a planted stage or a linked cache: left alone, for the user to look at
            self.report({"WARNING"}, "Output folder: left alone what is not this tool's to "
                                     "recover or remove (look at it): " + ", ".join(refused))
        return self.txn.stage

    def _abort(self):
        """Undo the transaction of a cancelled or failed bake (nothing to do for a finished
        one): the folder as it was, the objects' bake records as they were, and images a
        preview loaded from the stage pointed at the folder (where the previous bake's files of
        the same names are again)."""
        from ..base.blend_files import BAKES_KEY, move_staged_paths

        txn, self.txn = self.txn, None
        if txn is None:
            return
        txn.rollback()
        for name, value in getattr(self, "_records", {}).items():
            obj = bpy.data.objects.get(name)
            if obj is None:
                continue
            if value is None:
                obj.pop(BAKES_KEY, None)
            else:
                obj[BAKES_KEY] = value
        move_staged_paths(txn.stage, txn.target)

    def _commit(self, result):
        """Swap the staged files in and point the session's data at them; returns ``result``
        with the committed paths."""
        from ..base import blend_files

        txn = self.txn
        if txn is None:
            return result
        txn.commit()   # a failure leaves self.txn: the caller's _abort undoes it all
        blend_files.move_staged_paths(txn.stage, txn.target)
        result = txn.final_result(result)
        self.txn = None
        txn.finish()
        for warning in getattr(txn, "warnings", []):
            self.report({"WARNING"}, warning)
        return result

    def _external(self, context, verb: str, args: list):
        """The job of Run On Dask: ``relight VERB FILE ARGS --out DIR --force`` with the
        panel's ``--workers`` / the preferences' ``--scheduler``, run by the preferences' Relight
        Command on the saved file (:mod:`.external_bake`), as an argument list (no shell)."""
        from ..farm import external_bake as eb

        props = context.scene.relight
        where = eb.distribution_args(props)   # the preferences' command and scheduler only
        command = eb.relight_command()
        path = eb.saved_blend()
        self.out_dir = _output_dir(props)
        os.makedirs(self.out_dir, exist_ok=True)
        return eb.external_job([command, verb, path, *args, "--out", self.out_dir, "--force",
                                "--device", props.device,
                                *(["--mix-devices"] if props.mix_devices else []), *where],
                               path)

    def _done(self, context, result):
        """``_finish`` for a job of this process; for a Dask job, its summary, and the open file
        reloaded to show what the command saved into it."""
        from ..farm.external_bake import ExternalResult, reload_when_idle

        if not isinstance(result, ExternalResult):
            return self._finish(context, self._commit(result))
        self.report({"INFO"}, result.summary)
        if not bpy.app.background:
            reload_when_idle(result.blend_path)

    def execute(self, context):
        self._started(context)
        try:
            gen = self._job(context)

            def warn(step):
                if step.message.startswith("warning:"):
                    self._say_warning(step.message[len("warning: "):])

            result = jobs.run(gen, on_progress=warn)
            self._done(context, result)
        except BakeInputError as exc:
            self._abort()
            self._fail(context, str(exc))
            return {"CANCELLED"}
        except Exception as exc:   # a fault: one line, the traceback in the log it names
            self._abort()
            self._fail(context, _fault_line(exc, self))
            return {"CANCELLED"}
        return {"FINISHED"}

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        self._started(context)
        try:
            self._gen = self._job(context)
        except BakeInputError as exc:
            self._abort()
            self._fail(context, str(exc))
            return {"CANCELLED"}
        except Exception as exc:
            self._abort()
            self._fail(context, _fault_line(exc, self))
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        context.workspace.status_text_set("Relight bake: starting (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == "ESC":
            self._gen.close()  # restores the scene; nothing was written
            self._abort()
            self._end(context)
            self.report({"WARNING"}, "Bake cancelled; the previous bake is unchanged"
                                     + self._cancel_note(context))
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            step = next(self._gen)
        except StopIteration as stop:
            self._end(context)
            try:
                self._done(context, stop.value)
            except Exception as exc:
                self._abort()
                self._fail(context, _fault_line(exc, self))
                return {"CANCELLED"}
            return {"FINISHED"}
        except BakeInputError as exc:
            self._end(context)
            self._abort()
            self._fail(context, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # Cycles failure: the generator has restored the scene
            self._end(context)
            self._abort()
            self._fail(context, _fault_line(exc, self))
            return {"CANCELLED"}
        if step.message.startswith("warning:"):
            self._say_warning(step.message[len("warning: "):])
        context.window_manager.progress_update(int(1000 * step.done / step.total))
        context.workspace.status_text_set(f"Relight bake: {step.message} (Esc to cancel)")
        return {"RUNNING_MODAL"}


class RELIGHT_OT_bake_textures(ModalBake, bpy.types.Operator):
    """Bake relightable textures of the active object (and the other selected meshes) with
    Cycles (Esc cancels)"""

    bl_idname = "relight.bake_textures"
    bl_label = "Bake Relightable Texture"
    # one undo step: Ctrl-Z takes the preview and the bake's records out of the scene again
    # (the files stay in the bake folder); a cancelled or failed bake pushes none
    bl_options = {"REGISTER", "UNDO"}

    def _prepare(self, context):
        props = context.scene.relight
        obj = context.active_object
        if props.method == "transport":
            from ..bakes import texture_transport as tx
            from .properties import transport_settings_from_scene

            objects = transport_objects(context)
            for o in objects:
                check_bakeable(o)
            self.settings = transport_settings_from_scene(props)
            self.settings.validate()
            sides = object_resolutions(objects)
            if props.run_on != "HERE":
                args = [a for o in objects for a in ("--object", o.name)]
                args += [a for n, r in sides.items() for a in ("--object-resolution", f"{n}={r}")]
                args += to_argv(self.settings)   # components None: --tol, no preset components
                return self._external(context, "bake-textures",
                                      args + ["--truth", str(truth_count(props))])
            stage = self._make_out_dir(props)
            self.txn.retire_globs = list(tx.retire_globs(objects))
            from ..bakes.estimate import wanted

            # a large bake is estimated first: its cost in the status line, the time left
            return tx.bake_job(context.scene, objects, self.settings, stage, resolutions=sides,
                               truth=truth_count(props),
                               estimator=wanted(self.settings, resolutions=sides))
        check_bakeable(obj)
        self.settings = settings_from_scene(props)
        self.settings.validate()
        if props.run_on != "HERE":
            args = ["--object", obj.name, "--method", "lobes"] + to_argv(self.settings)
            return self._external(context, "bake-textures",
                                  args + ["--truth", str(truth_count(props))])
        stage = self._make_out_dir(props)
        return steerable_bake.lobes_job(context.scene, obj, self.settings, stage,
                                        truth=truth_count(props), sun=props.sun)

    def _finish(self, context, result):
        _finish(self, context.scene, result)
        after_preview(self, context)

    def _cancel_note(self, context) -> str:
        if context.scene.relight.method != "transport":
            return "; its finished basis-light bakes are kept, so baking again resumes"
        return "; its finished chunks are kept, so baking again resumes"


class RELIGHT_OT_bake_transport(ModalBake, bpy.types.Operator):
    """Bake the active object's per-vertex light transport with Cycles and fit eigentransport
    (Nowrouzezahrai 2008); the vertex preview then shades it under the world (Esc cancels)"""

    bl_idname = "relight.bake_transport"
    bl_label = "Bake Vertex Transport"
    bl_options = {"REGISTER", "UNDO"}

    def _prepare(self, context):
        from ..bakes import transport_bake

        props = context.scene.relight
        obj = context.active_object
        check_bakeable(obj, need_uv=False)
        settings = transport_bake.TransportSettings(
            **values(transport_bake.TransportSettings, props, VERTEX_FIELDS, rename=VERTEX_PROPS))
        settings.validate()
        if props.run_on != "HERE":
            return self._external(context, "bake-transport", ["--object", obj.name] + to_argv(
                settings, VERTEX_FIELDS))
        stage = self._make_out_dir(props)
        # the same job as `relight bake-transport`: bake, fit, files, preview
        return transport_bake.transport_job(context.scene, obj, settings, stage)

    def _cancel_note(self, context) -> str:
        return "; its finished chunks of directions are kept, so baking again resumes"

    def _finish(self, context, result):
        report, t = result.report, result.report["timings"]
        report_warnings(self, report.get("warnings", []))   # the preview's, the checks'
        remember_bake(self.out_dir)
        after_preview(self, context)
        self.report({"INFO"}, f"Baked {report['object']}: {report['vertices']} vertices x "
                              f"{report['directions']} directions in {t['wall_total']:.1f} s "
                              f"in all, d = {report.get('d', '?')}, preview "
                              f"{report.get('preview', {}).get('shade_ms', 0):.0f} ms")


class RELIGHT_OT_analyze(ModalBake, bpy.types.Operator):
    """How many CPCA clusters the active object's transport needs (Mahajan 2007): reuses the
    samples of its vertex transport bake when the directions and bounces match, bakes them
    otherwise, and writes <object>_analysis.json into the output folder (Esc cancels the bake)"""

    bl_idname = "relight.analyze"
    bl_label = "Analyze Clusters"
    bl_options = {"REGISTER"}
    failure_word = "Analysis"

    def _prepare(self, context):
        from ..bakes import analyze, transport_bake

        props = context.scene.relight
        obj = context.active_object
        check_bakeable(obj, need_uv=False)
        direction_set = transport_bake.TransportSettings(**values(
            transport_bake.TransportSettings, props, ("directions", "bounces"),
            rename=VERTEX_PROPS)).validate()
        stage = self._make_out_dir(props)
        return analyze.analysis_job(context.scene, obj, direction_set, stage,
                                    props.vertex_bounces)

    def _finish(self, context, result):
        from ..bakes import analyze

        text = analyze.summary(result.report)
        context.scene[analyze.SUMMARY_KEY] = text   # the panel shows the last analysis
        self.report({"INFO"}, text)


def show_preview(scene, obj, kind: str, reinstall: bool = False) -> str:
    """Show the preview of ``obj``'s existing bake of ``kind`` (no bake):
    ``steerable_texture``, ``transport_texture`` or ``eigentransport``. Previews of different
    kinds coexist in the object's materials: when one of ``kind`` is there it is switched on,
    otherwise (or with ``reinstall``) it is installed from the bake's files. Returns the file.
    Raises ValueError / FileNotFoundError with what to do."""
    from ..base.blend_files import bake_file

    what = {"steerable_texture": "steerable texture", "transport_texture": "transport texture",
            "eigentransport": "vertex transport", "material_tensors": "material"}.get(kind)
    if what is None:
        raise ValueError(f"unknown bake kind {kind!r}")
    path = bake_file(obj, kind, what)
    if kind == "material_tensors":     # one bake, several receivers: all of them
        from ..bakes import material_edit

        tensors = dict(material_edit.scene_bakes(scene)).get(obj)
        if tensors is None:
            raise FileNotFoundError(f"{obj.name}'s material bake file cannot be read: {path}")
        receivers = [scene.objects.get(n) for n, _ in tensors.objects]
        if reinstall or not all(o is not None and preview_nodes.activate_preview(o, kind)
                                for o in receivers):
            material_edit.install_preview(scene, tensors)
        else:
            material_edit.update_preview(scene)
        return path
    if not reinstall and preview_nodes.activate_preview(obj, kind):
        if kind == "eigentransport":      # the colour attribute follows the current lighting
            from ..preview import vertex_relight

            vertex_relight.update_preview(scene)
        return path
    if kind == "steerable_texture":
        from ...lt_addon.steerable.texture import SteerableTexture

        preview_nodes.install_preview(scene, obj, path, SteerableTexture.load(path),
                                      sun=scene.relight.sun)
    elif kind == "transport_texture":
        from ..bakes import texture_transport as tx

        bake, store, report = tx.load_bake(path)
        tx.install_transport_preview(scene, obj, report, bake, store,
                                     sun_angle=preview_sun_angle(scene)[0],
                                     sun=scene.relight.sun)
    else:
        from ..preview import vertex_relight

        vertex_relight.update_preview(scene)
        preview_nodes.install_attribute_preview(obj, vertex_relight.SHADING_ATTRIBUTE)
    return path


class RELIGHT_OT_show_preview(bpy.types.Operator):
    """Show the preview of one of the active object's existing bakes (no re-bake): switches to
    it when the material already holds it (previews of different bakes coexist), else installs
    it from the bake's files"""

    bl_idname = "relight.show_preview"
    bl_label = "Show Preview"
    bl_options = {"REGISTER", "UNDO"}

    kind: bpy.props.EnumProperty(name="Bake", items=[
        ("transport_texture", "Transport texture", ""),
        ("steerable_texture", "Steerable texture", ""),
        ("eigentransport", "Vertex transport", ""),
        ("material_tensors", "Material edits", "")])
    reinstall: bpy.props.BoolProperty(name="Reinstall", default=False,
                                      description="Rebuild the preview from the bake's files "
                                                  "even when the material holds it")

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "MESH"

    def execute(self, context):
        try:
            path = show_preview(context.scene, context.active_object, self.kind, self.reinstall)
        except (ValueError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if not context.scene.relight.show_preview:   # Show means shown
            context.scene.relight.show_preview = True
        self.report({"INFO"}, f"Showing {os.path.basename(path)}")
        return {"FINISHED"}


class RELIGHT_OT_follow_sun(bpy.types.Operator):
    """Make the preview follow the chosen Sun lamp's direction (or stop following it)"""

    bl_idname = "relight.follow_sun"
    bl_label = "Follow Sun"
    bl_options = {"REGISTER", "UNDO"}

    follow: bpy.props.BoolProperty(name="Follow", default=True)

    def execute(self, context):
        scene = context.scene
        sun = scene.relight.sun
        if self.follow and sun is None:
            self.report({"ERROR"}, "Choose a Sun lamp in the Relight panel first")
            return {"CANCELLED"}
        preview_nodes.ensure_sliders(scene)
        changed = preview_nodes.set_follow_sun(scene, sun if self.follow else None)
        scene["relight_follow_sun"] = 1.0 if self.follow else 0.0
        scene.update_tag()
        self.report({"INFO"}, f"{'Following ' + sun.name if self.follow else 'Sliders drive the light'}"
                              f" ({changed} preview materials)")
        return {"FINISHED"}


class RELIGHT_OT_remove_preview(bpy.types.Operator):
    """Remove the relight preview nodes from the active object's materials"""

    bl_idname = "relight.remove_preview"
    bl_label = "Remove Preview"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "MESH"

    def execute(self, context):
        n = preview_nodes.remove_preview(context.active_object, context.scene)
        self.report({"INFO"}, f"Removed the preview from {n} material(s)")
        if render_guard.unlock_after_previews(context.scene):
            self.report({"INFO"}, "Turned Render > Lock Interface back off (the bake had "
                                  "turned it on)")
        return {"FINISHED"}


class RELIGHT_OT_open_bake_folder(bpy.types.Operator):
    """Open the folder this session's last bake wrote into, in the file browser of the system"""

    bl_idname = "relight.open_bake_folder"
    bl_label = "Open Folder"

    @classmethod
    def poll(cls, context):
        return last_bake_folder() is not None

    def execute(self, context):
        folder = last_bake_folder()
        if folder is None:
            self.report({"ERROR"}, "no bake folder of this session to open: bake first")
            return {"CANCELLED"}
        open_path(folder)
        return {"FINISHED"}


class RELIGHT_OT_open_comparison(bpy.types.Operator):
    """Open the picture of this session's last bake next to Cycles (preview | Cycles |
    difference), made when Check vs Cycles is on and the scene has a camera"""

    bl_idname = "relight.open_comparison"
    bl_label = "Open Comparison"

    @classmethod
    def poll(cls, context):
        return last_comparison() is not None

    def execute(self, context):
        png = last_comparison()
        if png is None:
            self.report({"ERROR"}, "no comparison picture of this session: bake with Check vs "
                                   "Cycles on and a scene camera")
            return {"CANCELLED"}
        open_path(png)
        return {"FINISHED"}


def kept_chunks(context, kind: str | None = None) -> list:
    """The chunk folders that cancelled or failed bakes of the active object (its texture bake,
    alone or with other meshes, its vertex bake or a material bake it comes first in) keep in
    the output folder, as ``[(folder, chunk count)]``; [] when there are none or no output
    folder yet. ``kind`` "texture", "vertex" or "materials" keeps only that bake's."""
    import glob

    from ...lt_addon.io.names import object_stem
    from ..base.bake_inputs import CACHE_FOLDER

    obj = context.active_object
    try:
        root = os.path.join(_output_dir(context.scene.relight), CACHE_FOLDER)
    except BakeInputError:
        return []
    if obj is None or not os.path.isdir(root) or os.path.islink(root):
        return []   # (a linked cache is someone else's folder: the bake refuses it, in a line)
    active = object_stem(obj.name)
    out = []
    for folder in sorted(glob.glob(os.path.join(root, "*"))):
        base = os.path.basename(folder)   # "A+B" (baked together), "A_vertex", "A_materials",
        what = next((k for k in ("vertex", "materials") if base.endswith("_" + k)), "texture")
        if kind not in (None, what):      # "A_lobes" (the lobes method: a texture bake)
            continue
        if os.path.islink(folder):
            continue
        if (base == f"{active}_{what}" if what != "texture" else
                base == f"{active}_lobes" or active in base.split("+")):
            n = len(glob.glob(os.path.join(folder, "**", "*_[0-9][0-9][0-9][0-9][0-9].npy"),
                              recursive=True))   # with stages nested: "A/indirect/<key>/"
            if n:
                out.append((folder, n))
    return out


class RELIGHT_OT_discard_chunks(bpy.types.Operator):
    """Delete the finished chunks that a cancelled bake of the active object kept (the next
    bake then starts from nothing)"""

    bl_idname = "relight.discard_chunks"
    bl_label = "Discard Kept Chunks"
    bl_options = {"REGISTER"}

    kind: bpy.props.EnumProperty(
        name="Bake", default="ALL", description="Whose chunks: one bake's, or every bake's",
        items=[("ALL", "All", "Every bake of the active object"),
               ("texture", "Texture", "The texture bake (either method)"),
               ("vertex", "Vertex", "The vertex transport bake"),
               ("materials", "Materials", "The material bake")])

    def execute(self, context):
        from ...lt_addon.io.untrusted import UntrustedFileError

        from ...lt_addon.io import untrusted
        from ..base.bake_inputs import CACHE_FOLDER

        kept = kept_chunks(context, None if self.kind == "ALL" else self.kind)
        try:
            root = os.path.join(_output_dir(context.scene.relight), CACHE_FOLDER)
        except BakeInputError:   # no output folder yet: no chunks either
            root = None
        try:
            if root is not None:   # (kept_chunks does not look through a linked cache)
                untrusted.real_folder(root)
            _discard_chunk_folders([folder for folder, _ in kept])
        except UntrustedFileError as exc:   # a link in the cache: nothing removed, said so
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Discarded {sum(n for _, n in kept)} kept chunk(s)")
        return {"FINISHED"}


def _discard_chunk_folders(folders: list) -> None:
    """Remove the chunk ``folders`` (of :func:`kept_chunks`, all in one ``.relight_cache``),
    then that folder when left empty. The bake folder may come from someone else (issue 56):
    the cache and every folder must be a real folder (``lstat``), checked before anything
    goes, else UntrustedFileError naming the link and nothing is removed; ``shutil.rmtree``
    of a real folder removes links inside it, never what they point to."""
    import shutil

    from ...lt_addon.io import untrusted

    if not folders:
        return
    root = os.path.dirname(folders[0])
    untrusted.real_folder(root)
    for folder in folders:
        untrusted.real_folder(folder)
    for folder in folders:
        shutil.rmtree(folder)
    if untrusted.real_folder(root) and not os.listdir(root):
        os.rmdir(root)


#: Scene property holding the last estimate's lines, shown in the panel.
LAST_ESTIMATE_KEY = "relight_last_estimate"


class RELIGHT_OT_estimate(ModalBake, bpy.types.Operator):
    """Predict what Bake Relightable Texture would cost with these settings: time per stage,
    disk, memory and the viewport's GPU memory, from two small calibration bakes on this
    machine (a few seconds; nothing is written; Esc cancels)"""

    bl_idname = "relight.estimate"
    bl_label = "Estimate"
    bl_options = {"REGISTER"}
    failure_word = "Estimate"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return (obj is not None and obj.type == "MESH"
                and context.scene.relight.method == "transport")

    def _job(self, context):   # here, on the panel's Device (Run On does not apply)
        from ..base import cycles_device

        device = cycles_device.resolve(context.scene.relight.device, context.scene)
        return cycles_device.stepped(self._prepare(context), device)

    def _prepare(self, context):
        from ..bakes.estimate import estimate_groups
        from .properties import transport_settings_from_scene

        props = context.scene.relight
        objects = transport_objects(context)
        for o in objects:
            check_bakeable(o)
        settings = transport_settings_from_scene(props)
        settings.validate()
        return estimate_groups(context.scene, objects, settings, object_resolutions(objects),
                               truth_count(props))

    def _finish(self, context, result):
        for line in result["lines"]:
            self.report({"INFO"}, line.strip())
        context.scene[LAST_ESTIMATE_KEY] = "\n".join(ln.strip() for ln in result["lines"])


CLASSES = (RELIGHT_OT_bake_textures, RELIGHT_OT_estimate, RELIGHT_OT_bake_transport,
           RELIGHT_OT_analyze,
           RELIGHT_OT_show_preview, RELIGHT_OT_follow_sun, RELIGHT_OT_remove_preview,
           RELIGHT_OT_discard_chunks, RELIGHT_OT_open_bake_folder, RELIGHT_OT_open_comparison)
