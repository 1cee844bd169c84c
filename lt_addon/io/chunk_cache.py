"""A bake's finished chunks kept on disk, keyed by everything they depend on, so a cancelled,
failed or killed bake that is run again redoes only the chunks it is missing.

A bake is a list of chunks (for example a range of light directions), each a pure function of
(the scene content that matters, the bake settings, the chunk id). :class:`ChunkCache` keeps each
finished chunk as ``<root>/<digest>/<chunk>.npy`` -- written under a temporary name and renamed,
so a chunk file is whole or absent -- where ``digest`` is the SHA-256 of the key's canonical
JSON. A rerun with the same key finds them; a changed scene or setting gives another digest, so
a stale chunk is never read, and :meth:`ChunkCache.prune_others` drops the stale folders. The
cache is a means to finish a bake, not a product: the bake removes it once its files are
complete (:meth:`ChunkCache.clear`).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil

import numpy as np

from . import atomic

__all__ = ["digest", "ChunkCache"]


def digest(key) -> str:
    """SHA-256 (hex) of ``key``'s canonical JSON (sorted keys, no spaces; other types by str)."""
    text = json.dumps(key, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class ChunkCache:
    """Finished chunks of one bake under ``root``, for one ``key`` (a JSON-able dict).

    Attributes
    ----------
    folder : str
        ``<root>/<first 20 hex digits of the key's digest>``.
    reused, written : int
        Chunks :meth:`get` found and :meth:`put` stored since this object was made.
    """

    def __init__(self, root: str, key: dict):
        self.root = os.path.abspath(root)
        self.key = key
        self.digest = digest(key)
        self.folder = os.path.join(self.root, self.digest[:20])
        self.reused = 0
        self.written = 0

    def path(self, chunk: str) -> str:
        safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(chunk))
        return os.path.join(self.folder, safe + ".npy")

    def get(self, chunk: str) -> np.ndarray | None:
        """The stored array of ``chunk``, or None. A file that does not read (truncated by a
        crash of the file system, say) is removed and counts as missing."""
        p = self.path(chunk)
        if not os.path.isfile(p):
            return None
        try:
            arr = np.load(p, allow_pickle=False)
        except (OSError, ValueError, EOFError):
            os.remove(p)
            return None
        self.reused += 1
        return arr

    def put(self, chunk: str, array) -> None:
        """Store ``chunk``'s array (its dtype kept: store what the bake stores)."""
        os.makedirs(self.folder, exist_ok=True)
        key_file = os.path.join(self.folder, "key.json")
        if not os.path.exists(key_file):   # what the chunks depend on, for a person to read
            atomic.write_json(key_file, self.key, default=str)
        with atomic.atomic_path(self.path(chunk)) as tmp:
            np.save(tmp, np.asarray(array), allow_pickle=False)
        self.written += 1

    def prune_others(self) -> int:
        """Remove the folders of other keys under ``root`` (stale after a scene or settings
        change); returns how many were removed. Only key folders (20 hex digits) go: a
        folder of another name is another stage's cache nested here, with its own key."""
        if not os.path.isdir(self.root):
            return 0
        gone = 0
        for name in os.listdir(self.root):
            p = os.path.join(self.root, name)
            if (os.path.isdir(p) and p != self.folder and len(name) == 20
                    and all(ch in "0123456789abcdef" for ch in name)):
                shutil.rmtree(p, ignore_errors=True)
                gone += 1
        return gone

    def clear(self) -> None:
        """Remove this key's chunks, and ``root`` (and its parent) when left empty."""
        shutil.rmtree(self.folder, ignore_errors=True)
        for folder in (self.root, os.path.dirname(self.root)):
            try:
                os.rmdir(folder)
            except OSError:
                break
