"""Atomic file writes: every file this package writes goes through :func:`atomic_path`.

A reader (or a user whose bake was cancelled) sees either the old file or the whole new one,
never a half-written file, and a failed write leaves no temporary file behind:

* the data go to a hidden temporary name in the destination's own folder (so the final
  :func:`os.replace` is a rename on one file system, atomic on POSIX and Windows);
* the temporary name keeps the destination's extension, for writers that choose the format
  by it (OpenEXR, NumPy's ``.npz``, Blender's image and .blend savers);
* the rename happens only when the ``with`` block finished without an exception; otherwise the
  temporary file is removed and an existing destination is untouched.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import socket
from contextlib import contextmanager
from typing import Iterator

__all__ = ["atomic_path", "write_bytes", "write_text", "write_json", "staged_folder", "token",
           "owner_of"]


def _host() -> str:
    return "".join(ch if ch.isascii() and ch.isalnum() else "_"
                   for ch in socket.gethostname())[:40] or "host"


def token() -> str:
    """A fresh name part ``relight-<host>-<pid>-<8 hex>`` that every temporary file and folder of
    this tool carries, so a later run can tell ours from anyone else's and whether the process
    that made it is gone (:func:`owner_of`, :mod:`.transaction`'s sweep)."""
    return f"relight-{_host()}-{os.getpid()}-{secrets.token_hex(4)}"


_TOKEN = re.compile(r"relight-(?P<host>[A-Za-z0-9_]+)-(?P<pid>\d+)-[0-9a-f]{8}")


def owner_of(name: str) -> tuple[str, int] | None:
    """``(host, pid)`` of the process that made a temporary name of :func:`token`, else None
    (also for pid 0: no process of ours has it, so a name with it is not ours to remove)."""
    m = _TOKEN.search(name)
    return (m["host"], int(m["pid"])) if m and int(m["pid"]) > 0 else None


def _temporary_name(path: str) -> str:
    folder, base = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(base)
    if stem.endswith(".tar"):   # keep two-part extensions whole
        stem, ext = stem[:-4], ".tar" + ext
    return os.path.join(folder, f".{stem}.{token()}.tmp{ext}")


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yield a temporary path next to ``path``; on a clean exit rename it onto ``path``.

    The body writes the temporary file by any means (``open``, ``np.savez``, a library that
    takes a file name). If the body raises, or writes nothing, the temporary file is removed,
    ``path`` is not touched and the exception propagates (``FileNotFoundError`` when nothing
    was written)."""
    path = os.fspath(path)
    tmp = _temporary_name(path)
    try:
        try:
            yield tmp
        except OSError as exc:
            if exc.filename is None and exc.errno is not None:   # name the file being written
                raise OSError(exc.errno, exc.strerror, path) from exc
            raise
        if not os.path.exists(tmp):
            raise FileNotFoundError(f"nothing was written to {tmp} for {path}")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_bytes(path: str | os.PathLike, data: bytes) -> int:
    """Write ``data`` to ``path`` atomically (flushed and fsynced); returns its size."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return len(data)


def write_text(path: str | os.PathLike, text: str) -> int:
    """Write UTF-8 ``text`` to ``path`` atomically; returns the size in bytes."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, data, **dump_kw) -> int:
    """Write ``data`` as indented JSON to ``path`` atomically; returns the size in bytes.
    ``dump_kw`` goes to :func:`json.dumps` (e.g. ``default=float`` for NumPy scalars). The
    text is made before the file is opened, so data that cannot be encoded changes nothing."""
    dump_kw.setdefault("indent", 2)
    return write_text(path, json.dumps(data, **dump_kw))


def move(src: str, dst: str) -> None:
    """Move the whole file ``src`` onto ``dst`` (same file system): one atomic rename."""
    os.replace(src, dst)


def replace_folder(built: str | os.PathLike, target: str | os.PathLike) -> None:
    """Move the completed folder ``built`` to ``target`` (same file system). An existing
    ``target`` is renamed aside first and removed only after the new one is in place, so
    ``target`` never names a partial folder."""
    import shutil

    built, target = os.fspath(built), os.fspath(target)
    if not os.path.exists(target):
        os.rename(built, target)
        return
    old = f"{target}.{token()}.old"
    os.rename(target, old)
    os.rename(built, target)
    shutil.rmtree(old)


@contextmanager
def staged_folder(target: str | os.PathLike) -> Iterator[str]:
    """Yield an empty folder ``<target>.<token>.tmp`` to build a folder's files in; on a clean
    exit swap it in whole (:func:`replace_folder`); if the body raises, remove it and leave
    ``target`` as it was. Staging folders of killed runs are swept by
    :func:`.transaction.sweep` (the export and bake commands call it first)."""
    import shutil

    target = os.path.abspath(os.fspath(target))
    tmp = f"{target}.{token()}.tmp"
    os.makedirs(tmp)
    try:
        yield tmp
        replace_folder(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def safe_name(name: str) -> str:
    """``name`` (an object's, say) as a file-name stem: letters, digits, ``-`` and ``_`` kept,
    anything else ``_``."""
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in name)
