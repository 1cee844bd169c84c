"""Any bake, read from its file in plain Python: one entry point over the four formats, each
versioned and refused in one line when newer than this version reads.

======================================  ===========================================
file                                    :func:`load_bake` returns
======================================  ===========================================
``<object>_texture_report.json``        ``(ObjectBake, TransportStore, report)``:
                                        a transport-texture bundle
                                        (:func:`.transport.bundle.relight`)
``<object>_steerable.exr``              :class:`.steerable.texture.SteerableTexture`
                                        (``.relight(direction)``)
``<object>_transport.npz``              :class:`.transport.sidecar.TransportData`
                                        (``.shade(env, rotation, ...)``)
``<object>_materials.npz``              :class:`.transport.ptt.TransferTensors`
                                        (``.shade(light, colours)``)
======================================  ===========================================
"""

from __future__ import annotations

import os

from .errors import InputError


def load_bake(path: str):
    """The bake in ``path`` (see the table above); InputError for anything else."""
    if not os.path.isfile(path):
        raise InputError(f"no bake file at {path}")
    try:
        if path.endswith(".json"):
            from .transport import bundle

            return bundle.load_bake(path)
        if path.endswith(".exr"):
            from .steerable.texture import SteerableTexture

            return SteerableTexture.load(path)
        if path.endswith(".npz"):
            from .transport import ptt
            from .transport.sidecar import TransportData

            if path.endswith("_materials.npz"):
                return ptt.TransferTensors.load(path)
            return TransportData(path)
    except InputError:
        raise
    except (ValueError, KeyError, OSError) as exc:
        raise InputError(f"{path}: {exc}") from None
    raise InputError(f"{path}: not a bake file (a _texture_report.json, _steerable.exr, "
                     "_transport.npz or _materials.npz)")
