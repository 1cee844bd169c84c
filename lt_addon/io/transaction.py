"""One bake, one transaction: a bake's files are built in a staging folder and swapped in whole.

Every file of one atomic write is whole (:mod:`.atomic`), but a bake writes a *set* of files
(T, model, albedo, indirect, previews, report) and the ``.blend`` records it. This module makes
the set a unit, with a small journal so that a process killed at any instant leaves a state the
next run can finish or undo:

1. **Stage.** :class:`BakeTransaction` makes ``<out>/.relight-stage-<token>/`` (same folder,
   hence the same file system: every move below is a rename). The bake writes everything there.
   The folder ``out`` itself is not touched; a kill here leaves the previous bake as it was and
   a stage the next run removes.
2. **Check.** :meth:`~BakeTransaction.commit` reads every staged file back (:func:`check_file`:
   JSON parses, NPZ CRCs, NPY/EXR/PNG headers and sizes) and rewrites the paths in the staged
   JSON files from the stage to ``out``.
3. **Swap.** The caller first writes the new ``.blend`` under a temporary name (the slow part
   of saving). Then the journal ``.journal.json`` (in the stage, written atomically) says
   ``swapping`` and lists the entries and that temporary ``.blend``. For each entry: the old file of that name, if any, is
   renamed into ``<stage>/.old/``, then the new one is renamed into ``out``. Files of the
   previous bake that the new one does not write (``retire``) go to ``.old`` too. Then the
   journal says ``swapped``, with the identity (inode, size, mtime) of the ``.blend`` as it was.
4. **Record.** The caller renames the new ``.blend`` into place, then
   :meth:`~BakeTransaction.finish` marks the journal ``committed`` and removes the stage with
   the old files. Steps 3 and 4 are renames only: a kill lands between them only in a window
   of milliseconds, and leaves a journal the next run acts on.

Undo (:meth:`~BakeTransaction.rollback`, and :func:`recover` for a killed run) needs no record
of which renames happened: a staged entry that is gone and whose file in ``out`` is the one the
swap moved in (its device and inode, which the journal lists under ``moved``) goes back into the
stage, and whatever is in ``.old`` goes back; both are renames, so an interrupted undo can be
run again. A killed run in state ``swapped`` is rolled back when
the ``.blend`` is unchanged (its save never happened) and forward otherwise; ``committed`` is
only cleaned up. Windows: a rename fails while a file is open, so the texture bake drops its
memory maps of T before the swap; a failed rename raises and is undone like any other fault.

:func:`sweep` is the debris collector every bake and export runs first on its folder: it
recovers stages and removes temporary files of this tool's processes that are gone (by the
host and pid in their names, :func:`.atomic.token`), never anything else.

**A stage from elsewhere** (issue 56; ``docs/security.md``). A bake folder may come from
someone else, with a stage and journal in it made to look like a killed run's. So a journal is
data, never a path list: it names basenames only (:func:`.untrusted.check_name`; a name with
``..``, a separator or a drive refuses the whole stage before anything moves), and every path is
re-derived under the folder the stage is in (its ``target`` field is not read). A stage is
recovered only when its name is exactly this version's (``STAGE_PREFIX`` + a token of this host
with a pid above 0 that is not running): older temporary-name patterns, pid 0 and other names are
never recovered. The stage and its ``.old`` must be real folders (``lstat``: a symlinked stage is
never entered). The undo moves a file out of the folder only when it is the very file the swap
moved in (device and inode in the journal), and puts back only what is in ``.old``. The
journal's ``blend_tmp`` (the new ``.blend`` under a temporary name) is never removed by a
recovery: the journal cannot vouch for a path, and the CLI sweeps the ``.blend``'s own folder for
our temporary files of dead processes by their token (``sweep(folder, stages=False)``), which is
where that file is. A refused stage is left as it is, named in :func:`sweep`'s ``refused``
list (the bake goes on; the CLI prints the list), for a person to look at.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
from typing import Iterable

from . import atomic, untrusted, versions
from .untrusted import UntrustedFileError

__all__ = ["BakeTransaction", "after_commit", "sweep", "recover", "check_file", "target_of", "pid_alive",
           "STAGE_PREFIX", "rewrite_paths"]

STAGE_PREFIX = ".relight-stage-"
JOURNAL = ".journal.json"
OLD = ".old"
#: the chunk cache's folder in a bake folder (``operators/base/bake_inputs.CACHE_FOLDER``)
CACHE = ".relight_cache"
#: the whole name of a stage this version makes: ``STAGE_PREFIX`` + :func:`.atomic.token`
_STAGE_NAME = re.compile(re.escape(STAGE_PREFIX)
                         + r"relight-(?P<host>[A-Za-z0-9_]+)-(?P<pid>\d+)-[0-9a-f]{8}")
FORMAT = "relightable_textures.commit_journal"


#: stage folder -> what to do once its transaction is committed (:func:`after_commit`)
_AFTER_COMMIT: dict = {}


def after_commit(folder: str, action) -> None:
    """Run ``action()`` once the bake writing into ``folder`` is committed -- at once when
    ``folder`` is not a stage (a bake called directly, into a folder of its own). The chunk
    caches go this way: a bake that fails after writing its files keeps them for the rerun."""
    folder = os.path.abspath(folder)
    if os.path.basename(folder).startswith(STAGE_PREFIX) and os.path.isdir(folder):
        _AFTER_COMMIT.setdefault(folder, []).append(action)
    else:
        action()


def target_of(folder: str) -> str:
    """The folder a stage commits to (``folder`` itself when it is not a stage): the chunk
    caches a bake keeps for resuming live there, outside the stage."""
    folder = os.path.abspath(folder)
    head, base = os.path.split(folder)
    return head if base.startswith(STAGE_PREFIX) else folder


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this machine (a reused pid counts as alive: the sweep
    then leaves the debris for later, it never removes a live process's files)."""
    if pid <= 0:
        return False
    if sys.platform == "win32":
        import ctypes

        kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)
        handle = kernel32.OpenProcess(0x1000, False, pid)   # PROCESS_QUERY_LIMITED_INFORMATION
        if not handle:   # ERROR_INVALID_PARAMETER: no such process; anything else (access
            return ctypes.get_last_error() != 87   # denied: another user's): alive
        code = ctypes.c_ulong()
        ok = kernel32.GetExitCodeProcess(handle, ctypes.byref(code))
        kernel32.CloseHandle(handle)
        return bool(ok) and code.value == 259                # STILL_ACTIVE
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove(path: str) -> None:
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.remove(path)


def _fsync_dir(folder: str) -> None:
    """Make the renames in ``folder`` durable (POSIX; Windows has no directory handles)."""
    if sys.platform == "win32":
        return
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _prune_empty(folder: str) -> None:
    """Remove ``folder`` and its subfolders bottom-up where they hold nothing (a chunk cache
    whose bakes are all committed). Real folders only: a symlinked ``folder`` is left alone and
    links inside are not walked (``lstat``; ``os.walk`` does not follow links below its top)."""
    try:
        if not untrusted.real_folder(folder):
            return
    except UntrustedFileError:
        return
    for root, _, _ in sorted(os.walk(folder, followlinks=False), key=lambda w: -len(w[0])):
        try:
            os.rmdir(root)
        except OSError:
            pass


def file_identity(path: str | None) -> list | None:
    """(inode, size, mtime ns) of ``path``, None when absent: an atomic save changes the inode."""
    if not path:
        return None
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_ino, st.st_size, st.st_mtime_ns]


# ------------------------------------------------------------------------------------------
# checking staged files


_MAGIC = {".png": b"\x89PNG\r\n\x1a\n", ".exr": b"\x76\x2f\x31\x01", ".npy": b"\x93NUMPY",
          ".npz": b"PK", ".jpg": b"\xff\xd8\xff", ".glb": b"glTF"}


def check_file(path: str) -> None:
    """Raise ValueError naming ``path`` when it is not a whole file of its kind: empty, wrong
    magic bytes, a JSON that does not parse, an NPZ whose CRCs fail, an NPY shorter than its
    header says. Cheap: no array is loaded whole."""
    ext = os.path.splitext(path)[1].lower()
    size = os.path.getsize(path)
    if size == 0:
        raise ValueError(f"{path} is empty")
    magic = _MAGIC.get(ext)
    if magic is not None:
        with open(path, "rb") as fh:
            if fh.read(len(magic)) != magic:
                raise ValueError(f"{path} is not a {ext[1:].upper()} file (bad signature)")
    if ext == ".json":
        with open(path, encoding="utf-8") as fh:
            try:
                json.load(fh)
            except ValueError as exc:
                raise ValueError(f"{path} is not valid JSON: {exc}") from None
    elif ext == ".npz":
        import zipfile

        try:
            with zipfile.ZipFile(path) as zf:
                bad = zf.testzip()
        except (zipfile.BadZipFile, NotImplementedError, EOFError) as exc:
            raise ValueError(f"{path} is not a whole NPZ file: {exc}") from None
        if bad is not None:
            raise ValueError(f"{path}: member {bad} fails its CRC")
    elif ext == ".npy":
        import numpy as np

        from .untrusted import UntrustedFileError, read_npy_header

        with open(path, "rb") as fh:   # (3.0, a UTF-8 header: this package never writes one)
            try:
                shape, fortran, dtype, offset = read_npy_header(fh, path, kinds="biufUSV")
            except UntrustedFileError as exc:
                raise ValueError(f"{path} is truncated ({exc.cause})") from None
        need = offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if size < need:
            raise ValueError(f"{path} is truncated ({size} of {need} bytes)")


# ------------------------------------------------------------------------------------------
# paths


def rewrite_paths(value, stage: str, target: str):
    """``value`` (JSON-like: dicts, lists, strings) with every path inside ``stage`` moved to
    ``target``; other values unchanged. Matching is on the stage's unique folder name, so a
    path in any spelling (absolute, Blender's ``//`` relative, either separator) is mapped."""
    name = os.path.basename(os.path.normpath(stage))
    pattern = re.compile(re.escape(name) + r"[\\/]")

    def fix(v):
        if isinstance(v, str):
            return pattern.sub("", v) if name in v else v
        if isinstance(v, dict):
            return {k: fix(x) for k, x in v.items()}
        if isinstance(v, list):
            return [fix(x) for x in v]
        if isinstance(v, tuple):
            return tuple(fix(x) for x in v)
        return v

    return fix(value)


# ------------------------------------------------------------------------------------------
# the transaction


class BakeTransaction:
    """Stage, check, swap and record one bake's files in ``out_dir`` (module docstring).

    ``blend``: the ``.blend`` the caller saves after :meth:`commit` (None: nothing is saved,
    e.g. the panel, whose session holds the record until the user saves). ``retire``: names
    (globs) in ``out_dir`` of the previous bake's files that go when the new bake does not
    write them (its previews of another kind, say); only names the bake owns.

    Use::

        with BakeTransaction(out, blend=path) as txn:
            run the bake into txn.stage
            txn.commit()
            save the .blend
        # clean exit: finish(); an exception: rollback(), then it propagates
    """

    def __init__(self, out_dir: str, blend: str | None = None, retire: Iterable[str] = ()):
        self.target = os.path.abspath(out_dir)
        self.blend = os.path.abspath(blend) if blend else None
        self.retire_globs = list(retire)
        self.stage = os.path.join(self.target, STAGE_PREFIX + atomic.token())
        self.old = os.path.join(self.stage, OLD)
        self.state = "new"
        self.entries: list = []
        self.retired: list = []
        self.swept: dict = {}
        self.blend_before = file_identity(self.blend)

    # -- lifecycle
    def begin(self) -> "BakeTransaction":
        self.created_target = not os.path.isdir(self.target)
        os.makedirs(self.target, exist_ok=True)
        self.swept = sweep(self.target)
        os.makedirs(self.stage)
        self.state = "staging"
        return self

    def __enter__(self):
        return self.begin()

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.finish()
        else:
            self.rollback()
        return False

    def _journal(self, state: str) -> None:
        atomic.write_json(os.path.join(self.stage, JOURNAL), {
            **versions.stamp(FORMAT), "state": state,
            "target": self.target, "entries": self.entries, "retired": self.retired,
            "blend": self.blend, "blend_before": self.blend_before,
            "blend_tmp": getattr(self, "blend_tmp", None),
            # names that existed in the target before the swap (for a person reading it)
            "existed": getattr(self, "existed", []),
            # name -> [device, inode] of each staged entry: an undo moves a file out of the
            # target only when it is the one the swap moved in (a rename keeps both)
            "moved": getattr(self, "moved", {})})
        self.state = state

    def staged(self) -> list:
        """Names of the entries in the stage (files and folders the bake wrote)."""
        return sorted(n for n in os.listdir(self.stage) if n not in (JOURNAL, OLD))

    def path(self, name: str) -> str:
        """Where ``name`` is staged."""
        return os.path.join(self.stage, name)

    def final(self, value):
        """``value`` with staged paths mapped to where they live after the commit."""
        return rewrite_paths(value, self.stage, self.target)

    def final_result(self, result):
        """A job's result object with its staged paths replaced by the committed ones (its
        report dicts, lists and strings; objects such as models are left as they are)."""
        if isinstance(result, (dict, list, tuple, str)):
            return self.final(result)
        for name, value in list(getattr(result, "__dict__", {}).items()):
            if isinstance(value, (dict, list, str)):
                setattr(result, name, self.final(value))
        return result

    def prepare(self) -> list:
        """Check the staged files and fix the paths in their JSON documents (nothing in
        ``out_dir`` changes); returns the staged names. Raises when a file is bad, a folder of
        the user's stands where a file goes, or the ``.blend`` changed meanwhile."""
        if self.state != "staging":
            raise RuntimeError(f"prepare in state {self.state}")
        self._check_blend()
        self.entries = self.staged()
        if not self.entries:
            raise ValueError(f"the bake wrote no file into {self.stage}")
        for name in self.entries:
            p = self.path(name)
            for root, _, files in (os.walk(p) if os.path.isdir(p) else [("", None, [p])]):
                for f in files:
                    q = os.path.join(root, f)
                    check_file(q)
                    if q.endswith(".json"):
                        with open(q, encoding="utf-8") as fh:
                            data = json.load(fh)
                        fixed = self.final(data)
                        if fixed != data:
                            atomic.write_json(q, fixed)
        for name in self.entries:   # a folder where a file goes (or the reverse) is not a bake's
            dest = os.path.join(self.target, name)
            is_dir = os.path.isdir(dest) and not os.path.islink(dest)
            if os.path.lexists(dest) and is_dir != os.path.isdir(self.path(name)):
                import errno

                code = errno.EISDIR if is_dir else errno.ENOTDIR
                raise OSError(code, os.strerror(code), dest)
        import fnmatch

        new = set(self.entries)
        self.retired = sorted(
            n for n in os.listdir(self.target)
            if n not in new and any(fnmatch.fnmatchcase(n, g) for g in self.retire_globs))
        self.state = "checked"
        return list(self.entries)

    def _check_blend(self) -> None:
        if self.blend and file_identity(self.blend) != self.blend_before:
            raise ChangedMeanwhile(
                f"{self.blend} changed while the bake ran (saved by another program?); nothing "
                "was replaced: reopen it and bake again")

    def swap(self, blend_tmp: str | None = None) -> list:
        """Swap the checked files into ``out_dir`` (renames only: the window a kill can land in
        is milliseconds, and the journal covers it). ``blend_tmp``: the new ``.blend``, already
        written under a temporary name, that the caller renames onto ``blend`` right after;
        a recovery removes it. Returns the names swapped in."""
        from .. import faults

        if self.state == "staging":
            self.prepare()
        if self.state != "checked":
            raise RuntimeError(f"swap in state {self.state}")
        self._check_blend()
        self.blend_tmp = blend_tmp
        self.existed = [n for n in self.entries if os.path.lexists(os.path.join(self.target, n))]
        self.moved = {n: _identity(self.path(n)) for n in self.entries}
        self._journal("swapping")
        os.makedirs(self.old)
        for name in self.retired:
            os.rename(os.path.join(self.target, name), os.path.join(self.old, name))
        for i, name in enumerate(self.entries):
            dest = os.path.join(self.target, name)
            if os.path.lexists(dest):
                os.rename(dest, os.path.join(self.old, name))
            os.rename(self.path(name), dest)
            if i == 0:
                faults.checkpoint("commit")
        _fsync_dir(self.target)
        self._journal("swapped")
        return list(self.entries)

    def commit(self) -> list:
        """:meth:`prepare` and :meth:`swap`, for a transaction without a ``.blend`` to save."""
        self.prepare()
        return self.swap()

    def finish(self) -> None:
        """Keep the commit (after the ``.blend`` is saved) and remove the stage and old files;
        an uncommitted transaction is rolled back instead."""
        if self.state != "swapped":
            self.rollback()
            return
        self.warnings = []   # the bake is committed: what fails from here is tidying up
        try:
            self._journal("committed")
        except OSError as exc:   # (a recovery still rolls forward: the .blend changed)
            self.warnings.append(f"could not mark the commit in {self.stage}: {exc}")
        shutil.rmtree(self.stage, ignore_errors=True)
        self.state = "done"
        for action in _AFTER_COMMIT.pop(self.stage, []):
            try:
                action()
            except Exception as exc:   # e.g. a chunk cache that would not go
                self.warnings.append(f"could not remove the chunks that served: {exc}")
        _prune_empty(os.path.join(self.target, CACHE))

    def rollback(self) -> None:
        """Undo whatever part of the swap happened and remove the stage."""
        if self.state in ("done", "rolled back", "new"):
            return
        _AFTER_COMMIT.pop(self.stage, None)
        if os.path.isdir(self.stage):
            _undo(self.stage, self.target, self.entries, self.retired,
                  getattr(self, "moved", {}))
        self.state = "rolled back"
        _prune_empty(os.path.join(self.target, CACHE))
        if getattr(self, "created_target", False):   # a folder this bake made, left empty
            try:
                os.rmdir(self.target)
            except OSError:
                pass


class ChangedMeanwhile(RuntimeError):
    """The ``.blend`` a bake would record into changed on disk while the bake ran."""


def _identity(path: str) -> list:
    """[device, inode] of the entry ``path`` itself (``lstat``): kept by a rename."""
    st = os.lstat(path)
    return [st.st_dev, st.st_ino]


def _undo(stage: str, target: str, entries: list, retired: list, moved: dict | None = None) -> None:
    """Put ``target`` back as it was before the swap. Every step is a rename that leaves the
    stage explaining the state, so an undo that is itself interrupted (a kill, a file Windows
    holds open) can be run again: a new file moved in goes back into the stage (never deleted
    while the old one may be missing), then the old one comes back from ``.old``.

    ``moved``: name -> [device, inode] of the entries the swap moved in (None: the journal's);
    a file in ``target`` goes back into the stage only when it is that very file. A journal of
    an earlier version has none: a file then goes back only when its old file is in ``.old``
    to take its place. Names are basenames (:func:`.untrusted.check_name`, all checked before
    anything moves); ``.old`` must be a real folder, and only regular files and real folders
    come back from it (UntrustedFileError otherwise, nothing moved)."""
    names = list(entries) + list(retired)
    for name in names:
        untrusted.check_name(name)
    old = os.path.join(stage, OLD)
    have_old = untrusted.real_folder(old)
    if moved is None:
        moved = _journal_of(stage).get("moved")
    for name in names:
        dest = os.path.join(target, name)
        staged = os.path.join(stage, name)
        kept = os.path.join(old, name)
        if name in entries and not os.path.lexists(staged) and os.path.lexists(dest) and (
                _identity(dest) == list(moved.get(name) or []) if isinstance(moved, dict)
                else have_old and os.path.lexists(kept)):
            os.rename(dest, staged)          # the new file, back into the stage
        if have_old and _plain(kept) and not os.path.lexists(dest):
            os.rename(kept, dest)            # the old file, back into place
    _fsync_dir(target)
    shutil.rmtree(stage, ignore_errors=True)


def _plain(path: str) -> bool:
    """Whether ``path`` is a regular file or a real folder (``lstat``; False when absent)."""
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return False
    import stat

    return stat.S_ISREG(mode) or stat.S_ISDIR(mode)


def _journal_of(stage: str) -> dict:
    """The journal of ``stage`` as it reads ({} when missing or unreadable)."""
    try:
        return untrusted.read_json(os.path.join(stage, JOURNAL))
    except UntrustedFileError:
        return {}


def _checked_journal(stage: str) -> dict | None:
    """The journal of ``stage`` (None when there is none), its fields checked: names are
    basenames, ``moved`` pairs of integers. UntrustedFileError (naming the journal) otherwise:
    the stage is then left alone."""
    path = os.path.join(stage, JOURNAL)
    if not os.path.lexists(path):
        return None
    j = untrusted.read_json(path)

    def bad(cause):
        return UntrustedFileError(path, f"{cause}; the stage is left alone")

    for field in ("entries", "retired"):
        names = j.get(field, [])
        if not isinstance(names, list):
            raise bad(f"its {field} are not a list")
        for name in names:
            try:
                untrusted.check_name(name)
            except UntrustedFileError as exc:
                raise bad(f"its {field} name {exc.cause}") from None
    moved = j.get("moved")
    if moved is not None and not (isinstance(moved, dict) and all(
            isinstance(v, list) and len(v) == 2 and all(type(x) is int for x in v)
            for v in moved.values())):
        raise bad("its moved entries are not [device, inode] pairs")
    if j.get("blend") is not None and not isinstance(j["blend"], str):
        raise bad("its blend is not a path")
    if type(j.get("format_version", 1)) is not int:
        raise bad("its format_version is not a number")
    return j


def recover(stage: str) -> str:
    """Finish or undo the stage of a process that is gone (by its journal); returns what was
    done: ``removed`` (never swapped: the previous bake is untouched), ``rolled back``,
    ``rolled forward`` or ``left`` (old files without a journal, or a newer version's
    journal). Raises UntrustedFileError, having changed nothing, when ``stage`` is not a real
    folder, its journal does not read or names anything but basenames, or its ``.old`` is not
    a real folder (module docstring: a stage from elsewhere). The journal's ``blend_tmp`` is
    never removed here (the caller's sweep of the ``.blend``'s folder removes ours)."""
    if not untrusted.real_folder(stage):
        return "removed"   # (gone meanwhile)
    j = _checked_journal(stage)
    if j and int(j.get("format_version", 1)) > versions.version_of(FORMAT):
        return "left"   # a newer version's journal: not ours to interpret
    if not j or j.get("state") not in ("swapping", "swapped", "committed"):
        old = os.path.join(stage, OLD)
        if os.path.lexists(old) and (not os.path.isdir(old) or os.path.islink(old)
                                     or os.listdir(old)):
            return "left"   # old files without a readable journal: for a person to look at
        shutil.rmtree(stage, ignore_errors=True)
        return "removed"
    untrusted.real_folder(os.path.join(stage, OLD))   # (before anything moves)
    if j["state"] == "committed" or (
            j["state"] == "swapped" and j.get("blend")
            and file_identity(j["blend"]) != j.get("blend_before")):
        shutil.rmtree(stage, ignore_errors=True)   # the .blend was saved: keep the new bake
        return "rolled forward"
    _undo(stage, os.path.dirname(os.path.abspath(stage)), j.get("entries", []),
          j.get("retired", []), j.get("moved"))
    return "rolled back"


#: Temporary names of earlier versions (before :func:`.atomic.token`): ``.<name>.<pid>-<hex>.tmp.<ext>``
#: (atomic writes) and ``.<name>.npy.<pid>.tmp.npy`` (transport stores); their pid is all they hold.
_LEGACY = (re.compile(r"^\..+\.(\d+)-[0-9a-f]{8}\.tmp(\.[A-Za-z0-9]+)*$"),
           re.compile(r"^\..+\.(\d+)\.tmp\.npy$"),
           re.compile(r"^\..+\.(\d+)\.tmp\.json$"))


def _debris_owner(name: str, legacy: bool = True):
    """(host or None, pid) when ``name`` is a temporary name of this tool, else None (also for
    pid 0 or below: no process of ours has one)."""
    own = atomic.owner_of(name)
    if own is not None or not legacy:
        return own
    for rx in _LEGACY:
        m = rx.match(name)
        if m:
            return (None, int(m.group(1))) if int(m.group(1)) > 0 else None
    return None


def _looks_like_debris(name: str) -> bool:
    """Whether ``name`` has the shape of a temporary name of this tool, whatever its pid."""
    return bool(atomic._TOKEN.search(name)) or any(rx.match(name) for rx in _LEGACY)


def sweep(folder: str, stages: bool = True) -> dict:
    """Recover the stages and remove the temporary files and folders in ``folder`` (and its
    chunk cache, ``.relight_cache``) that processes of this tool on this host left when they
    were killed. A name counts only when it carries our token (or an earlier version's temporary
    pattern; a stage only this version's exact name) and its pid is above 0 and not running;
    anything else is left alone. Links are never followed: a symlinked chunk cache is not
    walked, a symlinked stage not entered. Returns ``{"removed": [...], "rolled_back": [...],
    "rolled_forward": [...]}`` (names), with ``"refused": [...]`` when something was: "name:
    why" of what looked like our debris but was left alone, e.g. a planted stage -- for the
    caller to report."""
    out = {"removed": [], "rolled_back": [], "rolled_forward": [], "refused": []}
    if not os.path.isdir(folder):
        return _without_empty_refused(out)
    host = atomic._host()
    places = [folder]
    cache = os.path.join(folder, CACHE)
    if stages:
        try:
            if untrusted.real_folder(cache):
                places += [root for root, _, _ in os.walk(cache, followlinks=False)]
        except UntrustedFileError as exc:
            out["refused"].append(f"{CACHE}: {exc.cause}")
    for place in places:
        try:
            names = os.listdir(place)
        except OSError:
            continue
        for name in names:
            p = os.path.join(place, name)
            rel = os.path.relpath(p, folder)
            if name.startswith(STAGE_PREFIX):
                if not stages or place != folder:
                    continue
                m = _STAGE_NAME.fullmatch(name)
                if m is None or int(m["pid"]) <= 0:
                    if m is not None or _looks_like_debris(name):
                        why = ("pid 0 is no process's" if m is not None else
                               "not a stage name of this version")
                        out["refused"].append(f"{rel}: {why}")
                    continue
                if m["host"] != host or int(m["pid"]) == os.getpid() or pid_alive(int(m["pid"])):
                    continue
                try:
                    done = recover(p)
                except UntrustedFileError as exc:
                    what = rel if exc.path in ("", p) else os.path.relpath(exc.path, folder)
                    out["refused"].append(f"{what}: {exc.cause}")
                    continue
                except OSError:
                    continue
                if done != "left":
                    out[{"removed": "removed", "rolled back": "rolled_back",
                         "rolled forward": "rolled_forward"}[done]].append(rel)
                continue
            owner = _debris_owner(name, legacy=stages)   # (old names: only in our folders)
            if owner is None:
                continue
            h, pid = owner
            if (h is not None and h != host) or pid == os.getpid() or pid_alive(pid):
                continue
            try:
                _remove(p)
            except OSError:
                continue
            out["removed"].append(rel)
    return _without_empty_refused(out)


def _without_empty_refused(out: dict) -> dict:
    if not out["refused"]:
        del out["refused"]
    return out
