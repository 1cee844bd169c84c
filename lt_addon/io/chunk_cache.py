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

A chunk is checked before it is reused: beside it, ``<chunk>.sha256`` holds
``hmac-sha256:<hex>``, the HMAC-SHA256 under this user's chunk key (:func:`chunk_key`) of its
file name and every byte of the file (:func:`mac`), written once the chunk is in place; it is
checked after the header and before the data is parsed. A chunk whose checksum is
missing or differs (a worker or a disk that wrote something else, a file edited by hand, a chunk
planted by someone who can write the bake folder, an unkeyed SHA-256 of an earlier version),
whose header is not what the bake asks for (read before its data: :func:`.untrusted.load_npy`),
which is not a regular file (a symlink is never read through) or whose floating values are not
all finite (NaN, inf: a faulty bake) is removed and baked again, and counted in
:attr:`ChunkCache.rejected`.

Untrusted folders (issue 56; ``docs/security.md``): the bake folder and its cache may come from
someone else. The cache key is computable from the ``.blend`` and a plain SHA-256 needs no
secret, so only the keyed checksum makes a planted chunk fail. And the cache's own folders --
``.relight_cache`` down to this key's folder, and every key folder :meth:`ChunkCache.prune_others`
would remove or adopt from -- must be real folders (``lstat``): a symbolic link there is refused
with an :class:`~.untrusted.UntrustedFileError` naming it ("remove it to go on"), before anything
is written, read or removed through it.

**The chunk key.** 32 random bytes (hex) in ``$RELIGHT_CHUNK_KEY_FILE`` when set, else in the
user's cache folder: ``$XDG_CACHE_HOME`` or ``~/.cache`` (``%LOCALAPPDATA%`` on Windows)
``/relightable-textures/chunk-key``, made on first use with mode 0600 (its folder 0700). Dask
workers on the same machine share the home folder, hence the key; workers on other machines
writing into a shared cache need the same key: point ``RELIGHT_CHUNK_KEY_FILE`` at one file
every worker can read (and nobody else), or their chunks are rejected and baked again by the
coordinator. A new key (a deleted file, another user) only costs a rebake of kept chunks.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import secrets
import shutil
import stat
import sys

import numpy as np

from . import atomic, untrusted
from .untrusted import UntrustedFileError

__all__ = ["digest", "checksum", "mac", "chunk_key", "key_file", "ChunkCache", "KEY_ENV",
           "CACHE_FOLDER"]

#: environment variable naming the chunk key's file (farms: one key all workers share)
KEY_ENV = "RELIGHT_CHUNK_KEY_FILE"
#: the chunk cache's folder in a bake folder (``operators/base/bake_inputs.CACHE_FOLDER``): the
#: folders from it down to a key's folder are this tool's and must be real folders
CACHE_FOLDER = ".relight_cache"
#: what the checksum file of a chunk starts with (an earlier version's plain SHA-256 does not)
MAC_PREFIX = "hmac-sha256:"


def digest(key) -> str:
    """SHA-256 (hex) of ``key``'s canonical JSON (sorted keys, no spaces; other types by str)."""
    text = json.dumps(key, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def checksum(array) -> str:
    """SHA-256 (hex) of an array's shape, dtype and bytes (C order): the unkeyed checksum of
    earlier versions (anyone can compute it; chunks carry :func:`mac` now)."""
    a = np.ascontiguousarray(array)
    h = hashlib.sha256(f"{a.shape}|{a.dtype.str}|".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def mac(path: str, key: bytes, name: str | None = None) -> str:
    """HMAC-SHA256 (hex) under ``key`` of the chunk file ``path``'s name (``name``, default
    its basename) and every byte of it (the NPY header, hence shape and dtype, and the data),
    read in blocks: only a process holding the key can make one (:func:`chunk_key`), and it is
    checked before the data is parsed."""
    h = hmac.new(key, b"relight-chunk-v1|" + (name or os.path.basename(path)).encode() + b"|",
                 hashlib.sha256)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _check_header(path: str, shape=None, dtype=None) -> None:
    """The chunk file ``path``'s NPY header checked before its data is read: a regular file,
    no Python objects (a structured dtype of numbers is fine), ``shape`` / ``dtype`` when
    given (None entries: any length), and exactly as long as the header says."""
    size = untrusted.regular_file(path)
    with open(path, "rb") as fh:   # (structured records: the gathered transfer's entries)
        hshape, _, hdtype, offset = untrusted.read_npy_header(fh, path, kinds="biufV")
    untrusted.check_shape(path, hshape, shape, hdtype, dtype)
    need = offset + int(np.prod(hshape, dtype=object)) * hdtype.itemsize
    if need != size:
        raise UntrustedFileError(path, f"is {size} bytes, its header says {need}")


def key_file() -> str:
    """Where the chunk key lives: ``$RELIGHT_CHUNK_KEY_FILE``, else the user's cache folder
    (the base :func:`...errors.log_folder` uses) ``/relightable-textures/chunk-key``."""
    if os.environ.get(KEY_ENV):
        return os.path.abspath(os.path.expanduser(os.environ[KEY_ENV]))
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        base = os.environ["LOCALAPPDATA"]
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "relightable-textures", "chunk-key")


_KEYS: dict = {}


def _read_key(path: str) -> bytes | None:
    try:
        size = untrusted.regular_file(path, 4096)
    except UntrustedFileError as exc:
        if exc.cause == "is missing":
            return None
        raise UntrustedFileError(path, f"{exc.cause} (the chunk key: remove it to make a new "
                                       "one)") from None
    with open(path, "rb") as fh:
        data = fh.read(size).strip()
    if len(data) < 32:
        raise UntrustedFileError(path, "is not a chunk key (fewer than 32 bytes; remove it to "
                                       "make a new one)")
    return data


def _make_key(path: str) -> None:
    """Write a new random key to ``path`` (mode 0600), never replacing one another process
    made meanwhile (a hard link of a whole file, or an exclusive create)."""
    os.makedirs(os.path.dirname(path), mode=0o700, exist_ok=True)
    data = secrets.token_hex(32).encode() + b"\n"
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)

    def write(p):
        fd = os.open(p, flags, 0o600)
        try:
            os.write(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)

    tmp = f"{path}.{atomic.token()}.tmp"
    write(tmp)
    try:
        os.link(tmp, path)
    except FileExistsError:
        pass
    except OSError:   # a file system without hard links
        try:
            write(path)
        except FileExistsError:
            pass
    finally:
        os.remove(tmp)


def chunk_key() -> bytes:
    """This user's secret for :func:`mac` (module docstring: made on first use, 0600)."""
    path = key_file()
    if path not in _KEYS:
        key = _read_key(path)
        if key is None:
            try:
                _make_key(path)
            except OSError as exc:
                why = exc.strerror or str(exc)
                raise UntrustedFileError(path, f"the chunk key cannot be made ({why}); set "
                                               f"{KEY_ENV} to a writable file, or bake with "
                                               "--no-resume") from None
            key = _read_key(path)
        _KEYS[path] = key
    return _KEYS[path]


def _unlink(path: str) -> None:
    """Remove the entry ``path`` itself (a link, never what it points to; a real folder whole)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISDIR(st.st_mode):
        shutil.rmtree(path, ignore_errors=True)
    else:
        os.remove(path)


def _is_key_name(name: str) -> bool:
    return len(name) == 20 and all(ch in "0123456789abcdef" for ch in name)


class ChunkCache:
    """Finished chunks of one bake under ``root``, for one ``key`` (a JSON-able dict).

    Raises :class:`~.untrusted.UntrustedFileError` when a folder of the cache (from
    ``.relight_cache``, or ``root`` when the path has none, down to this key's folder) is a
    symbolic link or not a folder: nothing is ever written, read or removed through a link.

    Attributes
    ----------
    folder : str
        ``<root>/<first 20 hex digits of the key's digest>``.
    reused, written : int
        Chunks :meth:`get` found and :meth:`put` stored since this object was made.
    rejected : int
        Chunks :meth:`get` found but refused (unreadable, checksum, non-finite values, not a
        regular file) and removed, so the bake made them again.
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
        # this tool's folders, top down: from .relight_cache (or root) to this key's folder
        parts = self.folder.split(os.sep)
        top = (max(i for i, p in enumerate(parts) if p == CACHE_FOLDER)
               if CACHE_FOLDER in parts else len(self.root.split(os.sep)) - 1)
        self._chain = [os.sep.join(parts[:i + 1]) or os.sep for i in range(top, len(parts))]
        self._check()
        self.secret = chunk_key()

    def _check(self) -> None:
        """UntrustedFileError unless every folder of the cache is a real folder or absent."""
        for folder in self._chain:
            if not untrusted.real_folder(folder):
                break

    def path(self, chunk: str) -> str:
        safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(chunk))
        return os.path.join(self.folder, safe + ".npy")

    def _signature(self, p: str, data: str | None = None) -> str:
        """The checksum line of chunk file ``p`` (its bytes from ``data``, default ``p``)."""
        return MAC_PREFIX + mac(data or p, self.secret, os.path.basename(p))

    def get(self, chunk: str, shape: tuple | None = None, dtype=None, lo: float | None = None,
            hi: float | None = None) -> np.ndarray | None:
        """The stored array of ``chunk``, or None. A chunk that fails a check -- it is not a
        regular file, its header is not the expected ``shape`` / ``dtype`` (read before the
        data), it does not read (truncated), its keyed checksum differs, it holds NaN or inf,
        or values outside ``[lo, hi]`` -- is removed (a link itself, never its target),
        counted in :attr:`rejected` and treated as missing (baked again)."""
        self._check()
        p = self.path(chunk)
        if not os.path.lexists(p):
            return None
        arr = None
        try:   # header, then the keyed checksum of every byte, then the data
            _check_header(p, shape, None if dtype is None else np.dtype(dtype))
            untrusted.regular_file(p + ".sha256", 4096)
            with open(p + ".sha256", encoding="ascii") as fh:
                ok = hmac.compare_digest(fh.read(4096).strip(), self._signature(p))
            if ok:
                arr = np.load(p, allow_pickle=False)
        except (UntrustedFileError, OSError, ValueError, EOFError, UnicodeDecodeError):
            ok = False
        if ok and arr.dtype.kind == "f":
            ok = bool(np.isfinite(arr).all())
        if ok and lo is not None and arr.size:
            ok = float(arr.min()) >= lo
        if ok and hi is not None and arr.size:
            ok = float(arr.max()) <= hi
        if not ok:
            for q in (p, p + ".sha256", p + ".device"):
                _unlink(q)
            self.rejected += 1
            return None
        dev_note = p + ".device"
        if os.path.lexists(dev_note):   # another device's chunk, adopted by --mix-devices
            try:
                untrusted.regular_file(dev_note, 4096)
                with open(dev_note, encoding="utf-8") as fh:
                    dev = fh.read(4096).strip()
            except (UntrustedFileError, OSError, ValueError):
                dev = "unknown"
            if not self.adopt_devices:
                for q in (p, p + ".sha256", dev_note):
                    _unlink(q)
                self.other_devices[dev] = self.other_devices.get(dev, 0) + 1
                return None
            self.mixed_devices[dev] = self.mixed_devices.get(dev, 0) + 1
        self.reused += 1
        return arr

    def _make_folder(self) -> None:
        self._check()
        os.makedirs(self.folder, exist_ok=True)
        self._check()
        key_file = os.path.join(self.folder, "key.json")
        if not os.path.lexists(key_file):   # what the chunks depend on, for a person to read
            atomic.write_json(key_file, self.key, default=str)

    def put(self, chunk: str, array) -> None:
        """Store ``chunk``'s array (its dtype kept: store what the bake stores) with its keyed
        checksum."""
        self._make_folder()
        array = np.asarray(array)
        p = self.path(chunk)
        _unlink(p + ".device")   # baked here now, not adopted
        with atomic.atomic_path(p) as tmp:   # (a rename: replaces a link, never writes into it)
            np.save(tmp, array, allow_pickle=False)
            signature = self._signature(p, tmp)
        atomic.write_text(p + ".sha256", signature + "\n")
        self.written += 1

    def prune_others(self, adopt_devices: bool = False) -> int:
        """Remove the folders of other keys under ``root`` (stale after a scene or settings
        change); returns how many were removed. Only key folders (20 hex digits) go: a
        folder of another name is another stage's cache nested here, with its own key. A key
        folder that is a symbolic link (or not a folder) is refused (UntrustedFileError): it
        is never removed or adopted from through the link.

        A folder whose key differs only in its ``device`` holds the same chunks baked on
        another device (another sample set). By default it is removed and counted in
        :attr:`other_devices` (those chunks are baked again). With ``adopt_devices`` (the user
        agreed: ``--mix-devices``) its chunks this key lacks move into this key's folder first,
        each with a ``.device`` note of where it came from; :meth:`get` reuses them (counted in
        :attr:`mixed_devices`) only while adopting, and otherwise bakes them again (counted in
        :attr:`other_devices`), also in a later run."""
        self.adopt_devices = adopt_devices
        self._check()
        if not untrusted.real_folder(self.root):
            return 0
        others = [os.path.join(self.root, name) for name in sorted(os.listdir(self.root))
                  if _is_key_name(name) and name != os.path.basename(self.folder)]
        for p in others:   # all checked before any goes
            untrusted.real_folder(p)
        gone = 0
        for p in others:
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
        folder; returns how many. Only regular files move (a link is left to the removal of
        ``folder``, which removes the link itself)."""
        self._make_folder()
        n = 0
        for f in sorted(os.listdir(folder)):
            src = os.path.join(folder, f)
            if not f.endswith(".npy") or os.path.lexists(os.path.join(self.folder, f)):
                continue
            try:
                untrusted.regular_file(src)
                untrusted.regular_file(src + ".sha256", 4096)
            except UntrustedFileError:
                continue
            atomic.write_text(os.path.join(self.folder, f + ".device"), device + "\n")
            atomic.move(src + ".sha256", os.path.join(self.folder, f + ".sha256"))
            atomic.move(src, os.path.join(self.folder, f))
            n += 1
        return n

    def _other_device(self, folder: str) -> str | None:
        """The device of ``folder``'s key when it equals this key but for ``device``."""
        if "device" not in self.key:
            return None
        try:
            other = untrusted.read_json(os.path.join(folder, "key.json"))
        except UntrustedFileError:
            return None
        if other.get("device", "CPU") == self.key["device"]:
            return None
        mine = json.loads(json.dumps(self.key, default=str))   # as key.json holds it
        rest = {k: v for k, v in other.items() if k != "device"}
        return str(other.get("device", "CPU")) if rest == {
            k: v for k, v in mine.items() if k != "device"} else None

    def clear(self) -> None:
        """Remove this key's chunks, and ``root`` (and its parent) when left empty (real
        folders only: a link is never removed through)."""
        self._check()
        if untrusted.real_folder(self.folder):
            shutil.rmtree(self.folder, ignore_errors=True)
        for folder in (self.root, os.path.dirname(self.root)):
            try:
                if not untrusted.real_folder(folder):
                    continue
                os.rmdir(folder)
            except (OSError, UntrustedFileError):
                break
