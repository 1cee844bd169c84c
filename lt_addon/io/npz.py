"""NPZ files written so that a failure is one exception, not two.

``np.savez`` leaves its ``zipfile.ZipFile`` open when a write fails (a full disk, a file size
limit): the exception propagates, and later the garbage collector's ``ZipFile.__del__`` tries to
finish the file, fails again and prints ``Exception ignored in: <function ZipFile.__del__ ...>``
with a traceback after the bake's one-line error (issue 56). :func:`save_npz` writes the same
format (members ``<key>.npy``, NPY format via ``np.lib.format.write_array``, ZIP64, no pickles)
and closes the archive in every case, keeping the first error.
"""

from __future__ import annotations

import os
import zipfile

import numpy as np

__all__ = ["save_npz"]


def save_npz(file, compressed: bool = False, **arrays) -> None:
    """Write ``arrays`` to ``file`` (a path or a binary file object) as ``np.savez`` /
    ``np.savez_compressed`` would, readable by ``np.load``; object arrays are refused."""
    if isinstance(file, (str, os.PathLike)):
        file = os.fspath(file)
        if not file.endswith(".npz"):   # np.savez's rule, kept: callers pass temporary names
            file += ".npz"
    mode = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    zf = zipfile.ZipFile(file, mode="w", compression=mode, allowZip64=True)
    try:
        for key, value in arrays.items():
            with zf.open(key + ".npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
    except BaseException:
        try:
            zf.close()   # (sets zf.fp to None even when it fails: nothing is left for __del__)
        except Exception:
            pass
        raise
    zf.close()
