"""A baked steerable illumination texture: basis images + everything needed to relight them.

This is the data a bake produces and the preview consumes (Ashikhmin & Shirley 2002, sec. 6-7):

    T(w0) = clamp( sum_k c_k(w0) B_k ) * gain(w0) * intensity * colour

with ``B_k`` the N = N1^2 basis images (responses to the product basis lights ``b_ij``), ``c_k``
the steering coefficients of the analytic basis at the disk point of the light direction
``w0``, the post-steering clamp (sec. 7.1) and a calibration gain (:mod:`.calibration`) that
maps the broad steered lobe to a directional light of unit normal irradiance, so
``intensity`` is comparable with a Cycles Sun lamp's strength (W/m^2).

Files: one multi-channel EXR (:mod:`.exrio`), channels ``bKK.R/G/B`` (KK = basis index
``i * N1 + j``), metadata holding the basis design, sampled-light centres, calibration, frame,
bake settings and the add-on version. Storage modes:

``float``  float32 channels.
``half``   float16 channels (refused, with a clear message, if a value exceeds 65504).
``u8``     8 bits per texel per channel with per-image min/max (paper sec. 7: 49 x 3 bytes per
           texel in memory); the 0..255 codes are stored exactly in half channels of the EXR
           (EXR has no 8-bit type) and min/max in the metadata.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io import exrio
from .calibration import METHODS as CALIBRATION_METHODS
from .calibration import make_calibration
from .clamp import clamp_steered
from ..sphere.hemisphere import hemisphere_to_disk, normalize_directions
from .sampled_basis import build_sampled_basis
from .basis import paper_basis, steering_coefficients
from ..io.storage import Uint8Encoded, encode_uint8

FRAMES = ("world", "tangent")
STORAGE_MODES = ("float", "half", "u8")
FORMAT_VERSION = 1
_CHANNELS = "RGB"


@dataclass
class SteerableTexture:
    """Basis images of one object and their relighting parameters.

    Attributes
    ----------
    basis_images : ndarray, shape (N, R, R, 3), float32
        Response to basis light ``k = i * N1 + j``; row 0 at v = 0 (bottom). Units: the baked
        quantity (outgoing radiance for ``mode = "radiance"``) per unit basis radiance.
    order : int
        N1 (N = N1^2).
    width : float
        Gaussian width of the basis design (paper 0.01).
    centres : ndarray, shape (K, 2)
        Disk-domain centres of the sampled lights that were baked.
    frame : {"world", "tangent"}
    calibration : str
        Calibration method name (:data:`.calibration.METHODS`).
    settings : dict
        Bake settings and figures (resolution, samples, seed, bounces, mode, timings...).
    """

    basis_images: np.ndarray
    order: int
    width: float
    centres: np.ndarray
    frame: str = "world"
    calibration: str = "steerable_cos"
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        imgs = np.asarray(self.basis_images)
        n = self.order * self.order
        if imgs.ndim != 4 or imgs.shape[0] != n or imgs.shape[3] != 3:
            raise ValueError(f"basis_images must have shape ({n}, R, R, 3), got {imgs.shape}")
        if self.frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, got {self.frame!r}")
        if self.calibration not in CALIBRATION_METHODS:
            raise ValueError(f"calibration must be one of {CALIBRATION_METHODS}, got {self.calibration!r}")
        self.basis_images = imgs.astype(np.float32, copy=False)
        self.centres = np.asarray(self.centres, dtype=np.float64)

    # -- derived objects (cached by paper_basis) ------------------------------------------------
    @property
    def basis(self):
        return paper_basis(self.order, self.width)

    @property
    def resolution(self) -> int:
        return int(self.basis_images.shape[1])

    def calibration_model(self):
        return make_calibration(self.basis, self.calibration)

    # -- relighting -----------------------------------------------------------------------------
    def steering_weights(self, direction) -> tuple[np.ndarray, float]:
        """Steering coefficients and calibration gain for one light direction.

        Parameters
        ----------
        direction : array_like, shape (3,)
            Unit vector towards the light in the bake frame (z up). Below the horizon the
            light is defined as off: coefficients and gain are 0.

        Returns
        -------
        coefficients : ndarray, shape (N,), float64
        gain : float
        """
        d = normalize_directions(np.asarray(direction, dtype=np.float64).reshape(3))
        if d[2] < 0.0:
            return np.zeros(self.order * self.order), 0.0
        c = steering_coefficients(self.basis, hemisphere_to_disk(d))
        gain, offset = self.calibration_model().gain_offset(d)
        if float(offset) != 0.0:
            raise ValueError("calibration with an offset (paper_linear) needs an albedo reference "
                             "image; use steerable_cos for textures")
        return c, float(gain)

    def relight(self, direction, intensity: float = 1.0, color=(1.0, 1.0, 1.0),
                clamp: bool = True) -> np.ndarray:
        """Texture lit by a distant light from ``direction``.

        Parameters
        ----------
        direction : array_like, shape (3,)
            Towards the light, bake frame (z up).
        intensity : float
            Normal irradiance of the light (a Sun lamp's strength in W/m^2).
        color : array_like, shape (3,)
            Linear RGB tint.
        clamp : bool
            Clamp negative steered values to 0 before calibration (paper sec. 7.1).

        Returns
        -------
        texture : ndarray, shape (R, R, 3), float32

        Raises
        ------
        ValueError
            Non-finite ``intensity`` / ``color``, or a result beyond the float32 range (it
            would silently become inf).
        """
        intensity = float(intensity)
        color64 = np.asarray(color, dtype=np.float64)
        if not (np.isfinite(intensity) and np.all(np.isfinite(color64))):
            raise ValueError(f"intensity and color must be finite, got intensity {intensity!r}, "
                             f"color {color!r}")
        c, gain = self.steering_weights(direction)
        flat = self.basis_images.reshape(len(c), -1)
        steered = (c.astype(np.float32) @ flat).reshape(self.basis_images.shape[1:])
        if clamp:
            steered = clamp_steered(steered)
        scale64 = gain * intensity * color64
        top = float(np.max(np.abs(scale64), initial=0.0))
        peak = max(top, top * float(np.max(np.abs(steered), initial=0.0)))
        if peak > float(np.finfo(np.float32).max):   # a float compare: no float32 cast
            raise ValueError(f"relit values would reach {peak:.3g}, beyond the float32 range "
                             f"({np.finfo(np.float32).max:.3g}); lower the intensity")
        scale = scale64.astype(np.float32)
        return (steered * scale).astype(np.float32)

    # -- files ----------------------------------------------------------------------------------
    def metadata(self, storage: str) -> dict:
        return {
            "format": "relightable_textures.steerable_texture",
            "format_version": FORMAT_VERSION,
            "order": int(self.order),
            "width": float(self.width),
            "w": float(self.basis.w),
            "a": [float(v) for v in self.basis.a],
            "centres": self.centres.tolist(),
            "frame": self.frame,
            "calibration": self.calibration,
            "storage": storage,
            "resolution": self.resolution,
            "channel_names": "bKK.R/G/B, KK = i * order + j",
            "settings": self.settings,
        }

    def save(self, path: str, storage: str = "half") -> int:
        """Write the EXR atomically; returns its size in bytes."""
        if storage not in STORAGE_MODES:
            raise ValueError(f"storage must be one of {STORAGE_MODES}, got {storage!r}")
        meta = self.metadata(storage)
        channels = {}
        if storage == "u8":
            enc = encode_uint8(self.basis_images, per_channel=True)
            meta["u8_min"], meta["u8_max"] = enc.lo.tolist(), enc.hi.tolist()
            for k in range(enc.data.shape[0]):
                for ci, cn in enumerate(_CHANNELS):
                    channels[f"b{k:02d}.{cn}"] = enc.data[k, :, :, ci]
            return exrio.write_exr(path, channels, meta, pixel_type="half")
        for k in range(self.basis_images.shape[0]):
            for ci, cn in enumerate(_CHANNELS):
                channels[f"b{k:02d}.{cn}"] = self.basis_images[k, :, :, ci]
        return exrio.write_exr(path, channels, meta, pixel_type=storage)

    @classmethod
    def load(cls, path: str) -> "SteerableTexture":
        """Read a file written by :meth:`save` (any storage mode); images come back float32."""
        from ..io import untrusted as ut

        # a file from elsewhere: the EXR's header is checked (sizes, channel count) before its
        # pixels are inflated (exrio.read_exr), and the metadata's order and resolution must
        # describe the channels the file has before they size anything
        channels, meta = exrio.read_exr(path)
        if meta.get("format") != "relightable_textures.steerable_texture":
            raise ut.UntrustedFileError(path, "is not a steerable texture written by "
                                              "Relightable Textures")
        version = ut.field(meta, "format_version", path, int, 0)
        if version > FORMAT_VERSION:
            raise ut.UntrustedFileError(path, f"was written by a newer version (format "
                                              f"{version}); update the extension")
        order = ut.check_count(path, ut.field(meta, "order", path, int), 12, "order", lo=1)
        r = ut.check_count(path, ut.field(meta, "resolution", path, int),
                           ut.MAX_RESOLUTION, "resolution", lo=1)
        storage = ut.field(meta, "storage", path, str)
        n = order ** 2
        if len(channels) != 3 * n:
            raise ut.UntrustedFileError(path, f"has {len(channels)} channels; order {order} "
                                              f"needs {3 * n}")
        imgs = np.empty((n, r, r, 3), dtype=np.float32)
        for k in range(n):
            for ci, cn in enumerate(_CHANNELS):
                name = f"b{k:02d}.{cn}"
                if name not in channels:
                    raise ut.UntrustedFileError(path, f"has no channel {name}")
                ut.check_shape(f"{path}[{name}]", channels[name].shape, (r, r))
                imgs[k, :, :, ci] = channels[name]
        ut.check_values(path, imgs, what="basis image values")
        try:
            if storage == "u8":
                imgs = Uint8Encoded(imgs.astype(np.uint8),
                                    np.asarray(meta["u8_min"], np.float32),
                                    np.asarray(meta["u8_max"], np.float32),
                                    per_channel=True).decode()
            return cls(imgs, order, ut.field(meta, "width", path, float),
                       np.asarray(ut.field(meta, "centres", path, list), np.float64),
                       meta["frame"], meta["calibration"], meta.get("settings", {}))
        except (ValueError, TypeError, KeyError, IndexError) as exc:
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ut.UntrustedFileError(path, f"is not a usable steerable texture ({text})") \
                from None


def build_from_sampled_bakes(sampled_images: np.ndarray, order: int = 7, width: float = 0.01,
                             centres=None, **kwargs) -> SteerableTexture:
    """Turn bakes under the sampled lights into a :class:`SteerableTexture` (float64 solve).

    Parameters
    ----------
    sampled_images : ndarray, shape (K, R, R, 3)
        Bake of sampled light ``k`` (centre ``centres[k]``), row 0 at v = 0.
    centres : ndarray, shape (K, 2), optional
        Default: the sampled basis' default tensor grid.
    """
    sampled = build_sampled_basis(paper_basis(order, width), centres)
    basis_images = sampled.to_basis_images(sampled_images, dtype=np.float32)
    return SteerableTexture(basis_images, order, width, sampled.centres, **kwargs)
