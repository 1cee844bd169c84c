"""The texture bake's indirect light as a PCA over T's directions (bpy-free).

:mod:`.gathered_indirect` gathers the indirect light of every baked direction by rays and finds
its PCA over directions (``I[c, s] ~ sum_j V[s, j] U[j, c]``). Stored per object:

- ``basis_images`` (k, R, R, 3) float32: the component images as outgoing radiance (each gather
  point's ``U`` times its albedo; the bake's Extend margin filled as in every baked image), at
  the indirect grid's side ``R``;
- ``coefficients`` (S, k) float32: ``V``, one row per baked direction (the direct light's
  directions, so a sun's weights ``k_s(w0, a)`` relight both terms).

A sun from ``w0`` of angular size ``a`` then adds ``max(0, sum_s k_s(w0, a) V[s] @ images)``,
an environment of weights ``W[s, c]`` (:func:`.texture.environment_weights`) adds
``max(0, W^T V @ images)``: the same (S, J) "direction matrix" form as the steerable term's
(:func:`.texture.steering_matrix`), so the environment preview and exports take either. The
clamp at 0 removes the PCA's small negatives (4.7 % of the texels at 16 components on the bumps,
>= -0.001 against a mean of 0.0023; measured in docs/bench/2026-transport-log.md).

File: one ``.npz`` (images float16, coefficients float32, a JSON header) -- :func:`save` /
:meth:`GatheredIndirect.load`.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from ..io import atomic, versions
from . import texture as tt
from ..io.npz import save_npz

FORMAT = "relightable_textures.gathered_indirect"


@dataclass
class GatheredIndirect:
    """The gathered indirect term of one object (module docstring).

    Attributes
    ----------
    basis_images : (k, R, R, 3) float32, outgoing radiance per unit coefficient (W m^-2 sr^-1
        per W m^-2 of the sun's normal irradiance), row 0 at v = 0.
    coefficients : (S, k) float32, one row per baked direction of ``directions``.
    directions : DirectionSet -- T's.
    settings : dict -- how it was made (rays, bounces, components, figures).
    """

    basis_images: np.ndarray
    coefficients: np.ndarray
    directions: object
    settings: dict = field(default_factory=dict)
    frame: str = "world"

    def __post_init__(self):
        imgs = np.asarray(self.basis_images, np.float32)
        V = np.asarray(self.coefficients, np.float32)
        if imgs.ndim != 4 or imgs.shape[3] != 3 or imgs.shape[1] != imgs.shape[2]:
            raise ValueError(f"basis_images must have shape (k, R, R, 3), got {imgs.shape}")
        if V.shape != (self.directions.size, imgs.shape[0]):
            raise ValueError(f"coefficients must have shape ({self.directions.size}, "
                             f"{imgs.shape[0]}), got {V.shape}")
        self.basis_images, self.coefficients = imgs, V

    @property
    def resolution(self) -> int:
        return int(self.basis_images.shape[1])

    @property
    def components(self) -> int:
        return int(self.basis_images.shape[0])

    def direction_matrix(self, dset=None) -> np.ndarray:
        """(S, k) float64: the images' weights under a unit sun from each baked direction."""
        if dset is not None and dset.size != self.directions.size:
            raise ValueError(f"this term was gathered over {self.directions.size} directions, "
                             f"not {dset.size}")
        return np.asarray(self.coefficients, np.float64)

    def relight_weights(self, idx, w) -> np.ndarray:
        """(R, R, 3) float32 under the direction weights ``w`` of rows ``idx`` (as
        :func:`.texture.sun_weights`), clamped at 0."""
        c = np.asarray(w, np.float64) @ np.asarray(self.coefficients[np.asarray(idx)],
                                                    np.float64)
        img = np.einsum("j,jyxc->yxc", c, self.basis_images.astype(np.float64))
        return np.maximum(img, 0.0).astype(np.float32)

    def relight(self, direction, sun_angle: float = 0.0, kernel: str = "linear",
                intensity: float = 1.0) -> np.ndarray:
        """(R, R, 3) float32 under a sun from ``direction`` (world, z up) of ``sun_angle``
        degrees, with the direct light's own weights; 0 below the horizon."""
        idx, w = tt.sun_weights(self.directions, direction, sun_angle, kernel)
        if len(idx) == 0:
            return np.zeros(self.basis_images.shape[1:], np.float32)
        return (float(intensity) * self.relight_weights(idx, w)).astype(np.float32)

    def relight_dense(self, weights) -> np.ndarray:
        """(R, R, 3) float32 under dense direction weights (S,) or (S, 3) (an environment)."""
        W = np.asarray(weights, np.float64)
        if W.ndim == 1:
            W = np.repeat(W[:, None], 3, axis=1)
        G = W[:, :3].T @ self.direction_matrix()                          # (3, k)
        img = np.einsum("cj,jyxc->yxc", G, self.basis_images.astype(np.float64))
        return np.maximum(img, 0.0).astype(np.float32)

    def storage_bytes(self) -> int:
        return int(self.basis_images.size * 2 + self.coefficients.size * 4)

    def save(self, path: str, storage: str = "half") -> int:
        """Write the ``.npz`` atomically (images float16 for ``"half"``, else float32);
        returns its size in bytes."""
        if storage not in ("half", "float"):
            raise ValueError(f"storage must be 'half' or 'float', got {storage!r}")
        header = {**versions.stamp(FORMAT), "directions": self.directions.spec,
                  "directions_count": int(self.directions.size), "storage": storage,
                  "settings": self.settings}
        imgs = self.basis_images.astype(np.float16 if storage == "half" else np.float32)
        with atomic.atomic_path(path) as tmp:
            save_npz(tmp, images=imgs, coefficients=self.coefficients,
                     header=np.frombuffer(json.dumps(header).encode(), np.uint8),
                     **{k: np.array(v) for k, v in versions.stamp(FORMAT).items()})
        return os.path.getsize(path)

    @classmethod
    def load(cls, path: str, directions) -> "GatheredIndirect":
        """Read a file written by :meth:`save`; ``directions``: T's (its count is checked).
        Read as a file from elsewhere (:func:`..io.untrusted.open_npz`): the header a capped
        JSON object; ``coefficients`` (S, k) and ``images`` (k, R, R, 3) checked against each
        other and T's S from their headers before they are inflated, k <= S, R <= the cap;
        values finite."""
        from ..io import untrusted as ut

        with ut.open_npz(path, stored=True) as z:
            header = ut.npz_json(z) if "header" in z else {}
            versions.check(header, FORMAT, path, "a gathered indirect term")
            S = directions.size
            coef = z.get("coefficients", shape=(S, None), dtype="f")
            k = coef.shape[1]
            ut.check_count(path, k, S, "components", lo=1)
            shape, _ = z.header("images") if "images" in z else ((), None)
            R = shape[1] if len(shape) == 4 else 0
            ut.check_count(path, R, ut.MAX_RESOLUTION, "resolution", lo=1)
            imgs = z.get("images", shape=(k, R, R, 3), dtype="f")
            ut.check_values(path, coef, what="coefficients")
            ut.check_values(path, imgs, what="image values")
            settings = header.get("settings", {})
            return cls(imgs.astype(np.float32), coef, directions,
                       settings if isinstance(settings, dict) else {})


def indirect_images(term, direction, sun_angle: float = 0.0, kernel: str = "linear"):
    """(R, R, 3) float32: an indirect term (gathered or steerable) under a sun; the steerable
    term takes no sun size."""
    d = np.asarray(direction, np.float64)
    if isinstance(term, GatheredIndirect):
        return term.relight(d, sun_angle, kernel)
    return term.relight(d)


def direction_matrix(term, dset) -> np.ndarray:
    """(S, J) float64 weights of an indirect term's images per baked direction: the gathered
    term's coefficients, or the steerable term's steering matrix."""
    if isinstance(term, GatheredIndirect):
        return term.direction_matrix(dset)
    return tt.steering_matrix(term, dset)


def preview_arrays(term: GatheredIndirect, sun_angle: float, table_size: int,
                   kernel: str = "linear"):
    """What the viewport group samples: (component images (k, R, R, 3), coefficient tables
    (ceil(k / 3), D, D, 3): ``sum_s k_s(w0, a) V[s, j]`` at the sun-disk texel centres,
    component ``j`` in tile ``j // 3``, channel ``j % 3``), float32."""
    tables = tt.coefficient_tables(term.coefficients, term.directions, table_size, sun_angle,
                                   kernel)                                     # (k, D, D)
    k, D = tables.shape[0], tables.shape[1]
    n = -(-k // 3)
    padded = np.zeros((n * 3, D, D), np.float32)
    padded[:k] = tables
    return (term.basis_images.astype(np.float32),
            padded.reshape(n, 3, D, D).transpose(0, 2, 3, 1))


def viewport_relight(images, table_tiles, direction) -> np.ndarray:
    """NumPy twin of the gathered indirect group (intensity 1, white): (R, R, 3) --
    ``max(0, sum_j c_j(w0) images[j])``, the coefficients read bilinearly from the tables;
    0 below the horizon."""
    tab = np.asarray(table_tiles, np.float64)
    n = tab.shape[0]
    c = tt.table_lookup(tab.transpose(0, 3, 1, 2).reshape(n * 3, *tab.shape[1:3]), direction)
    imgs = np.asarray(images, np.float64)
    out = np.einsum("j,jyxc->yxc", c[:len(imgs)], imgs)
    return np.maximum(out, 0.0).astype(np.float32)
