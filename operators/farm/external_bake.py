"""Run a panel bake on Dask from the UI: the same ``relight`` CLI command, in a process of a
Python environment that has bpy and Dask (bpy).

Blender's own Python has neither Dask nor a way to start bpy worker processes, so the panel's
*Run On: Local Dask Workers / Dask Scheduler* hands the bake to ``relight`` (the console script
of such an environment, e.g. this repository's ``.venv/bin/relight``, set as the Relight
Command of the add-on's preferences, as is the scheduler address: a .blend names neither, so a
received file cannot choose a program to run or a cluster to trust): it opens the saved .blend,
bakes the chunks on the workers, writes the files and saves the bake record and preview into the
.blend. :func:`external_job` is an ordinary job (a generator of :class:`.jobs.Progress`), so
the modal operator shows the command's progress lines and Esc interrupts it: the command gets
SIGINT, keeps its finished chunks and exits, and the next Bake resumes from them. When it
succeeds, the open file is reloaded from disk to show the bake (not when it was changed while
the bake ran: then the user is told to revert).
"""

from __future__ import annotations

import os
import queue
import re
import shutil
import signal
import subprocess
import threading
from dataclasses import dataclass

from ..base.cycles_bake import BakeInputError
from ..base.jobs import Progress

#: ``Run On`` choices of the panel (scene property ``relight.run_on``). The command and the
#: scheduler address are the add-on's preferences, never the .blend's (:func:`farm_preferences`).
RUN_ON = (("HERE", "This Blender", "Bake in this Blender process (modal, Esc cancels)"),
          ("WORKERS", "Local Dask Workers", "Bake the chunks on a local Dask cluster of "
           "Workers processes, through the Relight Command of the add-on's Preferences (needs "
           "bpy and Dask there)"),
          ("SCHEDULER", "Dask Scheduler", "Bake the chunks on the Dask cluster at the Dask "
           "Scheduler of the add-on's Preferences (a cluster trusted with running code here), "
           "through the Relight Command; the workers must read the .blend and the output "
           "folder at the same paths"))

#: The add-on's module name, its preferences' ``bl_idname``: ``relightable_textures`` when
#: registered from a path, ``bl_ext.<repository>.relightable_textures`` as an installed
#: extension (this module is ``<package>.operators.farm.external_bake``).
ADDON_ID = __name__.rsplit(".", 3)[0]
#: Where the user sets them, for the lines that say so.
WHERE = "Preferences > Add-ons > Relightable Textures"
#: What connecting to a scheduler means, said wherever an address is set.
SCHEDULER_TRUST = ("the Dask client runs code the scheduler sends (pickled tasks and results): "
                   "connect only to a cluster you trust with this machine")


@dataclass(frozen=True)
class FarmPreferences:
    """The user's settings of Run On Dask, from the add-on's preferences (stored in Blender's
    user preferences, not in any .blend): the ``relight`` executable (empty: ``relight`` on
    PATH) and the Dask scheduler address (empty: none)."""
    relight_command: str = ""
    scheduler: str = ""


def farm_preferences() -> FarmPreferences:
    """The add-on's preferences (:class:`FarmPreferences`); the defaults -- no command, no
    scheduler -- when the add-on has no preferences entry (registered from a path, as in the
    tests, rather than enabled as an installed extension). A .blend's scene properties are
    never read here: a received file must not choose a program to run or a cluster to trust."""
    import bpy

    entry = bpy.context.preferences.addons.get(ADDON_ID)
    prefs = getattr(entry, "preferences", None)
    if prefs is None:
        return FarmPreferences()
    return FarmPreferences(prefs.relight_command.strip(), prefs.dask_scheduler.strip())


_PROGRESS = re.compile(r"^\S+ \[(\d+)/(\d+)\] (.*)$")


@dataclass
class ExternalResult:
    """A finished external bake: its command line, exit status and the output it printed."""
    command: list
    stdout: str
    blend_path: str

    @property
    def summary(self) -> str:
        """The command's first result line ("baked ...")."""
        lines = [ln for ln in self.stdout.splitlines() if ln.strip()]
        return next((ln for ln in lines if ln.startswith("baked")), lines[0] if lines else "")


def relight_command() -> str:
    """The ``relight`` executable the panel runs: the Relight Command of the add-on's
    preferences (an absolute path: a blend-relative ``//`` one would name a file beside
    whichever .blend is open), else ``relight`` on PATH; BakeInputError with the fix when there
    is none. Run as an argument list, never through a shell."""
    text = os.path.expanduser(farm_preferences().relight_command)
    if text and not os.path.isabs(text):
        raise BakeInputError(f"Relight Command {text!r} is not an absolute path: set it in "
                             f"{WHERE}")
    found = text if text and os.path.isfile(text) and os.access(text, os.X_OK) else (
        None if text else shutil.which("relight"))
    if not found:
        raise BakeInputError(
            (f"Relight Command {text!r} is not an executable file" if text else
             "no `relight` command on PATH") + f": set the Relight Command in {WHERE} to the "
            "`relight` of a Python environment with bpy and Dask "
            "(e.g. <repository>/.venv/bin/relight)")
    return found


def distribution_args(props) -> list:
    """``--workers N`` or ``--scheduler ADDRESS`` for the panel's Run On; the address is the
    add-on's preferences' (never the .blend's: the Dask client unpickles what a scheduler
    sends)."""
    if props.run_on == "WORKERS":
        return ["--workers", str(int(props.dask_workers))]
    address = farm_preferences().scheduler
    if not address:
        raise BakeInputError(f"set the Dask Scheduler address (e.g. tcp://host:8786) in {WHERE}"
                             f"; {SCHEDULER_TRUST}")
    return ["--scheduler", address]


def saved_blend() -> str:
    """The open .blend's path; BakeInputError when it is unsaved or (in the UI) has unsaved
    changes: the external process bakes the file on disk, and saves the bake into it. In
    background mode Blender flags every file dirty, so a script must save before it bakes."""
    import bpy

    if not bpy.data.filepath:
        raise BakeInputError("save the .blend first: Dask workers bake the file on disk")
    if bpy.data.is_dirty and not bpy.app.background:
        raise BakeInputError("save the .blend (Ctrl S) first: Dask workers bake the file on "
                             "disk, not the unsaved changes")
    return bpy.data.filepath


def _reader(stream, lines: queue.Queue, tag: str) -> None:
    try:
        for line in iter(stream.readline, ""):
            lines.put((tag, line.rstrip("\n")))
    finally:   # the job waits for both streams' end
        lines.put((tag, None))


def _interrupt(proc, windows: bool) -> None:
    """Ctrl-C the command as a user would: the first one cancels after its current step and
    keeps the finished chunks, a second one (after ``5 s``) stops it at once -- its
    ``finally`` blocks still close the Dask cluster; only a command that ignores both is
    killed (after 30 s more)."""
    sig = signal.CTRL_BREAK_EVENT if windows else signal.SIGINT
    for wait in (5.0, 30.0):
        if proc.poll() is not None:
            return
        try:
            proc.send_signal(sig)
        except (OSError, ValueError):
            break
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def external_job(command: list, blend_path: str, poll: float = 0.05):
    """Job: run ``command`` (a ``relight`` verb with ``--workers`` / ``--scheduler``) and
    yield Progress from its progress lines (and every ``poll`` seconds, so a modal timer is
    never held longer); returns an :class:`ExternalResult`. Closing the job sends the command
    SIGINT (it keeps its finished chunks) and waits for it. A non-zero exit raises
    BakeInputError with the command's ``relight: error:`` line (or its last lines)."""
    windows = os.name == "nt"
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            encoding="utf-8", errors="replace", bufsize=1,
                            creationflags=subprocess.CREATE_NEW_PROCESS_GROUP if windows else 0)
    lines: queue.Queue = queue.Queue()
    for stream, tag in ((proc.stdout, "out"), (proc.stderr, "err")):
        threading.Thread(target=_reader, args=(stream, lines, tag), daemon=True).start()
    out, err, open_streams = [], [], 2
    last = Progress(0, 1, f"starting {os.path.basename(command[0])} {command[1]}")
    finished = False
    try:
        while open_streams:
            try:
                tag, line = lines.get(timeout=poll)
            except queue.Empty:
                yield last
                continue
            if line is None:
                open_streams -= 1
                continue
            (out if tag == "out" else err).append(line)
            m = _PROGRESS.match(line) if tag == "err" else None
            if m:
                last = Progress(int(m[1]), max(int(m[2]), 1), m[3])
                yield last
        rc = proc.wait()
        finished = True
    finally:
        if not finished:
            _interrupt(proc, windows)
    if rc != 0:
        error = next((ln for ln in err if ln.startswith("relight: error:")), None)
        raise BakeInputError(error[len("relight: error: "):] if error else
                             f"{os.path.basename(command[0])} {command[1]} exited with {rc}: "
                             + " | ".join(err[-3:]))
    return ExternalResult(command, "\n".join(out), blend_path)


def reload_when_idle(blend_path: str) -> None:
    """Reload the open file from disk (it now holds the bake) once the operator has ended,
    unless it was changed while the bake ran."""
    import bpy

    def reload():
        if bpy.data.filepath == blend_path and not bpy.data.is_dirty:
            bpy.ops.wm.revert_mainfile()
        return None

    bpy.app.timers.register(reload, first_interval=0.1)
