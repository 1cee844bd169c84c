"""Multi-channel OpenEXR files with JSON metadata, written atomically.

Row order: every image array in this package is indexed ``[row, column]`` with **row 0 at the
bottom** (v = 0), the way UV space and Blender's ``Image.pixels`` run. EXR files store the top row
first; :func:`write_exr` and :func:`read_exr` flip, so files look upright in any EXR viewer and
arrays need no flip at the bpy edge.

Metadata is one JSON document in the header attribute ``relight:metadata`` (EXR string
attributes are plain bytes; one JSON string keeps nested values and is easy to read elsewhere).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile

import numpy as np

from . import atomic

HALF_MAX = 65504.0
METADATA_KEY = "relight:metadata"
PIXEL_TYPES = {"half": np.float16, "float": np.float32}


def _openexr():
    try:
        import OpenEXR
    except ImportError as exc:  # pragma: no cover - the package is a hard dependency
        raise ImportError("the OpenEXR package is required (pip install OpenEXR)") from exc
    return OpenEXR


def write_exr(path: str, channels: dict, metadata: dict | None = None,
              pixel_type: str = "half") -> int:
    """Write named channels to ``path`` atomically; returns the file size in bytes.

    Parameters
    ----------
    path : str
        Target ``.exr`` path. Written to a temporary name in the same folder, then renamed, so an
        existing file is replaced only by a complete one.
    channels : dict[str, ndarray of shape (H, W)]
        Channel name -> image, row 0 at the bottom. All the same shape; any real dtype.
    metadata : dict, optional
        JSON-serialisable values stored in the ``relight:metadata`` header attribute.
    pixel_type : {"half", "float"}
        Storage precision. ``"half"`` refuses values outside +-65504 (they would become inf)
        with a ValueError that names the channel -- use ``"float"`` for such data.

    Raises
    ------
    ValueError
        Empty or mismatched channels, NaN/inf values, half-float overflow, unknown pixel type.
    """
    if pixel_type not in PIXEL_TYPES:
        raise ValueError(f"pixel_type must be one of {sorted(PIXEL_TYPES)}, got {pixel_type!r}")
    if not channels:
        raise ValueError("no channels to write")
    shapes = {np.shape(a) for a in channels.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"all channels must be 2D images of one shape, got {sorted(shapes)}")
    dtype = PIXEL_TYPES[pixel_type]
    data = {}
    for name, image in channels.items():
        image = np.asarray(image)
        if not np.all(np.isfinite(image)):
            raise ValueError(f"channel {name!r} has NaN or inf values")
        if pixel_type == "half" and np.abs(image).max(initial=0.0) > HALF_MAX:
            raise ValueError(
                f"channel {name!r} exceeds the half-float range (|x| > {HALF_MAX:g}); "
                "store it as float")
        data[name] = np.ascontiguousarray(image[::-1].astype(dtype))
    OpenEXR = _openexr()
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if metadata is not None:
        if "format" in metadata and "format_version" not in metadata:   # every file versioned
            from .versions import version_of

            metadata = {**metadata, "format_version": version_of(metadata["format"])}
        header[METADATA_KEY] = json.dumps(metadata, sort_keys=True)
    with atomic.atomic_path(path) as tmp, OpenEXR.File(header, data) as exr:
        exr.write(tmp)
    return os.path.getsize(path)


def exr_header(path: str, max_bytes: int | None = None) -> dict:
    """The header of EXR file ``path`` alone (``header_only``: no pixel is read or inflated),
    checked as a file from elsewhere (:mod:`.untrusted`): a regular file with one part, at
    most MAX_CHANNELS channels, a data window of at most MAX_RESOLUTION on a side whose pixels
    (4 bytes a channel at most) take at most ``max_bytes`` (default MAX_ARRAY_BYTES) -- a
    header may claim sizes its compressed data would inflate to. Returns ``dict(header)``
    with ``"width"``, ``"height"`` and ``"channel_names"`` added."""
    from . import untrusted as ut

    cap = ut.MAX_ARRAY_BYTES if max_bytes is None else int(max_bytes)
    if not os.path.lexists(path):
        raise FileNotFoundError(f"EXR file not found: {path}")
    ut.regular_file(path)
    OpenEXR = _openexr()
    try:
        with OpenEXR.File(path, header_only=True) as exr:
            parts = len(exr.parts)
            header = dict(exr.header())
    except (RuntimeError, ValueError, TypeError, IndexError) as exc:
        raise ut.UntrustedFileError(path, f"is not a readable OpenEXR image ({exc})") from None
    if parts != 1:
        raise ut.UntrustedFileError(path, f"has {parts} parts; this tool writes one")
    try:
        lo, hi = (np.asarray(v, np.int64) for v in header["dataWindow"])
        names = [c.name for c in header["channels"]]
    except (KeyError, TypeError, ValueError, AttributeError):
        raise ut.UntrustedFileError(path, "has no data window or channel list") from None
    width, height = int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
    if not (1 <= width <= ut.MAX_RESOLUTION and 1 <= height <= ut.MAX_RESOLUTION):
        raise ut.UntrustedFileError(path, f"is {width} x {height} pixels; the limit is "
                                          f"{ut.MAX_RESOLUTION} on a side")
    if not 1 <= len(names) <= ut.MAX_CHANNELS:
        raise ut.UntrustedFileError(path, f"has {len(names)} channels; the limit is "
                                          f"{ut.MAX_CHANNELS}")
    need = width * height * len(names) * 4
    if need > cap:
        raise ut.UntrustedFileError(path, f"would inflate to {need} bytes of pixels, more than "
                                          f"the {cap} this file may have")
    header.update(width=width, height=height, channel_names=names)
    return header


#: what OpenEXR's C++ library prints on standard error when a chunk of pixels does not decode
#: (it then returns the image with those pixels left unset, and raises nothing)
_DECODE_ERRORS = ("EXR_ERR_", "Exception raised reading pixel data", "Unable to run decoder")


@contextlib.contextmanager
def _library_errors(path: str):
    """Refuse ``path`` when OpenEXR reports a pixel chunk it could not decode. The library
    prints those on file descriptors 2 (``EXR_ERR_...``) and 1 (``Warning: Exception raised
    reading pixel data``) and goes on with a partial image: a damaged file from elsewhere would
    load with holes, and its messages would follow the CLI's one line. So both descriptors go
    to a temporary file while it reads: decode errors become one UntrustedFileError, anything
    else it printed is passed on."""
    from . import untrusted as ut

    saved = {}
    try:
        for fd, stream in ((1, sys.stdout), (2, sys.stderr)):
            if stream is not None:
                stream.flush()
            saved[fd] = os.dup(fd)
    except (OSError, ValueError, AttributeError):   # no such descriptor (a GUI without console)
        for dup in saved.values():
            os.close(dup)
        yield
        return
    with tempfile.TemporaryFile() as sink:
        for fd in saved:
            os.dup2(sink.fileno(), fd)
        try:
            yield
        finally:
            for fd, dup in saved.items():
                os.dup2(dup, fd)
                os.close(dup)
            sink.seek(0)
            said = sink.read(1 << 16).decode("utf-8", "replace")
        errors = [ln.strip() for ln in said.splitlines() if any(e in ln for e in _DECODE_ERRORS)]
        if errors:
            first = errors[0].replace(path, "").strip(": ")
            raise ut.UntrustedFileError(path, f"has pixel data that does not decode ({first[:160]})")
        if said:
            sys.stderr.write(said)


def read_exr(path: str, max_bytes: int | None = None) -> tuple[dict, dict]:
    """Read every channel and the metadata written by :func:`write_exr`, its header checked
    first (:func:`exr_header`: sizes and channel count capped before any pixel is inflated).

    Returns
    -------
    channels : dict[str, ndarray of shape (H, W)]
        Row 0 at the bottom; dtype as stored (float16 or float32).
    metadata : dict
        The ``relight:metadata`` document, or ``{}`` for a file without one.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The file is not an OpenEXR image OpenEXR can read, is larger than the caps, or its
        metadata is not a JSON object (:class:`.untrusted.UntrustedFileError`, naming it).
    """
    from . import untrusted as ut

    exr_header(path, max_bytes)
    OpenEXR = _openexr()
    with _library_errors(path):
        try:
            exr = OpenEXR.File(path, separate_channels=True)  # keep "b00.R" etc. apart
        except RuntimeError as exc:  # OpenEXR's only error for "not an EXR" / unreadable
            raise ut.UntrustedFileError(path, f"is not a readable OpenEXR image ({exc})") from None
        with exr:
            header = dict(exr.header())  # the live header is emptied when the file closes
            try:
                channels = {name: np.ascontiguousarray(ch.pixels[::-1])
                            for name, ch in exr.channels().items()}
            except (RuntimeError, ValueError, TypeError) as exc:
                raise ut.UntrustedFileError(path, f"cannot be read ({exc})") from None
    raw = header.get(METADATA_KEY)
    if isinstance(raw, bytes):
        try:
            raw = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise ut.UntrustedFileError(path, f"its {METADATA_KEY} is not UTF-8") from None
    if not raw:
        return channels, {}
    if not isinstance(raw, str):   # (a flipped type byte: OpenEXR hands an OpaqueAttribute)
        raise ut.UntrustedFileError(path, f"its {METADATA_KEY} is not text")
    try:
        meta = json.loads(raw)
    except (ValueError, RecursionError):
        raise ut.UntrustedFileError(path, f"its {METADATA_KEY} is not JSON") from None
    if not isinstance(meta, dict):
        raise ut.UntrustedFileError(path, f"its {METADATA_KEY} is not a JSON object")
    return channels, meta


def stack_channels(path: str, channels: dict, names, shape) -> np.ndarray:
    """``(H, W, C)`` float32 of ``channels[name]`` for ``names`` read from ``path``, each of
    ``shape`` (H, W) and finite; UntrustedFileError naming the file and the channel otherwise."""
    from . import untrusted as ut

    out = np.empty(tuple(shape) + (len(names),), np.float32)
    for i, name in enumerate(names):
        if name not in channels:
            raise ut.UntrustedFileError(path, f"has no channel {name}")
        ch = channels[name]
        ut.check_shape(f"{path}[{name}]", np.shape(ch), shape)
        out[..., i] = ch
    ut.check_values(path, out)
    return out
