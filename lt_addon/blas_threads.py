"""NumPy's and SciPy's BLAS threads, read and set while the process runs.

The wheels of NumPy and SciPy bundle OpenBLAS (``numpy.libs/``, ``scipy.libs/``; ``.dylibs/``
on macOS), whose threads busy-wait for a while after each call. A bake sets them on purpose
(:func:`limited`): one thread while Cycles renders or the ray engine casts (their own threads
have the cores), every core for the fit. Only libraries already loaded are touched (a library
not loaded has no threads); a BLAS this module does not know (Accelerate, MKL, Blender's own
NumPy build) is left as it is and reported as not found.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import glob
import os
import sys

#: (setter, getter) symbol pairs: OpenBLAS, its 64-bit-integer build (NumPy's), SciPy's prefix
_SYMBOLS = [(f"{p}openblas_set_num_threads{s}", f"{p}openblas_get_num_threads{s}")
            for p in ("", "scipy_") for s in ("", "64_")]


@functools.lru_cache(maxsize=None)
def _library(path: str):
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    for set_name, get_name in _SYMBOLS:
        try:
            setter, getter = getattr(lib, set_name), getattr(lib, get_name)
        except AttributeError:
            continue
        setter.argtypes, setter.restype = [ctypes.c_int], None
        getter.argtypes, getter.restype = [], ctypes.c_int
        return setter, getter
    return None


def libraries() -> dict:
    """{library file name: (setter, getter)} of the OpenBLAS builds of the NumPy and SciPy this
    process has imported."""
    out = {}
    for name in ("numpy", "scipy"):
        mod = sys.modules.get(name)
        if mod is None or not getattr(mod, "__file__", None):
            continue
        pkg = os.path.dirname(mod.__file__)
        for folder in (os.path.join(os.path.dirname(pkg), f"{name}.libs"),
                       os.path.join(pkg, ".dylibs"), os.path.join(pkg, ".libs")):
            for path in sorted(glob.glob(os.path.join(folder, "*openblas*"))):
                fns = _library(path)
                if fns is not None:
                    out[os.path.basename(path)] = fns
    return out


def threads() -> dict:
    """{library: threads} now (empty: no BLAS this module can set)."""
    return {name: int(get()) for name, (_, get) in libraries().items()}


def set_threads(n: int) -> None:
    """Set every known BLAS to ``n`` threads (at least 1)."""
    for setter, _ in libraries().values():
        setter(max(1, int(n)))


@contextlib.contextmanager
def limited(n: int):
    """Run the block with every known BLAS at ``n`` threads; restore each one's count after."""
    before = {name: get() for name, (_, get) in libraries().items()}
    set_threads(n)
    try:
        yield
    finally:
        libs = libraries()
        for name, count in before.items():
            if name in libs:
                libs[name][0](count)
