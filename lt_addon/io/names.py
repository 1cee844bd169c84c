"""File and folder names derived from object names: one function for every bake file, report,
chunk cache, preview and export (issue 59).

:func:`.atomic.safe_name` keeps letters, digits, ``-`` and ``_`` and turns anything else into
``_``, so ``a/b`` and ``a_b`` (or ``My Box`` and ``My_Box``) mapped to one stem and the second
object's bake overwrote the first's. :func:`object_stem` keeps that stem where sanitising left the
name as it was -- bakes of ordinary names keep their file names -- and otherwise appends ``-``
and 6 hex digits of the SHA-256 of the UTF-8 name (stable across runs and machines). A plain name
that already ends like that (``x-abcdef``) is hashed too, so no plain name can take the stem of a
hashed one.

Case is not folded in the stem (``Cube`` stays ``Cube``): on a case-insensitive file system
(macOS, Windows) ``Box`` and ``box`` would still be one file, so the objects of one bake whose
stems are equal ignoring case are refused before anything is baked (:func:`check_stems`).
Bakes written before this scheme are found by the paths their .blend records and reports hold,
never by re-deriving a name.
"""

from __future__ import annotations

import hashlib
import os
import re

from .atomic import safe_name

_HASHED = re.compile(r"-[0-9a-f]{6}\Z")


def object_stem(name: str) -> str:
    """The file-name stem of object ``name``: ``safe_name(name)`` when that is ``name`` itself,
    else it plus ``-`` and 6 hex digits of SHA-256(name); injective but for hash collisions,
    which :func:`check_stems` refuses."""
    safe = safe_name(name)
    if safe == name and safe and not _HASHED.search(safe):
        return safe
    return f"{safe}-{hashlib.sha256(name.encode('utf-8', 'surrogatepass')).hexdigest()[:6]}"


class StemCollision(ValueError):
    """Two objects of one bake would write the same files."""


def check_stems(names) -> None:
    """Refuse (:class:`StemCollision`, one line naming both) objects of one bake whose stems
    are equal ignoring case: their files would overwrite each other on a case-insensitive file
    system (macOS, Windows), or anywhere for a (very unlikely) hash collision."""
    seen = {}
    for name in names:
        key = object_stem(name).casefold()
        if key in seen and seen[key] != name:
            raise StemCollision(
                f"objects {seen[key]!r} and {name!r} would write the same files "
                f"({object_stem(seen[key])}_* and {object_stem(name)}_*: file names ignore case "
                "on macOS and Windows); rename one of them or bake them apart into different "
                "folders")
        seen.setdefault(key, name)


def output_folder(blend_path: str, home: str | None = None, stamp: str = "") -> str:
    """The default bake folder, one rule for the panel and the command line (issue 57):
    ``<blend folder>/<blend stem>_relight`` for a saved .blend; for an unsaved session (only the
    panel has one) ``<home>/relight/untitled-<stamp>_relight``, ``stamp`` fixed once per
    session by the caller, so two unsaved sessions never replace each other's bakes."""
    if blend_path:
        folder, base = os.path.split(os.path.abspath(blend_path))
        return os.path.join(folder, os.path.splitext(base)[0] + "_relight")
    home = home or os.path.expanduser("~")
    return os.path.join(home, "relight", f"untitled-{stamp}_relight" if stamp
                        else "untitled_relight")
