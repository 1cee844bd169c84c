"""Files from elsewhere: one place decides what a name read from a file may touch, and what a
file's bytes may make this process allocate.

A bake folder, a report, a ``.blend``'s records and the chunk cache may come from someone else
(an asset pack, a colleague, a render farm): they are *untrusted input* (``docs/security.md``).
PEP 706's ``tarfile`` filters are the model -- every name becomes a path here or nowhere:

- :func:`confined` joins a *basename* read from such a file under the real path of the folder it
  belongs to, refusing ``..``, absolute paths, separators, NUL, and (checked with ``lstat``,
  never following) symlinks, FIFOs, sockets and devices.
- :func:`regular_file` / :func:`real_folder` check a path the tool itself built the same way.
- :func:`read_json`, :func:`npy_header`, :func:`load_npy` and :func:`open_npz` read with caps:
  bytes before parsing, the header before the data, the decompressed size of every NPZ member
  (and its ratio to the compressed size) before it is inflated.
- :func:`check_values` refuses NaN/inf and values out of a stated range.

Every refusal is an :class:`UntrustedFileError` (an :class:`~lt_addon.errors.InputError`)
whose message reads ``<file>: <cause>``: the CLI prints it as ``relight: error: ...`` with exit
status 2, the panel as one report line.
"""

from __future__ import annotations

import json
import os
import stat
import tokenize
import zipfile
import zlib

import numpy as np

from ..errors import InputError

__all__ = ["UntrustedFileError", "confined", "regular_file", "real_folder", "read_json",
           "npy_header", "load_npy", "open_npz", "check_values", "check_shape",
           "MAX_JSON_BYTES", "MAX_ARRAY_BYTES", "MAX_RESOLUTION", "MAX_DIRECTIONS",
           "MAX_ZIP_RATIO", "MAX_CHANNELS", "CHECKSUM_MAX_BYTES", "field", "check_count",
           "file_checksum", "check_checksum", "check_sparse", "sparse_matrix", "npz_scalar"]

#: caps on what a file may make this process read or allocate (generous for real bakes: a
#: 16384^2 texture, 65536 directions; far below what exhausts a workstation's memory by accident)
MAX_JSON_BYTES = 64 * 2**20          # a report or header: real ones are < 1 MiB
MAX_ARRAY_BYTES = 64 * 2**30         # one array on disk (T of production at 2048^2 is ~5.6 GB)
MAX_RESOLUTION = 16384               # a texture's side
MAX_DIRECTIONS = 65536               # directions of one direction set
MAX_ZIP_RATIO = 1100                 # deflate's own ceiling is ~1032:1; more is a crafted file
MAX_CHANNELS = 4096                  # channels of one EXR (a steerable texture of order 12: 432)
#: T above this many bytes is not hashed on load: its values are range-checked instead
#: (:func:`check_checksum`). SHA-256 measured 0.53 s/GiB on an idle core (SHA-NI, bytes in
#: memory) and 1.0-1.7 s/GiB reading a 50 MiB T from the page cache on a busy 2-core machine
#: (2026-12-06): over the ~1 s a GiB a load may spend, so T is verified up to 256 MiB (512^2 at
#: 400 directions: ~0.1-0.4 s) and larger ones rely on the range check (~0.3 s/GiB as read).
CHECKSUM_MAX_BYTES = 256 << 20


class UntrustedFileError(InputError):
    """A file from a bake folder, report, cache or record that cannot be used as it is."""

    def __init__(self, path, cause: str):
        self.path = os.fspath(path) if path is not None else ""
        self.cause = cause
        super().__init__(f"{self.path}: {cause}" if self.path else cause)


# ------------------------------------------------------------------------------------------
# names and paths

def _kind(mode: int) -> str | None:
    """What a non-regular, non-folder file is, by its ``lstat`` mode (None: file or folder)."""
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return None


def check_name(name) -> str:
    """``name`` when it is a plain basename (no separator, not ``.``/``..``, no NUL, not
    empty, not absolute, no drive); UntrustedFileError otherwise."""
    if not isinstance(name, str) or not name:
        raise UntrustedFileError(None, f"{name!r} is not a file name")
    bad = ("/" in name or "\\" in name or "\x00" in name or name in (".", "..")
           or os.path.isabs(name) or os.path.splitdrive(name)[0] or ":" in name)
    if bad:
        raise UntrustedFileError(None, f"{name!r} is not a plain file name (only names inside "
                                       "the bake's folder are followed)")
    return name


def confined(root: str, name, *, must_exist: bool = False, folder: bool | None = None) -> str:
    """The path of basename ``name`` under the real path of ``root``, refusing anything that
    could lead elsewhere: a name with a separator, ``..``, an absolute path, and an existing
    entry that is a symlink, FIFO, socket or device (``lstat``: links are never followed).
    ``must_exist``: refuse a missing entry; ``folder``: True/False to require a folder/file."""
    check_name(name)
    base = os.path.realpath(root)
    path = os.path.join(base, name)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        if must_exist:
            raise UntrustedFileError(path, "is missing") from None
        return path
    except OSError as exc:
        raise UntrustedFileError(path, f"cannot be read ({exc.strerror})") from None
    kind = _kind(st.st_mode)
    if kind:
        raise UntrustedFileError(path, f"is {kind}; refused (a bake folder holds plain files)")
    is_dir = stat.S_ISDIR(st.st_mode)
    if folder is True and not is_dir:
        raise UntrustedFileError(path, "is not a folder")
    if folder is False and is_dir:
        raise UntrustedFileError(path, "is a folder where a file was expected")
    return path


def regular_file(path: str, max_bytes: int | None = None) -> int:
    """Size of ``path`` when it is a regular file (``lstat``: a symlink, FIFO or device is
    refused, so a read never blocks or leaves the folder) of at most ``max_bytes``."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise UntrustedFileError(path, "is missing") from None
    except OSError as exc:
        raise UntrustedFileError(path, f"cannot be read ({exc.strerror})") from None
    kind = _kind(st.st_mode)
    if kind:
        raise UntrustedFileError(path, f"is {kind}; refused")
    if not stat.S_ISREG(st.st_mode):
        raise UntrustedFileError(path, "is not a regular file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise UntrustedFileError(path, f"is {st.st_size} bytes, more than the {max_bytes} "
                                       "this kind of file may have")
    return st.st_size


def real_folder(path: str) -> bool:
    """True when ``path`` is a real folder (not a symlink to one); False when absent;
    UntrustedFileError when something else stands there."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return False
    if stat.S_ISDIR(st.st_mode):
        return True
    kind = _kind(st.st_mode) or "a file"
    raise UntrustedFileError(path, f"is {kind} where this tool keeps a folder; refused (remove "
                                   "it to go on)")


# ------------------------------------------------------------------------------------------
# reading with caps

def read_json(path: str, max_bytes: int = MAX_JSON_BYTES, kind: type | None = dict):
    """The parsed JSON of regular file ``path`` (at most ``max_bytes``), of type ``kind``."""
    size = regular_file(path, max_bytes)
    try:
        with open(path, "rb") as fh:   # (read(n) allocates n bytes first: the file's size)
            data = json.loads(fh.read(min(size, max_bytes) + 1).decode("utf-8"))
    except UnicodeDecodeError:
        raise UntrustedFileError(path, "is not UTF-8 text") from None
    except ValueError as exc:
        raise UntrustedFileError(path, f"is not valid JSON ({exc})") from None
    except RecursionError:
        raise UntrustedFileError(path, "is JSON nested too deeply") from None
    if kind is not None and not isinstance(data, kind):
        raise UntrustedFileError(path, f"holds a JSON {type(data).__name__}, not a "
                                       f"{kind.__name__}")
    return data


#: what numpy's NPY header parser raises on a damaged header (it tokenizes and evaluates the
#: header's text: a cut string is a tokenize.TokenError, deep nesting a RecursionError)
_NPY_HEADER_ERRORS = (ValueError, EOFError, SyntaxError, TypeError, tokenize.TokenError,
                      UnicodeDecodeError, OverflowError, RecursionError, MemoryError)


def read_npy_header(fh, path: str, kinds: str = "biuf"):
    """(shape, fortran_order, dtype, data offset) of the NPY stream ``fh`` at its start: the
    one parser of NPY headers from elsewhere (bake files, chunk caches, staged files), format
    1.0 / 2.0 only, headers of at most 10,000 bytes, dtype kinds in ``kinds`` (``"V"``:
    structured records of numbers), no Python objects, no negative dimension."""
    try:
        version = np.lib.format.read_magic(fh)
        read = {(1, 0): np.lib.format.read_array_header_1_0,
                (2, 0): np.lib.format.read_array_header_2_0}.get(version)
        if read is None:
            raise ValueError(f"NPY format {version} is not read by this tool")
        shape, fortran, dtype = read(fh, max_header_size=10000)
    except _NPY_HEADER_ERRORS as exc:
        raise UntrustedFileError(path, f"is not a whole NPY file (its header: "
                                       f"{_short(exc, 120)})") from None
    if dtype.hasobject or dtype.kind not in kinds:
        raise UntrustedFileError(path, f"holds {dtype}, not numbers")
    if any(int(n) < 0 for n in shape):
        raise UntrustedFileError(path, f"has a negative dimension {shape}")
    return tuple(int(n) for n in shape), bool(fortran), dtype, fh.tell()


def npy_header(path: str, max_bytes: int = MAX_ARRAY_BYTES):
    """(shape, fortran_order, dtype, data offset) of NPY file ``path``, read from its header
    alone, after checking the file is regular, capped, and as long as the header says."""
    size = regular_file(path, max_bytes)
    with open(path, "rb") as fh:
        shape, fortran, dtype, offset = read_npy_header(fh, path)
    need = offset + int(np.prod(shape, dtype=object)) * dtype.itemsize
    if need > size:
        raise UntrustedFileError(path, f"is truncated ({size} of the {need} bytes its header "
                                       "says)")
    return shape, fortran, dtype, offset


def check_shape(path: str, shape, expect, dtype=None, expect_dtype=None) -> None:
    """UntrustedFileError unless ``shape`` matches ``expect`` (None entries: any length) and
    ``dtype`` is ``expect_dtype`` (a dtype, or a kind string such as ``"f"``)."""
    shape = tuple(shape)
    if expect is not None:
        expect = tuple(expect)
        if len(shape) != len(expect) or any(e is not None and int(e) != s
                                            for s, e in zip(shape, expect)):
            want = "(" + ", ".join("*" if e is None else str(e) for e in expect) + ")"
            raise UntrustedFileError(path, f"has shape {shape}, expected {want}")
    if expect_dtype is not None and dtype is not None:
        ok = (np.dtype(dtype).kind in expect_dtype if isinstance(expect_dtype, str)
              else np.dtype(dtype) == np.dtype(expect_dtype))
        if not ok:
            raise UntrustedFileError(path, f"holds {np.dtype(dtype)}, expected {expect_dtype}")


def load_npy(path: str, *, shape=None, dtype=None, mmap: bool = False,
             max_bytes: int = MAX_ARRAY_BYTES) -> np.ndarray:
    """NPY file ``path`` checked against its header *before* its data is read: regular file,
    at most ``max_bytes``, numeric dtype (``dtype``: an exact dtype or kind letters), shape
    ``shape`` (None entries: any), whole. ``mmap``: a read-only memory map."""
    hshape, _, hdtype, _ = npy_header(path, max_bytes)
    check_shape(path, hshape, shape, hdtype, dtype)
    try:
        return np.load(path, mmap_mode="r" if mmap else None, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise UntrustedFileError(path, f"cannot be read ({exc})") from None


#: what zipfile and zlib raise on a damaged archive (a bad local header, a member compressed
#: with a method zipfile lacks, an "encrypted" flag, a corrupt deflate stream)
_ZIP_ERRORS = (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error,
               NotImplementedError, RuntimeError)


def _short(exc: BaseException, limit: int = 200) -> str:
    """``exc``'s message cut to ``limit`` characters (zipfile quotes whole headers)."""
    text = str(exc)
    return text if len(text) <= limit else text[:limit] + "..."


class _Npz:
    """A checked NPZ: members are inflated only after their stated sizes passed the caps."""

    def __init__(self, path: str, max_bytes: int, max_ratio: float, stored: bool = False):
        self.path = path
        regular_file(path, max_bytes)
        try:
            self.zf = zipfile.ZipFile(path)
        except _ZIP_ERRORS as exc:   # (a damaged version field: NotImplementedError)
            raise UntrustedFileError(path, f"is not a whole NPZ file ({_short(exc)})") from None
        total = 0
        self.members = {}
        for info in self.zf.infolist():
            name = info.filename
            if not name.endswith(".npy"):
                continue
            if info.file_size > max_bytes:
                self.close()
                raise UntrustedFileError(path, f"member {name} inflates to {info.file_size} "
                                               f"bytes, more than {max_bytes}")
            if stored and info.compress_type != zipfile.ZIP_STORED:
                self.close()
                raise UntrustedFileError(path, f"member {name} is compressed; this tool writes "
                                               "these files uncompressed (refused before it is "
                                               "inflated)")
            if info.compress_size and info.file_size / info.compress_size > max_ratio:
                self.close()
                raise UntrustedFileError(path, f"member {name} inflates {info.file_size} "
                                               f"bytes from {info.compress_size}: refused "
                                               "(a compression bomb?)")
            total += info.file_size
            self.members[name[:-4]] = info
        if total > max_bytes:
            self.close()
            raise UntrustedFileError(path, f"inflates to {total} bytes, more than {max_bytes}")

    def __contains__(self, key) -> bool:
        return key in self.members

    def keys(self):
        return list(self.members)

    files = property(keys)

    def header(self, key):
        """(shape, dtype) of member ``key`` from its NPY header alone."""
        try:
            with self.zf.open(self.members[key]) as fh:
                # (NPZ files hold their strings as fixed-width unicode scalars, kind "U")
                shape, _, dtype, _ = read_npy_header(fh, f"{self.path}[{key}]", "biufU")
        except _ZIP_ERRORS as exc:
            raise UntrustedFileError(self.path, f"member {key} cannot be read "
                                                f"({_short(exc)})") from None
        return shape, dtype

    def get(self, key, shape=None, dtype=None) -> np.ndarray:
        """Member ``key``, its header checked against ``shape`` / ``dtype`` first."""
        if key not in self.members:
            raise UntrustedFileError(self.path, f"has no array {key!r}")
        hshape, hdtype = self.header(key)
        check_shape(f"{self.path}[{key}]", hshape, shape, hdtype, dtype)
        need = int(np.prod(hshape, dtype=object)) * hdtype.itemsize
        if need > self.members[key].file_size:
            raise UntrustedFileError(self.path, f"member {key} is truncated")
        try:
            with self.zf.open(self.members[key]) as fh:
                return np.lib.format.read_array(fh, allow_pickle=False)
        except _ZIP_ERRORS as exc:
            raise UntrustedFileError(self.path, f"member {key} cannot be read "
                                                f"({_short(exc)})") from None

    def __getitem__(self, key) -> np.ndarray:
        return self.get(key)

    def close(self) -> None:
        self.zf.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def open_npz(path: str, *, max_bytes: int = MAX_ARRAY_BYTES,
             max_ratio: float = MAX_ZIP_RATIO, stored: bool = False) -> _Npz:
    """NPZ file ``path`` opened for checked reads (a context manager with ``z[key]``,
    ``key in z``, ``z.get(key, shape=, dtype=)``): a regular file at most ``max_bytes`` whose
    members together inflate to at most ``max_bytes``, none by more than ``max_ratio`` : 1.
    ``stored``: every member must be stored uncompressed (formats this tool has always written
    with ``np.savez``: a deflated member, a possible bomb of ~1000:1, is refused unread)."""
    return _Npz(path, max_bytes, max_ratio, stored)


_EXP_BITS = {2: 0x7C00, 4: 0x7F800000, 8: 0x7FF0000000000000}
_INT = {2: (np.int16, np.uint16), 4: (np.int32, np.uint32), 8: (np.int64, np.uint64)}


def _float_range(part: np.ndarray):
    """(min, max, all finite) of float block ``part`` from two integer reductions over its
    bits (IEEE floats order like sign-magnitude integers): as signed integers the largest is
    the largest non-negative value (or NaN/inf above it); as unsigned, the largest with the
    sign bit set is the most negative value (or a negative NaN/inf). Float16 min/max in NumPy
    is emulated; this ran at ~12 GB/s against 0.5 GB/s for ``isfinite`` + ``min`` + ``max``
    (50 MiB of float16: 4 ms against 130 ms)."""
    n = part.dtype.itemsize
    if n not in _INT or not part.dtype.isnative:
        p = part.astype(np.float64)
        mn, mx = float(p.min()), float(p.max())
        return mn, mx, bool(np.isfinite(mn) and np.isfinite(mx))
    si, ui = _INT[n]
    exp = _EXP_BITS[n]
    sign = 1 << (8 * n - 1)
    imax = int(part.view(si).max())
    umax = int(part.view(ui).max())
    finite = True
    mx = mn = None
    if imax >= 0:                                   # some value has its sign bit clear
        finite &= imax < exp
        mx = float(np.array(imax, si).view(part.dtype))
    if umax >= sign:                                # some value has its sign bit set
        mag = umax - sign
        finite &= mag < exp
        mn = -float(np.array(mag, si).view(part.dtype))
    if mx is None:          # all negative: the largest is the negative of smallest magnitude
        mx = -float(np.array(int(part.view(ui).min()) - sign, si).view(part.dtype))
    if mn is None:          # all non-negative: the smallest is the one of smallest bits
        mn = float(np.array(int(part.view(si).min()), si).view(part.dtype))
    return mn, mx, finite


def check_values(path: str, arr, *, lo: float | None = None, hi: float | None = None,
                 what: str = "values", block: int = 1 << 24) -> None:
    """UntrustedFileError when float ``arr`` holds NaN or inf, or values outside
    ``[lo, hi]``; read in blocks of ``block`` values (a memory map is never loaded whole).
    Costs two integer reductions per value (:func:`_float_range`): 4 ms for 50 MiB of float16
    (T of 400 directions at 256^2) once in the page cache."""
    a = np.asarray(arr) if not isinstance(arr, np.ndarray) else arr
    flat = a.reshape(-1) if a.flags.c_contiguous or a.flags.f_contiguous else np.ravel(a)
    for s in range(0, flat.size, block):
        part = np.ascontiguousarray(flat[s:s + block])
        if not part.size:
            continue
        if part.dtype.kind == "f":
            mn, mx, finite = _float_range(part)
            if not finite:
                raise UntrustedFileError(path, f"holds NaN or infinite {what}")
        else:
            mn, mx = part.min(), part.max()
        if lo is not None and mn < lo:
            raise UntrustedFileError(path, f"holds {what} below {lo:.6g} ({float(mn):.4g})")
        if hi is not None and mx > hi:
            raise UntrustedFileError(path, f"holds {what} above {hi:.6g} ({float(mx):.4g})")


# ------------------------------------------------------------------------------------------
# fields of a parsed document, counts, checksums, sparse matrices

_MISSING = object()


def field(doc, key: str, path: str, kind=None, default=_MISSING, *, where: str = ""):
    """``doc[key]`` of a document read from file ``path``, of type ``kind`` (a type or a
    tuple; ``int``/``float`` refuse bools, ``float`` takes ints): ``<file>: has no <key>``
    when it is missing (unless ``default``), ``<file>: <key> is a <type>, not ...`` when it is
    of another type. ``where``: the enclosing key for the message (``settings.table_size``)."""
    name = f"{where}.{key}" if where else str(key)
    if not isinstance(doc, dict):
        raise UntrustedFileError(path, f"{where or 'its top level'} is not a JSON object")
    if key not in doc:
        if default is not _MISSING:
            return default
        raise UntrustedFileError(path, f"has no {name}")
    value = doc[key]
    if kind is None:
        return value
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if float in kinds and int not in kinds:
        kinds = kinds + (int,)
    ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
    if ok and isinstance(value, float) and not np.isfinite(value):
        ok = False
    if not ok:
        want = " or ".join(k.__name__ for k in kinds)
        raise UntrustedFileError(path, f"{name} is {type(value).__name__} {value!r:.40}, "
                                       f"not {want}")
    return value


def check_count(path: str, n, cap: int, what: str, lo: int = 0) -> int:
    """``int(n)`` when it is an integer in ``lo..cap``; one line naming ``path`` otherwise
    (a count read from a file sizes an allocation only after this)."""
    try:
        v = int(n)
        ok = v == n and lo <= v <= cap
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise UntrustedFileError(path, f"{what} is {n!r:.40}, not an integer in {lo}..{cap}")
    return v


def file_checksum(path: str, chunk: int = 1 << 22) -> str:
    """``"sha256:<hex>"`` of file ``path``, read in chunks (0.53 s/GiB on an idle core: SHA-256
    with the CPU's SHA extensions beat BLAKE2b's 0.77 s/GiB here)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while True:
            b = fh.read(chunk)
            if not b:
                break
            h.update(b)
    return "sha256:" + h.hexdigest()


def check_checksum(path: str, recorded, max_bytes: int = CHECKSUM_MAX_BYTES) -> bool:
    """Compare file ``path`` with the checksum a report ``recorded`` for it at bake time.

    Returns True when verified, False when there was nothing to verify (``recorded`` None: a
    report written before checksums) or the file is larger than ``max_bytes``
    (:data:`CHECKSUM_MAX_BYTES`) -- hashing T of a production bake (2048^2, 400 directions:
    3.4 GB) would add 2-6 s to every relight, so there the loaders rely on the range check of
    T's values (integer reductions over the rows read: a relight reads a few rows, a dense
    pass ~0.3 s/GiB) and on its header checks. Garbage in range (a T from another bake of the
    same size) is then not detected above the cap. UntrustedFileError ``<file>: does not match the checksum
    its report records (changed after the bake?)`` otherwise."""
    if recorded is None:
        return False
    if not isinstance(recorded, str) or not recorded.startswith("sha256:"):
        raise UntrustedFileError(path, f"its report records a checksum {recorded!r:.40} this "
                                       "version does not know")
    size = regular_file(path)
    if size > max_bytes:
        return False
    if file_checksum(path) != recorded:
        raise UntrustedFileError(path, "does not match the checksum its report records "
                                       "(changed after the bake?)")
    return True


def check_sparse(path: str, indices, indptr, n_major: int, n_minor: int, nnz=None) -> None:
    """The index arrays of a CSR (CSC) matrix read from ``path``, checked before SciPy sees
    them (its C++ kernels index without bounds checks): ``indptr`` integer, of length
    ``n_major + 1``, starting at 0, non-decreasing, ending at ``len(indices)`` (== ``nnz``,
    the data's length); ``indices`` integer in ``0..n_minor - 1``. O(nnz) in NumPy: cheaper
    than building the matrix and calling ``check_format(full_check=True)`` (which also sorts
    nothing but copies) and it runs before any SciPy code."""
    indices, indptr = np.asarray(indices), np.asarray(indptr)
    if indices.dtype.kind not in "iu" or indptr.dtype.kind not in "iu":
        raise UntrustedFileError(path, "holds sparse indices that are not integers")
    if indices.ndim != 1 or indptr.ndim != 1:
        raise UntrustedFileError(path, "holds sparse index arrays that are not 1-D")
    if len(indptr) != int(n_major) + 1:
        raise UntrustedFileError(path, f"holds a sparse matrix whose indptr has {len(indptr)} "
                                       f"entries, expected {int(n_major) + 1}")
    if nnz is not None and int(nnz) != len(indices):
        raise UntrustedFileError(path, f"holds a sparse matrix with {int(nnz)} values but "
                                       f"{len(indices)} indices")
    if indptr[0] != 0 or int(indptr[-1]) != len(indices) or np.any(np.diff(indptr) < 0):
        raise UntrustedFileError(path, "holds a sparse matrix whose indptr is not a "
                                       "non-decreasing run from 0 to its number of values")
    if len(indices) and (int(indices.min()) < 0 or int(indices.max()) >= int(n_minor)):
        raise UntrustedFileError(path, f"holds a sparse matrix with indices outside "
                                       f"0..{int(n_minor) - 1}")


def sparse_matrix(path: str, fmt: str, data, indices, indptr, shape):
    """A ``"csr"`` / ``"csc"`` scipy.sparse matrix from arrays read from ``path``, after
    :func:`check_sparse` (data numeric and finite too)."""
    from scipy import sparse

    rows, cols = (int(shape[0]), int(shape[1]))
    major, minor = (rows, cols) if fmt == "csr" else (cols, rows)
    data = np.asarray(data)
    if data.ndim != 1 or data.dtype.kind not in "fiu":
        raise UntrustedFileError(path, "holds sparse values that are not a 1-D numeric array")
    check_sparse(path, indices, indptr, major, minor, len(data))
    check_values(path, data, what="sparse values")
    cls = sparse.csr_matrix if fmt == "csr" else sparse.csc_matrix
    return cls((data, indices, indptr), shape=(rows, cols))


def npz_scalar(z, key: str, kind=float):
    """A scalar member of a checked NPZ (``z``: :func:`open_npz`), as ``kind`` (int, float,
    str); one line naming the file when it is missing or not a scalar of that kind."""
    arr = z.get(key, shape=())
    try:
        if kind is str:
            if arr.dtype.kind not in "U":
                raise ValueError
            return str(arr[()])
        v = arr[()]
        if kind is int:
            if arr.dtype.kind not in "iub":
                raise ValueError
            return int(v)
        if arr.dtype.kind not in "iuf" or not np.isfinite(v):
            raise ValueError
        return float(v)
    except (ValueError, TypeError):
        raise UntrustedFileError(z.path, f"member {key} is not a {kind.__name__}") from None


def npz_json(z, key: str = "header") -> dict:
    """A JSON object stored as a uint8 member of a checked NPZ (``z``: :func:`open_npz`),
    capped at MAX_JSON_BYTES; one line naming the file when it is not a JSON object."""
    raw = z.get(key, shape=(None,), dtype=np.uint8)
    if raw.size > MAX_JSON_BYTES:
        raise UntrustedFileError(z.path, f"has a {key} larger than the cap")
    try:
        doc = json.loads(bytes(raw).decode())
    except (ValueError, RecursionError):
        raise UntrustedFileError(z.path, f"has a {key} that is not JSON") from None
    if not isinstance(doc, dict):
        raise UntrustedFileError(z.path, f"has a {key} that is not a JSON object")
    return doc
