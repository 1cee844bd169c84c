"""The per-vertex transport sidecar (``<object>_transport.npz``) and its shading (bpy-free).

Storage: one ``.npz`` per object holding the model (the mean, the d eigentransports and the
per-vertex coefficients as float32 -- or a CPCA model, Mahajan 2007, in the same slot), the
sample directions and solid angles, the vertices' world positions and normals at bake time (for
local lights), plus the bake's JSON metadata.

Shading (white Lambertian, so values are irradiance / pi, comparable with a Cycles DIFFUSE bake
without the colour pass): ``B = 1/pi (m . Lw + C (E Lw))`` with ``Lw_j = L(w_j) dw_j`` from the
environment (optionally rotated about +z, Nowrouzezahrai 2008 sec. 5) and/or a point light
(sec. 4.2.1). Both models have the same ``shade`` / ``shade_local`` interface.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..io import atomic, exrio
from ..sphere.directions import DirectionSet
from . import cpca as cpca_mod
from . import eigentransport as et_mod
from ..io.npz import save_npz

#: suffix of the raw (V, S) transport samples kept next to a ``<object>_transport.npz`` sidecar
#: (half floats, ``np.save``), so an analysis can reuse them instead of baking again
SAMPLES_SUFFIX = "_transport_samples.npy"


def samples_path(sidecar_path: str) -> str:
    """The samples file that belongs to a ``<object>_transport.npz`` sidecar."""
    stem = sidecar_path[:-len("_transport.npz")] if sidecar_path.endswith(
        "_transport.npz") else os.path.splitext(sidecar_path)[0]
    return stem + SAMPLES_SUFFIX


def save_sidecar(path: str, model, direction_set: DirectionSet, positions, normals,
                 metadata: dict) -> int:
    """Write the ``.npz`` sidecar atomically; returns its size in bytes."""
    arrays = model.to_arrays()
    arrays.update(
        directions=np.asarray(direction_set.directions, np.float64),
        solid_angles=np.asarray(direction_set.solid_angles, np.float64),
        direction_set=np.array(json.dumps(direction_set.to_dict())),
        positions=np.asarray(positions, np.float32), normals=np.asarray(normals, np.float32),
        bake=np.array(json.dumps(metadata)))
    with atomic.atomic_path(path) as tmp:
        save_npz(tmp, **arrays)
    return os.path.getsize(path)


class TransportData:
    """A loaded sidecar: the model (an Eigentransport or a CPCA), its direction set, vertex
    positions/normals and metadata."""

    def __init__(self, path: str):
        if not os.path.isfile(path):
            raise FileNotFoundError(f"transport sidecar not found: {path}")
        from ..io import untrusted as ut

        # a file from elsewhere: a capped NPZ, every member's header checked before it is
        # inflated, the direction count capped, the arrays finite; any refusal names the file
        with ut.open_npz(path, stored=True) as z:
            try:
                self.model = cpca_mod.model_from_arrays(z)
                params = json.loads(ut.npz_scalar(z, "direction_set", str))
                if not isinstance(params, dict):
                    raise ValueError("its direction_set is not a JSON object")
                dirs = z.get("directions", shape=(None, 3), dtype="f")
                ut.check_count(path, len(dirs), ut.MAX_DIRECTIONS, "directions", lo=1)
                self.direction_set = DirectionSet(dirs, z.get("solid_angles", shape=(len(dirs),),
                                                              dtype="f"),
                                                  params.get("kind", "custom"),
                                                  params.get("params", {}))
                V = self.model.n_vertices
                self.positions = np.asarray(z.get("positions", shape=(V, 3), dtype="f"),
                                            np.float64)
                self.normals = np.asarray(z.get("normals", shape=(V, 3), dtype="f"), np.float64)
                ut.check_values(path, self.positions, what="positions")
                ut.check_values(path, self.normals, what="normals")
                self.bake = json.loads(ut.npz_scalar(z, "bake", str))
            except ut.UntrustedFileError:
                raise
            except (ValueError, TypeError, KeyError, IndexError, RecursionError) as exc:
                text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise ut.UntrustedFileError(path, f"is not a usable transport sidecar "
                                                  f"({text})") from None
        self.path = path

    def weighted_environment(self, env, rotate_deg: float = 0.0) -> np.ndarray:
        """``Lw`` (S, 3) of an equirect environment (bottom row first), rotated about +z."""
        ds = self.direction_set
        if not rotate_deg % 360.0:
            return et_mod.project_environment(env, ds.directions, ds.solid_angles,
                                              row_order="bottom_first")
        radiance = et_mod.sample_equirect(env, ds.directions, row_order="bottom_first")
        R = et_mod.rotation_about_axis([0.0, 0.0, 1.0], rotate_deg)
        return et_mod.rotate_environment_samples(radiance, ds, R)

    def shade(self, env=None, rotate_deg: float = 0.0, strength: float = 1.0,
              point_light=None) -> np.ndarray:
        """Per-vertex outgoing radiance of a white Lambertian surface, shape (V, 3), float64,
        never negative (a truncated eigentransport or the point light's nearest-direction
        approximation can dip below 0 -- measured -0.157 with a lamp inside the hull -- and
        light cannot).

        ``point_light`` = (position (3,), power W, colour (3,)).
        """
        out = np.zeros((self.model.n_vertices, 3))
        if env is not None:
            out += self.model.shade(strength * self.weighted_environment(env, rotate_deg))
        if point_light is not None:
            pos, power, color = point_light
            W = et_mod.point_light_weights(self.positions, self.normals, self.direction_set,
                                           pos, power)
            out += self.model.shade_local(W)[:, None] * np.asarray(color, np.float64)[None, :]
        return np.maximum(out, 0.0)

    @property
    def is_clustered(self) -> bool:
        return isinstance(self.model, cpca_mod.CPCA)

    def cluster_colors(self) -> np.ndarray:
        """(V, 3) linear RGB: one colour per CPCA cluster (one colour for eigentransport)."""
        labels = (self.model.labels if self.is_clustered
                  else np.zeros(self.model.n_vertices, dtype=np.int64))
        return cpca_mod.cluster_colors(labels)


def read_environment_exr(path: str) -> np.ndarray:
    """An equirect EXR (R, G, B channels) as (H, W, 3) float64, bottom row first."""
    channels, _ = exrio.read_exr(path)
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        raise ValueError(f"{path} has no {'/'.join(missing)} channel(s); need an RGB "
                         "equirectangular EXR")
    return np.stack([channels[c] for c in "RGB"], -1).astype(np.float64)
