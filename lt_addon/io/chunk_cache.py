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

A chunk is checked before it is reused: beside it, ``<chunk>.sha256`` holds the SHA-256 of its
shape, dtype and bytes, written once the chunk is in place. A chunk whose checksum is missing or
differs (a worker or a disk that wrote something else, a file edited by hand) or whose floating
values are not all finite (NaN, inf: a faulty bake) is removed and baked again, and counted in
:attr:`ChunkCache.rejected`.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil

import numpy as np

from . import atomic

__all__ = ["digest", "checksum", "ChunkCache"]


def digest(key) -> str:
    """SHA-256 (hex) of ``key``'s canonical JSON (sorted keys, no spaces; other types by str)."""
    text = json.dumps(key, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def checksum(array) -> str:
    """SHA-256 (hex) of an array's shape, dtype and bytes (C order)."""
    a = np.ascontiguousarray(array)
    h = hashlib.sha256(f"{a.shape}|{a.dtype.str}|".encode())
    h.update(a.tobytes())
    return h.hexdigest()


class ChunkCache:
    """Finished chunks of one bake under ``root``, for one ``key`` (a JSON-able dict).

    Attributes
    ----------
    folder : str
        ``<root>/<first 20 hex digits of the key's digest>``.
    reused, written : int
        Chunks :meth:`get` found and :meth:`put` stored since this object was made.
    rejected : int
        Chunks :meth:`get` found but refused (unreadable, checksum, non-finite values) and
        removed, so the bake made them again.
    """

    def __init__(self, root: str, key: dict):
        self.root = os.path.abspath(root)
        self.key = key
        self.digest = digest(key)
        self.folder = os.path.join(self.root, self.digest[:20])
        self.reused = 0
        self.written = 0
        self.rejected = 0
        #: {device: chunk count} of the folders :meth:`prune_others` removed whose key differs
        #: from this one only in its ``device`` (a bake resumed on another device: those chunks
        #: are another sample set, so they are baked again, and the bake says so)
        self.other_devices: dict = {}
        #: {device: chunk count} of another device's chunks taken over by
        #: ``prune_others(adopt_devices=True)`` (``--mix-devices``): reused, not baked again
        self.mixed_devices: dict = {}
        self.adopt_devices = False

    def path(self, chunk: str) -> str:
        safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(chunk))
        return os.path.join(self.folder, safe + ".npy")

    def get(self, chunk: str, shape: tuple | None = None, dtype=None, lo: float | None = None,
            hi: float | None = None) -> np.ndarray | None:
        """The stored array of ``chunk``, or None. A chunk that fails a check -- it does not
        read (truncated), its checksum differs, it holds NaN or inf, or it has not the expected
        ``shape`` / ``dtype`` or values outside ``[lo, hi]`` -- is removed, counted in
        :attr:`rejected` and treated as missing (baked again)."""
        p = self.path(chunk)
        if not os.path.isfile(p):
            return None
        try:
            arr = np.load(p, allow_pickle=False)
            with open(p + ".sha256") as fh:
                ok = fh.read().strip() == checksum(arr)
        except (OSError, ValueError, EOFError):
            ok = False
        if ok and arr.dtype.kind == "f":
            ok = bool(np.isfinite(arr).all())
        if ok and shape is not None:
            ok = tuple(arr.shape) == tuple(shape)
        if ok and dtype is not None:
            ok = arr.dtype == np.dtype(dtype)
        if ok and lo is not None and arr.size:
            ok = float(arr.min()) >= lo
        if ok and hi is not None and arr.size:
            ok = float(arr.max()) <= hi
        if not ok:
            for q in (p, p + ".sha256", p + ".device"):
                if os.path.exists(q):
                    os.remove(q)
            self.rejected += 1
            return None
        dev_note = p + ".device"
        if os.path.exists(dev_note):   # another device's chunk, adopted by --mix-devices
            with open(dev_note) as fh:
                dev = fh.read().strip()
            if not self.adopt_devices:
                for q in (p, p + ".sha256", dev_note):
                    if os.path.exists(q):
                        os.remove(q)
                self.other_devices[dev] = self.other_devices.get(dev, 0) + 1
                return None
            self.mixed_devices[dev] = self.mixed_devices.get(dev, 0) + 1
        self.reused += 1
        return arr

    def put(self, chunk: str, array) -> None:
        """Store ``chunk``'s array (its dtype kept: store what the bake stores)."""
        os.makedirs(self.folder, exist_ok=True)
        key_file = os.path.join(self.folder, "key.json")
        if not os.path.exists(key_file):   # what the chunks depend on, for a person to read
            atomic.write_json(key_file, self.key, default=str)
        array = np.asarray(array)
        if os.path.exists(self.path(chunk) + ".device"):   # baked here now, not adopted
            os.remove(self.path(chunk) + ".device")
        with atomic.atomic_path(self.path(chunk)) as tmp:
            np.save(tmp, array, allow_pickle=False)
        atomic.write_text(self.path(chunk) + ".sha256", checksum(array) + "\n")
        self.written += 1

    def prune_others(self, adopt_devices: bool = False) -> int:
        """Remove the folders of other keys under ``root`` (stale after a scene or settings
        change); returns how many were removed. Only key folders (20 hex digits) go: a
        folder of another name is another stage's cache nested here, with its own key.

        A folder whose key differs only in its ``device`` holds the same chunks baked on
        another device (another sample set). By default it is removed and counted in
        :attr:`other_devices` (those chunks are baked again). With ``adopt_devices`` (the user
        agreed: ``--mix-devices``) its chunks this key lacks move into this key's folder first,
        each with a ``.device`` note of where it came from; :meth:`get` reuses them (counted in
        :attr:`mixed_devices`) only while adopting, and otherwise bakes them again (counted in
        :attr:`other_devices`), also in a later run."""
        self.adopt_devices = adopt_devices
        if not os.path.isdir(self.root):
            return 0
        gone = 0
        for name in os.listdir(self.root):
            p = os.path.join(self.root, name)
            if (os.path.isdir(p) and p != self.folder and len(name) == 20
                    and all(ch in "0123456789abcdef" for ch in name)):
                device = self._other_device(p)
                if device is not None and adopt_devices:
                    self._adopt(p, device)   # (counted when reused: get())
                elif device is not None:
                    n = sum(1 for f in os.listdir(p) if f.endswith(".npy"))
                    self.other_devices[device] = self.other_devices.get(device, 0) + n
                shutil.rmtree(p, ignore_errors=True)
                gone += 1
        return gone

    def _adopt(self, folder: str, device: str) -> int:
        """Move ``folder``'s chunks (with their checksums) that this key lacks into this key's
        folder; returns how many."""
        os.makedirs(self.folder, exist_ok=True)
        key_file = os.path.join(self.folder, "key.json")
        if not os.path.exists(key_file):
            atomic.write_json(key_file, self.key, default=str)
        n = 0
        for f in sorted(os.listdir(folder)):
            if not f.endswith(".npy") or os.path.exists(os.path.join(self.folder, f)):
                continue
            if not os.path.exists(os.path.join(folder, f + ".sha256")):
                continue
            atomic.write_text(os.path.join(self.folder, f + ".device"), device + "\n")
            atomic.move(os.path.join(folder, f + ".sha256"), os.path.join(self.folder, f + ".sha256"))
            atomic.move(os.path.join(folder, f), os.path.join(self.folder, f))
            n += 1
        return n

    def _other_device(self, folder: str) -> str | None:
        """The device of ``folder``'s key when it equals this key but for ``device``."""
        if "device" not in self.key:
            return None
        try:
            with open(os.path.join(folder, "key.json"), encoding="utf-8") as fh:
                other = json.load(fh)
        except (OSError, ValueError):
            return None
        if not isinstance(other, dict) or other.get("device", "CPU") == self.key["device"]:
            return None
        mine = json.loads(json.dumps(self.key, default=str))   # as key.json holds it
        rest = {k: v for k, v in other.items() if k != "device"}
        return str(other.get("device", "CPU")) if rest == {
            k: v for k, v in mine.items() if k != "device"} else None

    def clear(self) -> None:
        """Remove this key's chunks, and ``root`` (and its parent) when left empty."""
        shutil.rmtree(self.folder, ignore_errors=True)
        for folder in (self.root, os.path.dirname(self.root)):
            try:
                os.rmdir(folder)
            except OSError:
                break
