"""Contact sheets: linear images to 8-bit sRGB, and a PNG writer (captioned layouts are in
:mod:`.label`).

The PNG writer uses only the standard library (zlib), so sheets can be written from the CLI,
the demo and tests without Pillow.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from . import atomic


def linear_to_srgb8(image: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear RGB (any float shape (..., 3)) -> 8-bit sRGB, values clipped to [0, 1] first."""
    x = np.clip(np.asarray(image, dtype=np.float64) * exposure, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.rint(srgb * 255.0).astype(np.uint8)


def write_png(path: str, rgb8: np.ndarray) -> int:
    """Write an (H, W, 3) uint8 image (row 0 at the top) as PNG atomically; returns bytes."""
    a = np.ascontiguousarray(rgb8, dtype=np.uint8)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) uint8 image, got {a.shape}")
    h, w = a.shape[:2]
    raw = b"".join(b"\x00" + a[y].tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    return atomic.write_bytes(path, png)


def read_png(path: str) -> np.ndarray:
    """Read back an 8-bit RGB PNG written by :func:`write_png` (filter type 0 only)."""
    with open(path, "rb") as fh:
        data = fh.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"not a PNG file: {path}")
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            w, h = struct.unpack(">II", body[:8])
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = np.frombuffer(zlib.decompress(idat), dtype=np.uint8).reshape(h, 1 + 3 * w)
    if np.any(raw[:, 0] != 0):
        raise ValueError("only unfiltered PNG rows are supported")
    return raw[:, 1:].reshape(h, w, 3)
