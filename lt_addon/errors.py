"""Errors as users see them: one actionable line, the traceback in a log file.

:class:`InputError` is the one error type for input that cannot be baked, fitted or read: bad
settings, a bundle of a newer format. The message says what to change; the CLI prints it as one
line and the panel's operators report it. (The bpy layer raises the same class as
``BakeInputError``.)

Anything else that stops a bake -- a full disk, a permission, a path in the way, a bug -- is
told by :func:`describe` in one line naming the file and the cause, with the traceback written
by :func:`write_log` to a file whose path the line gives.
"""

from __future__ import annotations

import errno
import os
import sys
import tempfile
import time
import traceback


class InputError(ValueError):
    """The object, settings or file cannot be used; the message says what to change."""


#: errno -> (what happened, what to do), for OSError's one line
_OS_ERRORS = {
    errno.ENOSPC: ("the disk is full", "free space there or choose another --out"),
    errno.EFBIG: ("the file is larger than this system allows (disk quota or file size limit)",
                  "free space, raise the limit, or choose another --out"),
    errno.EACCES: ("permission denied", "make it writable or choose another --out"),
    errno.EPERM: ("permission denied", "make it writable or choose another --out"),
    errno.EROFS: ("the file system is read-only", "choose another --out"),
    errno.EISDIR: ("a folder is in the way where a file goes", "move it or choose another --out"),
    errno.ENOTDIR: ("a file is in the way where a folder goes", "move it or choose another --out"),
    errno.EEXIST: ("something is in the way", "move it or choose another --out"),
    errno.ENOTEMPTY: ("a folder is in the way", "move it or choose another --out"),
}
if hasattr(errno, "EDQUOT"):
    _OS_ERRORS[errno.EDQUOT] = ("the disk quota is exceeded", "free space or choose another --out")


def describe(exc: BaseException) -> str:
    """One line on ``exc``: for an OSError the file and the cause with what to do; otherwise
    its type and first line of message."""
    if isinstance(exc, OSError) and exc.errno is not None:
        what, todo = _OS_ERRORS.get(exc.errno, (exc.strerror or str(exc), ""))
        where = exc.filename or ""
        if exc.filename2:
            where = f"{where} -> {exc.filename2}"
        return f"{what}: {where}" + (f" ({todo})" if todo else "") if where else \
            what + (f" ({todo})" if todo else "")
    text = str(exc).strip().splitlines()
    first = text[-1] if text else ""
    if isinstance(exc, (InputError,)) or type(exc).__name__ in ("InjectedFault",
                                                                  "ChangedMeanwhile"):
        return first
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


def log_folder() -> str:
    """Where failure logs go: ``$RELIGHT_LOG_DIR``, else the user's cache folder
    (``~/.cache/relightable-textures/logs``; ``%LOCALAPPDATA%`` on Windows)."""
    if os.environ.get("RELIGHT_LOG_DIR"):
        return os.environ["RELIGHT_LOG_DIR"]
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        base = os.environ["LOCALAPPDATA"]
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "relightable-textures", "logs")


def write_log(exc: BaseException, context: str = "") -> str | None:
    """Write ``exc``'s traceback (and ``context``: the command line, say) to a new log file;
    returns its path, or None when no folder could take it. The fallback, when the log folder
    cannot take it, is a fresh private temporary folder (``mkdtemp``: mode 0700, a new name
    each time): a fixed name under the shared temporary folder could be another user's folder
    or link. The file is created new (``x``: an existing file or link there is not written
    through)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    text = (f"{time.strftime('%Y-%m-%dT%H:%M:%S%z')} pid {os.getpid()}\n{context}\n\n"
            + "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))

    def fallback():
        return tempfile.mkdtemp(prefix="relightable-textures-")

    for folder in (log_folder, fallback):
        try:
            folder = folder()
            os.makedirs(folder, exist_ok=True)
            for n in range(100):   # two failures in one second of one process: -1, -2, ...
                path = os.path.join(folder, f"relight-{stamp}-{os.getpid()}"
                                            + (f"-{n}" if n else "") + ".log")
                try:
                    with open(path, "x", encoding="utf-8") as fh:
                        fh.write(text)
                    return path
                except FileExistsError:
                    continue
        except OSError:
            continue
    return None


def one_line(exc: BaseException, context: str = "", after: str = "") -> str:
    """The line a user sees for ``exc``: :func:`describe`, ``after`` (what state things are
    in), and where the traceback is (:func:`write_log`)."""
    log = write_log(exc, context)
    return (describe(exc) + (f"; {after}" if after else "")
            + (f" (details: {log})" if log else " (no log could be written)"))
