"""Direction-sampled transport textures: relight a texture from S hard-sun bakes (bpy-free).

A transport texture is ``T[s, p]``: the value Cycles bakes at texel ``p`` (irradiance mode,
direct light only, i.e. ``E / pi`` of a white Lambertian surface) under a hard Sun lamp of
strength 1 (unit normal irradiance, angle 0) from direction ``w_s`` of a
:class:`~.directions.DirectionSet`. Because the bake is linear in the light, any distant
lighting is a weighted sum of these images:

* a sun of angular diameter ``a`` from ``w0``: ``E/pi = sum_s k_s(w0, a) T[s]`` with a
  normalised kernel ``k`` (:func:`sun_weights`);
* an environment ``L``: ``E/pi = sum_s L(w_s) dw_s T[s]`` (:func:`environment_weights`).

Outgoing radiance of the diffuse surface is ``albedo * E/pi``; indirect light is a separate
term (see ``operators/bakes/texture_transport.py``).

Storage is direction-major, ``(S, P)`` float16 on disk through a NumPy memmap
(:class:`TransportStore`), so a bake is streamed one direction at a time and a relight reads only
the few rows its kernel touches. Models fitted from the store stream over texel chunks too:

* :class:`TexturePCA` -- ``T ~ V U`` with ``V`` (S, K) direction loadings and ``U`` (K, P)
  eigen-textures, from the (S, S) Gram matrix accumulated chunk by chunk (uncentred: the
  best rank-K approximation in the Frobenius norm, no mean term to carry);
* :class:`BlockPCA` -- the same per square block of texels (clustered PCA over texel blocks,
  Mahajan et al. 2007's texture application), each block keeping the fewest components
  that meet the tolerance;
* the steerable basis of Ashikhmin & Shirley by quadrature (:func:`quadrature_sampled_lights`).

For the viewport a model's light dependence is tabulated: ``c_k(w0) = sum_s k_s(w0, a) V[s, k]``
on a D x D grid over the hemisphere disk (:func:`coefficient_tables`), sampled in the node tree
at the light's disk point (:func:`table_lookup` is the same bilinear lookup in NumPy).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np
import scipy.spatial

from ..io import atomic, untrusted, versions
from ..sphere.directions import DirectionSet, hull_barycentric, parse_direction_spec
from ..sphere.hemisphere import disk_to_hemisphere, hemisphere_to_disk, normalize_directions
from ..io.npz import save_npz

KERNELS = ("gauss", "linear")
#: Bytes of float64 working array per chunk when streaming over the store's texels.
CHUNK_BYTES = 32 << 20


def chunk_texels(n_directions: int) -> int:
    """Texels per streamed chunk so one (S, chunk) float64 block is about CHUNK_BYTES."""
    return max(256, CHUNK_BYTES // (8 * max(int(n_directions), 1)))
STORE_FORMAT = "relightable_textures.transport_texture"
MODEL_FORMAT = "relightable_textures.transport_model"


# ----------------------------------------------------------------------------------------------
# light kernels


def _spacing(dset: DirectionSet, idx: np.ndarray) -> np.ndarray:
    """Local sample spacing (rad) at sample(s) ``idx``: sqrt of the sample's solid angle."""
    return np.sqrt(dset.solid_angles[idx])


def _disc_points(direction: np.ndarray, radius: float, count: int) -> np.ndarray:
    """``count`` directions spread evenly (sunflower) over a cone of half-angle ``radius``."""
    if count <= 1 or radius <= 0:
        return direction[None, :]
    helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = np.cross(direction, helper)
    t /= np.linalg.norm(t)
    b = np.cross(direction, t)
    i = np.arange(count) + 0.5
    # uniform in solid angle over the cap: cos(theta) uniform in [cos r, 1]
    cos_t = 1.0 - (i / count) * (1.0 - np.cos(radius))
    sin_t = np.sqrt(np.clip(1.0 - cos_t ** 2, 0.0, None))
    phi = i * (np.pi * (3.0 - np.sqrt(5.0)))
    return (cos_t[:, None] * direction + sin_t[:, None] * (np.cos(phi)[:, None] * t
                                                           + np.sin(phi)[:, None] * b))


class _Hull:
    """Barycentric interpolation on the triangulated hull of the set's rows ``rows`` (all by
    default) plus a zero-valued nadir (so every upper-hemisphere query lies in a triangle; weight
    on the nadir is dropped). Indices are the set's own."""

    def __init__(self, dset: DirectionSet, rows=None):
        self.rows = np.arange(dset.size) if rows is None else np.asarray(rows, np.int64)
        self.size = dset.size
        pts = np.vstack([dset.directions[self.rows], [[0.0, 0.0, -1.0]]])
        self.points = pts
        self.n = len(self.rows)
        hull = scipy.spatial.ConvexHull(pts)
        self.eq = hull.equations
        if np.any(self.eq[:, 3] >= 0):
            raise ValueError("the sample directions do not surround the zenith; cannot interpolate")
        self.simplices = hull.simplices

    def weights(self, q: np.ndarray):
        """(Q, 3) indices into the set and (Q, 3) weights; the nadir's index is the set's size
        and carries weight 0."""
        tri, w = hull_barycentric(self.points, self.simplices, self.eq, q)
        w = w.copy()
        nadir = tri == self.n
        w[nadir] = 0.0
        return np.where(nadir, self.size, self.rows[np.minimum(tri, self.n - 1)]), w


_HULLS: dict = {}


def set_digest(dset: DirectionSet) -> str:
    """A key for caches of what a direction set alone decides (its hulls, its viewport tables):
    the sha1 of its directions' and solid angles' bytes (the kernel's disc sampling reads the
    solid angles; ``id()`` is reused once a set is collected)."""
    import hashlib

    h = hashlib.sha1(np.ascontiguousarray(dset.directions).tobytes())
    h.update(np.ascontiguousarray(dset.solid_angles).tobytes())
    return h.hexdigest()


def _hull(dset: DirectionSet, upper: bool = False) -> _Hull:
    """The set's hull (cached by :func:`set_digest`); ``upper``: of its rows above the
    horizon only, where the set reaches under it (:mod:`..sphere.under_horizon`), with
    ``mirror`` (S + 1,): each row's mirror under the horizon (-1: none; the nadir's own)."""
    key = (set_digest(dset), upper)
    if key not in _HULLS:
        if len(_HULLS) > 8:
            _HULLS.clear()
        d = dset.directions
        h = _Hull(dset, np.flatnonzero(d[:, 2] > 0.0) if upper else None)
        if upper:
            h.mirror = np.full(dset.size + 1, -1, np.int64)
            h.mirror[-1] = dset.size
            under = np.flatnonzero(d[:, 2] < 0.0)
            if len(under):
                tree = scipy.spatial.cKDTree(d[under] * np.array([1.0, 1.0, -1.0]))
                dist, j = tree.query(d)
                hit = (dist < 1e-9) & (d[:, 2] > 0.0)
                h.mirror[:-1][hit] = under[j[hit]]
        _HULLS[key] = h
    return _HULLS[key]


def check_interpolable(dset: DirectionSet, path: str) -> None:
    """The hull a sun is interpolated on (:func:`sun_weights`: the rows above the horizon where
    the set reaches under it, else all), built when a store's header is read: a set from
    elsewhere whose directions do not surround the zenith (all on one great circle, or none
    above the horizon) is refused there in one line naming the file, not by Qhull at the
    first relight. The hull is cached, so the relight does not build it again."""
    try:
        _hull(dset, upper=bool(np.any(dset.directions[:, 2] < 0.0)))
    except (ValueError, scipy.spatial.QhullError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise untrusted.UntrustedFileError(
            path, f"has directions a sun cannot be interpolated between ({first[:120]})") \
            from None


def sun_weights(dset: DirectionSet, direction, sun_angle_deg: float = 0.0,
                kernel: str = "linear") -> tuple[np.ndarray, np.ndarray]:
    """Sparse weights that relight a sun from the sampled hard suns: ``sum_s w_s T[s]``.

    Parameters
    ----------
    dset : DirectionSet
        The baked directions (upper hemisphere, and a band under it where the bake added one).
    direction : array_like, shape (3,)
        Towards the sun, world frame (z up); below the horizon gives no weights (the light is
        off, as for a distant light under the ground).
    sun_angle_deg : float
        Angular diameter of the sun disc (degrees, 0..90).
    kernel : {"linear", "gauss"}
        ``"linear"``: barycentric interpolation over the triangulated direction set, averaged
        over points spread on the sun disc -- exact at a sample direction for a 0-degree sun.
        ``"gauss"``: a Gaussian in the angle to the sun with ``sigma^2 = (a/4)^2 + (h/2)^2``
        (``h`` the local sample spacing), cut at 4 sigma and normalised (DESIGN.md sec. 3),
        over the directions above the horizon.

    Returns
    -------
    indices : ndarray of int, shape (K,)
    weights : ndarray, shape (K,), float64, summing to 1 (or empty below the horizon)
        Dimensionless: the sun's normal irradiance multiplies them.
    """
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
    a = float(sun_angle_deg)
    if not np.isfinite(a) or not 0.0 <= a <= 90.0:
        raise ValueError(f"sun angle must be in 0..90 degrees, got {sun_angle_deg!r}")
    d = normalize_directions(np.asarray(direction, dtype=np.float64).reshape(1, 3))[0]
    if d[2] <= 0.0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    alpha = np.radians(a)
    if kernel == "gauss":
        # (over the directions above the horizon: this kernel does not reach under it)
        cosang = np.where(dset.directions[:, 2] > 0.0,
                          np.clip(dset.directions @ d, -1.0, 1.0), -1.0)
        near = int(np.argmax(cosang))
        h = float(_spacing(dset, np.array([near]))[0])
        sigma = np.sqrt((alpha / 4.0) ** 2 + (0.5 * h) ** 2)
        ang = np.arccos(cosang)
        keep = np.nonzero(ang <= 4.0 * sigma)[0]
        w = np.exp(-0.5 * (ang[keep] / sigma) ** 2)
        return keep.astype(np.int64), w / w.sum()
    cosang = dset.directions @ d
    h = float(_spacing(dset, np.array([int(np.argmax(cosang))]))[0])
    # enough disc points that neighbouring ones are closer than the sample spacing
    count = 1 if alpha <= 0 else int(min(256, max(1, np.ceil(4.0 * (alpha / 2.0 / h) ** 2 * 3))))
    pts = _disc_points(d, alpha / 2.0, count)
    # the disc's part under the horizon is dark, but where the set reaches under it
    # (:mod:`..sphere.under_horizon`): there it is interpolated down to the set's lowest
    # direction. Points above the horizon interpolate between the directions above it, as in a
    # set without that band: near the horizon a hemi set's directions are dense in elevation
    # but tens of degrees apart in azimuth, and the hull of both bands would blend a sun 1
    # degree high with directions 3 under it (the gallery's fence at 1 degree under a
    # 0.526-degree Sun: 0.025 -> 0.063 from Cycles). A point under the horizon takes the
    # weights of its mirror above it, moved onto the mirrored rows: the same triangle upside
    # down, so the weights are continuous across the horizon and a floor stays dark under it
    # (the hull of both bands where a row of that triangle has no mirror).
    lowest = float(dset.directions[:, 2].min())
    pts = pts[pts[:, 2] > min(0.0, lowest)]
    if len(pts) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    acc = np.zeros(dset.size + 1)
    below = pts[:, 2] <= 0.0
    if (~below).any():
        tri, w = _hull(dset, upper=lowest < 0.0).weights(pts[~below])
        np.add.at(acc, tri.ravel(), w.ravel() / count)
    if below.any():
        upper = _hull(dset, upper=True)
        tri, w = upper.weights(pts[below] * np.array([1.0, 1.0, -1.0]))
        moved = upper.mirror[tri]
        ok = (moved >= 0).all(axis=1)
        np.add.at(acc, moved[ok].ravel(), w[ok].ravel() / count)
        if (~ok).any():
            tri, w = _hull(dset).weights(pts[below][~ok])
            np.add.at(acc, tri.ravel(), w.ravel() / count)
    acc = acc[:-1]
    keep = np.nonzero(acc > 0)[0]
    return keep.astype(np.int64), acc[keep]


def environment_weights(dset: DirectionSet, env_image, *, row_order: str,
                        rotation_deg: float = 0.0, validate: bool = True) -> np.ndarray:
    """Dense weights ``L(w_s) dw_s`` of an equirectangular environment (upper hemisphere).

    Parameters
    ----------
    env_image : array_like, shape (H, W) or (H, W, C)
        Radiance (W m^-2 sr^-1).
    row_order : {"top_first", "bottom_first"}
    rotation_deg : float
        Rotation of the environment's picture about +z (degrees, counter-clockwise seen from
        above): the relit light from direction ``w`` is ``L(R^T w)``. A world Mapping node
        (Point type) with Z rotation ``phi`` turns the picture the other way, so it equals
        ``rotation_deg = -phi`` (measured in a Cycles bake, see
        ``operators/preview/vertex_relight.shade_rotation``).
    validate : bool
        Check the image (finite values) -- see :func:`.eigentransport.sample_equirect`.

    Returns
    -------
    weights : ndarray, shape (S,) or (S, C), float64 (W m^-2 per sample)
    """
    from .eigentransport import sample_equirect

    t = np.radians(float(rotation_deg))
    c, s = np.cos(t), np.sin(t)
    Rt = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    L = sample_equirect(env_image, dset.directions @ Rt.T, row_order=row_order,
                        validate=validate)
    # the upper hemisphere only: directions under the horizon serve a sun's disc
    # (:mod:`..sphere.under_horizon`); their solid angles are their mirrors'
    w = dset.solid_angles * (dset.directions[:, 2] > 0.0)
    return L * (w if L.ndim == 1 else w[:, None])


def steering_matrix(steerable, dset: DirectionSet) -> np.ndarray:
    """(S, J) float64: a steerable texture (the indirect term) under a unit sun from ``w_s`` is
    ``clamp(sum_j B[s, j] I_j)`` -- its steering coefficients times its calibration gain
    (:meth:`..steerable.texture.SteerableTexture.steering_weights`); J = order^2 basis images.
    An environment then steers with ``sum_s L(w_s) dw_s B[s]`` (:func:`environment_weights`),
    the clamp applied to the sum."""
    rows = []
    for w in dset.directions:
        c, gain = steerable.steering_weights(w)
        rows.append(gain * c)
    return np.asarray(rows, np.float64)


def steer_environment(steerable, B: np.ndarray, weights) -> np.ndarray:
    """The steerable texture under an environment: ``max(0, sum_j G_j * I_j)`` with
    ``G = weights^T B``; ``weights`` (S,) or (S, 3) from :func:`environment_weights`.
    Returns (R, R, 3) float32 at the steerable texture's resolution."""
    W = np.asarray(weights, np.float64)
    if W.ndim == 1:
        W = np.repeat(W[:, None], 3, axis=1)
    G = W[:, :3].T @ B                                              # (3, J)
    images = np.asarray(steerable.basis_images, np.float64)        # (J, R, R, 3)
    return np.maximum(np.einsum("cj,jyxc->yxc", G, images), 0.0).astype(np.float32)


# ----------------------------------------------------------------------------------------------
# the on-disk store


#: The range T's values lie in: direct transport ``cos * V / pi`` of a white Lambertian
#: surface under a sun of unit normal irradiance is in [0, 1/pi] (cosine <= 1, visibility 0 or
#: 1, a Cycles bake's antialiasing averages such values). The tolerance covers float16 rounding
#: (half an ulp is 2^-11 relative; 1/pi is stored as 0.318359375, 1.00016/pi: the maximum of
#: real bakes, both by rays and by Cycles, at 16^2 and 32^2 on the bumps). Indirect light and
#: albedo are not in T (they are separate files).
T_LO, T_HI = -1e-4, (1.0 + 1e-3) / np.pi
#: dtypes T may be stored as: float16 (written by :meth:`TransportStore.create`) or float32,
#: little-endian as NumPy writes it on every platform this runs on.
T_DTYPES = (np.dtype("<f2"), np.dtype("<f4"))


def transport_bytes(n_directions: int, n_texels: int, channels: int = 1) -> int:
    """Bytes of a float16 transport store (S x P x C)."""
    return int(n_directions) * int(n_texels) * int(channels) * 2


@dataclass
class TransportStore:
    """``T[s, p]`` as a float16 ``.npy`` memmap plus a JSON header beside it.

    Attributes
    ----------
    path : str
        The ``.npy`` file (shape (S, P), float16, P = resolution^2, row 0 of the texture at
        v = 0 as Blender's images).
    directions : DirectionSet
    resolution : int
    meta : dict
    """

    path: str
    directions: DirectionSet
    resolution: int
    meta: dict = field(default_factory=dict)
    _array: np.ndarray | None = None
    #: written by this process (:meth:`finish`'s reader): its values are not checked again
    _trusted: bool = False

    @property
    def n_texels(self) -> int:
        return self.resolution * self.resolution

    @property
    def array(self) -> np.ndarray:
        """The (S, P) float16 memmap (read-only once finished), its values checked on first
        use (finite, in ``[T_LO, T_HI]``: :meth:`check_values`)."""
        if self._array is None:
            arr = self._raw()
            if not self._trusted:
                self.check_values(arr)
            self._array = arr
        return self._array

    def _raw(self) -> np.ndarray:
        """T's memory map after checking its NPY header against this store's header: a
        regular file of dtype :data:`T_DTYPES`, shape (S, R^2), as long as its header says --
        nothing of its data is read here."""
        if self._array is not None:
            return self._array
        shape, fortran, dtype, _ = untrusted.npy_header(self.path)
        if dtype not in T_DTYPES:
            raise untrusted.UntrustedFileError(
                self.path, f"holds {dtype.str}, not float16 or float32 (little-endian)")
        untrusted.check_shape(self.path, shape, (self.directions.size, self.n_texels))
        if fortran:
            raise untrusted.UntrustedFileError(self.path, "is stored column-major; T is "
                                                          "written row-major")
        try:
            return np.load(self.path, mmap_mode="r", allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise untrusted.UntrustedFileError(self.path, f"cannot be read ({exc})") from None

    def check_values(self, arr=None) -> None:
        """UntrustedFileError ``<T>: holds NaN or infinite transport values`` or values out of
        ``[T_LO, T_HI]`` (direct transport is in [0, 1/pi]). Read in blocks of 16 M values
        with two integer reductions each: T of 400 directions at 256^2 (50 MiB of float16)
        took 13-16 ms through its memory map from the page cache (4 ms in memory), ~0.3 s a
        GiB, on a busy 2-core machine (2026-12-06)."""
        arr = self._raw() if arr is None else arr
        untrusted.check_values(self.path, arr, lo=T_LO, hi=T_HI, what="transport values")

    def rows(self, indices) -> np.ndarray:
        """Rows ``indices`` of T (k, P) float32, each checked as it is read: a relight that
        reads a few directions of a large T does not read the rest of it."""
        if self._array is not None:
            arr, checked = self._array, True
        else:
            arr, checked = self._raw(), self._trusted
        out = np.empty((len(indices), self.n_texels), np.float32)
        for i, s in enumerate(indices):
            row = arr[int(s)]
            if not checked:
                untrusted.check_values(self.path, row, lo=T_LO, hi=T_HI,
                                       what="transport values")
            out[i] = row
        return out

    @staticmethod
    def header_path(path: str) -> str:
        return os.path.splitext(path)[0] + ".json"

    @classmethod
    def create(cls, path: str, directions: DirectionSet, resolution: int, meta: dict | None = None):
        """Open a new store for writing under a temporary name (:meth:`finish` renames it)."""
        folder = os.path.dirname(os.path.abspath(path))
        os.makedirs(folder, exist_ok=True)
        tmp = os.path.join(folder, f".{os.path.basename(path)}.{atomic.token()}.tmp.npy")
        try:
            arr = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float16,
                                            shape=(directions.size, resolution * resolution))
        except OSError as exc:   # a full disk: name the store, not its temporary name
            if os.path.exists(tmp):
                os.remove(tmp)
            raise OSError(exc.errno, exc.strerror, path) from exc
        store = cls(path, directions, int(resolution), dict(meta or {}), arr)
        store._tmp = tmp
        return store

    def write(self, s: int, image) -> None:
        """Store direction ``s``'s bake, shape (R, R) or (R*R,), and flush it to disk."""
        img = np.asarray(image, dtype=np.float32).reshape(-1)
        if img.shape[0] != self.n_texels:
            raise ValueError(f"image must have {self.n_texels} texels, got {img.shape[0]}")
        if np.any(np.abs(img) > 65504.0):
            raise OverflowError("a transport value exceeds the float16 range")
        self._array[s] = img.astype(np.float16)
        self._array.flush()

    def write_rows(self, start: int, rows) -> None:
        """Store directions ``start:start + n`` at once, rows (n, R*R). Not flushed here (the
        page cache writes it; :meth:`finish` flushes): a flush per chunk of one direction at
        4096^2 made the bake wait for 33 MB of writing 400 times. No full-size temporaries."""
        rows = np.asarray(rows, dtype=np.float32)
        if rows.ndim != 2 or rows.shape[1] != self.n_texels:
            raise ValueError(f"rows must have shape (n, {self.n_texels}), got {rows.shape}")
        if rows.size and max(float(rows.max()), -float(rows.min())) > 65504.0:
            raise OverflowError("a transport value exceeds the float16 range")
        self._array[start:start + len(rows)] = rows

    def finish(self) -> "TransportStore":
        """Flush and close for writing; returns a reader of the still-temporary store (its
        header beside it). :meth:`commit` renames both into place, :meth:`abort` drops them."""
        self._array.flush()
        del self._array
        self._array = None
        header = {**versions.stamp(STORE_FORMAT), "resolution": self.resolution,
                  "directions": self.directions.to_dict(include_arrays=True), **self.meta}
        with open(self.header_path(self._tmp), "w") as fh:
            json.dump(header, fh, indent=1)
        reader = TransportStore(self._tmp, self.directions, self.resolution, dict(self.meta),
                                _trusted=True)
        reader._tmp, reader.final_path = self._tmp, self.path
        return reader

    def commit(self) -> str:
        """Rename a finished store (data, then header) into its final place; returns the path.
        An earlier store of the same name is replaced only now."""
        final = getattr(self, "final_path", self.path)
        self._array = None
        os.replace(self._tmp, final)
        os.replace(self.header_path(self._tmp), self.header_path(final))
        self.path = final
        self._tmp = None
        return final

    def close(self) -> None:
        """Drop this object's memory map of T (it reopens on the next read). On Windows a file
        that is mapped cannot be renamed: a bake closes its stores before they are swapped in."""
        self._array = None

    def abort(self) -> None:
        """Drop a store that is being written or not yet committed: nothing is left behind."""
        self._array = None
        tmp = getattr(self, "_tmp", None)
        for p in ((tmp, self.header_path(tmp)) if tmp else ()):
            if os.path.exists(p):
                os.remove(p)

    @classmethod
    def open(cls, path: str) -> "TransportStore":
        """The store at ``path`` (T's ``.npy``; its header ``.json`` beside it), read as a file
        from elsewhere (:mod:`..io.untrusted`): the header is a capped regular JSON file whose
        resolution (<= MAX_RESOLUTION) and direction count (<= MAX_DIRECTIONS) are checked
        before anything is sized by them; T's NPY header must say its dtype (float16/32),
        shape (S, R^2) and a length the file has. T's values are checked when first read
        (:attr:`array`, :meth:`rows`). Every refusal is one UntrustedFileError naming the
        file."""
        hpath = cls.header_path(path)
        header = untrusted.read_json(hpath)
        versions.check(header, STORE_FORMAT, path, "a transport texture store")
        res = untrusted.check_count(hpath, untrusted.field(header, "resolution", hpath, int),
                                    untrusted.MAX_RESOLUTION, "resolution", lo=1)
        d = untrusted.field(header, "directions", hpath, dict)
        try:
            dset = DirectionSet.from_dict(d)
        except (ValueError, TypeError, KeyError) as exc:
            raise untrusted.UntrustedFileError(hpath, f"has a bad direction set ({exc})") \
                from None
        untrusted.check_count(hpath, dset.size, untrusted.MAX_DIRECTIONS, "directions", lo=1)
        check_interpolable(dset, hpath)
        for key in ("directions", "resolution", "format", "format_version"):
            header.pop(key, None)
        store = cls(path, dset, res, header)
        store._raw()            # T's own header against this one, before anyone maps it
        return store

    # -- relighting --------------------------------------------------------------------------
    def relight(self, indices, weights, texels=None) -> np.ndarray:
        """``sum_k weights[k] T[indices[k]]``; shape (R, R), float32 (row 0 at v = 0), or (m,)
        at flat ``texels`` (m,) only (the same values)."""
        if texels is not None:
            texels = np.asarray(texels, np.int64)
        out = np.zeros(self.n_texels if texels is None else len(texels), dtype=np.float64)
        for s, w in zip(np.asarray(indices), np.asarray(weights)):
            row = self.rows([int(s)])[0]
            out += float(w) * (row if texels is None else row[texels]).astype(np.float64)
        if texels is not None:
            return out.astype(np.float32)
        return out.reshape(self.resolution, self.resolution).astype(np.float32)

    def relight_dense(self, weights) -> np.ndarray:
        """``weights @ T`` for dense (S,) or (S, C) weights; shape (R, R) or (R, R, C)."""
        w = np.asarray(weights, dtype=np.float64)
        arr = self.array
        out = np.zeros((self.n_texels,) + w.shape[1:], dtype=np.float64)
        c = chunk_texels(arr.shape[0])
        for a in range(0, self.n_texels, c):
            block = arr[:, a:a + c].astype(np.float64)   # (S, c)
            out[a:a + c] = (block.T @ w)
        return out.reshape((self.resolution, self.resolution) + w.shape[1:]).astype(np.float32)

    def sun(self, direction, sun_angle_deg: float = 0.0, kernel: str = "linear") -> np.ndarray:
        """White-albedo direct radiance ``E/pi`` under a unit sun; shape (R, R)."""
        idx, w = sun_weights(self.directions, direction, sun_angle_deg, kernel)
        return self.relight(idx, w)


# ----------------------------------------------------------------------------------------------
# models


def gram_matrix(store: TransportStore, texels=None) -> np.ndarray:
    """``T T^T`` (S, S) in float64, streamed over texel chunks (optionally a texel subset)."""
    arr = store.array
    S = arr.shape[0]
    G = np.zeros((S, S))
    cols = np.arange(store.n_texels) if texels is None else np.asarray(texels)
    c = chunk_texels(S)
    for a in range(0, len(cols), c):
        sel = cols[a:a + c]
        X = (arr[:, sel[0]:sel[-1] + 1] if texels is None else arr[:, sel]).astype(np.float64)
        G += X @ X.T
    return G


def components_for_tolerance(eigenvalues, tol: float) -> int:
    """Fewest leading components whose residual ``sqrt(sum rest / sum all)`` is <= ``tol``."""
    lam = np.clip(np.sort(np.asarray(eigenvalues, dtype=np.float64))[::-1], 0.0, None)
    total = lam.sum()
    if total <= 0:
        return 1
    rest = np.sqrt(np.clip(total - np.cumsum(lam), 0.0, None) / total)
    return int(np.argmax(rest <= tol) + 1) if np.any(rest <= tol) else len(lam)


@dataclass
class TexturePCA:
    """``T ~ V U``: eigen-textures ``U`` (K, P) and direction loadings ``V`` (S, K).

    ``V`` has orthonormal columns (eigenvectors of ``T T^T``), so ``U = V^T T`` and the
    relative Frobenius residual is ``sqrt(sum of dropped eigenvalues / sum of all)``
    (:attr:`residual`).
    """

    V: np.ndarray
    U: np.ndarray
    resolution: int
    residual: float
    eigenvalues: np.ndarray

    @property
    def k(self) -> int:
        return int(self.V.shape[1])

    def coefficients(self, indices, weights) -> np.ndarray:
        """(K,) coefficients for sparse light weights."""
        return np.asarray(weights, np.float64) @ self.V[np.asarray(indices)].astype(np.float64)

    def relight(self, indices, weights) -> np.ndarray:
        c = self.coefficients(indices, weights)
        return self._combine(c).reshape(self.resolution, self.resolution)

    def relight_dense(self, weights) -> np.ndarray:
        w = np.asarray(weights, np.float64)                  # (S,) or (S, C)
        c = w.T @ self.V.astype(np.float64)                   # (K,) or (C, K)
        out = self._combine(c)                                # (P,) or (C, P)
        out = out if c.ndim == 1 else out.T
        return out.reshape((self.resolution, self.resolution) + np.shape(weights)[1:])

    def _combine(self, c) -> np.ndarray:
        """``c @ U`` (float32 out, float64 sums) by chunks of texels: U (K, P) is never
        converted whole (at 4096^2 and 96 components that would be 12.9 GB of float64)."""
        n = self.U.shape[1]
        out = np.empty(np.shape(c)[:-1] + (n,), np.float32)
        step = chunk_texels(self.U.shape[0])
        for a in range(0, n, step):
            out[..., a:a + step] = c @ self.U[:, a:a + step].astype(np.float64)
        return out

    def storage_bytes(self) -> dict:
        return {"eigen_textures_half": int(self.U.size * 2), "loadings_float32": int(self.V.size * 4)}

    # -- the model protocol shared with BlockPCA (summary, preview cost, file arrays) --
    kind = "pca"
    live_preview = True   # the node preview reads the eigen-textures through lookup tables

    def summary(self, S: int) -> dict:
        """JSON-safe description for the bake report (``S`` directions)."""
        return {"kind": self.kind, "components": self.k, "residual": self.residual}

    def preview_cost(self, extra_lookups: int = 0) -> dict:
        """Per-pixel cost of the live preview: two table lookups and one eigen-texture fetch
        per three components, plus ``extra_lookups`` (the indirect term's)."""
        tiles = -(-self.k // 3)
        return {"texture_lookups_per_pixel": 2 * tiles + 1 + int(extra_lookups),
                "multiply_adds_per_texel": 3 * self.k, "python_per_light_change": False}

    def to_arrays(self) -> dict:
        """The arrays of the model file (eigen-textures stored as half floats)."""
        return {"kind": np.array(self.kind), "V": self.V, "U": self.U.astype(np.float16),
                "resolution": np.array(self.resolution), "residual": np.array(self.residual)}

    @classmethod
    def from_arrays(cls, z, S: int | None = None) -> "TexturePCA":
        """From a model file's arrays (``z``: a checked NPZ, :func:`..io.untrusted.open_npz`,
        or a dict); ``S``: T's direction count, when known, that V's rows must match."""
        if hasattr(z, "get") and hasattr(z, "path"):
            path = z.path
            R = untrusted.check_count(path, untrusted.npz_scalar(z, "resolution", int),
                                      untrusted.MAX_RESOLUTION, "resolution", lo=1)
            V = z.get("V", shape=(S, None), dtype="f")
            U = z.get("U", shape=(V.shape[1], R * R), dtype="f")
            untrusted.check_values(path, V, what="loadings")
            untrusted.check_values(path, U, what="eigen-texture values")
            residual = untrusted.npz_scalar(z, "residual", float)
        else:
            V, U = np.asarray(z["V"]), z["U"]
            R, residual = int(z["resolution"]), float(z["residual"])
        return cls(V, np.asarray(U, np.float32), R, residual, np.zeros(V.shape[1]))


def fit_texture_pca(store: TransportStore, *, k: int | None = None, tol: float | None = None,
                    max_k: int = 96) -> TexturePCA:
    """Global uncentred PCA of the store (streamed). Exactly one of ``k`` / ``tol``.

    ``tol`` is the relative Frobenius residual of ``T`` to reach, with at most ``max_k``
    components (96: on the bumps demo at 400 directions the relight error against a 10-degree
    Cycles Sun was 0.077 with 48 components and 0.064 with 96, T itself 0.061; the preview
    reads two textures per three components); ``k`` is capped at ``S``.
    Conditioning: no inverse is formed (eigenvectors of the Gram matrix); eigenvalues below
    1e-12 of the largest are treated as zero.
    """
    if (k is None) == (tol is None):
        raise ValueError("give exactly one of k and tol")
    G = gram_matrix(store)
    lam, vec = np.linalg.eigh(G)
    order = np.argsort(lam)[::-1]
    lam, vec = np.clip(lam[order], 0.0, None), vec[:, order]
    lam[lam < 1e-12 * max(lam[0], 1e-300)] = 0.0
    kk = min(int(k), len(lam)) if k is not None else min(components_for_tolerance(lam, tol), max_k)
    kk = max(kk, 1)
    V = vec[:, :kk]
    arr = store.array
    U = np.empty((kk, store.n_texels), dtype=np.float32)
    c = chunk_texels(arr.shape[0])
    for a in range(0, store.n_texels, c):
        U[:, a:a + c] = V.T @ arr[:, a:a + c].astype(np.float64)
    total = lam.sum()
    residual = float(np.sqrt(max(total - lam[:kk].sum(), 0.0) / total)) if total > 0 else 0.0
    return TexturePCA(V.astype(np.float32), U, store.resolution, residual, lam)


@dataclass
class BlockPCA:
    """Clustered PCA over square texel blocks: block ``b`` has loadings ``V[b]`` (S, n_b) and
    eigen-textures ``U[b]`` (n_b, block*block); ``K = max n_b``."""

    V: list
    U: list
    resolution: int
    block: int
    residual: float

    @property
    def n_blocks(self) -> int:
        return len(self.V)

    @property
    def dims(self) -> np.ndarray:
        return np.array([v.shape[1] for v in self.V])

    def relight(self, indices, weights) -> np.ndarray:
        R, B = self.resolution, self.block
        nb = R // B
        out = np.zeros((R, R))
        idx = np.asarray(indices)
        w = np.asarray(weights, np.float64)
        for b in range(self.n_blocks):
            by, bx = divmod(b, nb)
            c = w @ self.V[b][idx].astype(np.float64)
            out[by * B:(by + 1) * B, bx * B:(bx + 1) * B] = (c @ self.U[b]).reshape(B, B)
        return out.astype(np.float32)

    def storage_bytes(self) -> dict:
        return {"eigen_textures_half": int(sum(u.size for u in self.U) * 2),
                "loadings_float32": int(sum(v.size for v in self.V) * 4)}

    def cost_per_texel(self, S: int) -> float:
        """Mahajan's cost ``sum n_b (p + S) / P`` with p = block^2 texels."""
        p = self.block ** 2
        return float(sum(n * (p + S) for n in self.dims) / (self.n_blocks * p))

    kind = "blocks"
    live_preview = False   # relit in NumPy only (one set of loadings per block)

    def summary(self, S: int) -> dict:
        """JSON-safe description for the bake report (``S`` directions)."""
        d = self.dims
        return {"kind": self.kind, "block": self.block, "blocks": self.n_blocks,
                "dims_min": int(d.min()), "dims_mean": float(d.mean()), "dims_max": int(d.max()),
                "residual": self.residual, "cost_per_texel": self.cost_per_texel(S)}

    def preview_cost(self, extra_lookups: int = 0) -> dict:
        return {"multiply_adds_per_texel": int(self.dims.max()), "viewport": "NumPy only"}

    def to_arrays(self) -> dict:
        """The arrays of the model file: loadings side by side, eigen-textures flattened
        (half floats), ``dims`` to split them again."""
        return {"kind": np.array(self.kind), "block": np.array(self.block),
                "resolution": np.array(self.resolution), "residual": np.array(self.residual),
                "dims": self.dims, "V": np.concatenate(self.V, axis=1),
                "U": np.concatenate([u.ravel() for u in self.U]).astype(np.float16)}

    @classmethod
    def from_arrays(cls, z, S: int | None = None) -> "BlockPCA":
        """From a model file's arrays (a checked NPZ, see :meth:`TexturePCA.from_arrays`, or
        a dict): the block divides the resolution, ``dims`` has one count per block, each at
        most S and block^2, and V's columns and U's length are what ``dims`` say."""
        if hasattr(z, "get") and hasattr(z, "path"):
            path = z.path
            R = untrusted.check_count(path, untrusted.npz_scalar(z, "resolution", int),
                                      untrusted.MAX_RESOLUTION, "resolution", lo=1)
            B = untrusted.check_count(path, untrusted.npz_scalar(z, "block", int), R,
                                      "block", lo=1)
            if R % B:
                raise untrusted.UntrustedFileError(path, f"block {B} does not divide the "
                                                         f"resolution {R}")
            dims = z.get("dims", shape=((R // B) ** 2,), dtype="iu")
            V = z.get("V", shape=(S, None), dtype="f")
            if len(dims) and (dims.min() < 1 or dims.max() > min(V.shape[0], B * B)
                              or int(dims.sum()) != V.shape[1]):
                raise untrusted.UntrustedFileError(path, "its block dims do not match its "
                                                         "loadings")
            U = z.get("U", shape=(int(dims.sum()) * B * B,), dtype="f")
            untrusted.check_values(path, V, what="loadings")
            untrusted.check_values(path, U, what="eigen-texture values")
            residual = untrusted.npz_scalar(z, "residual", float)
            z = {"dims": dims, "resolution": R, "residual": residual}
        else:
            B, V, U = int(z["block"]), np.asarray(z["V"]), np.asarray(z["U"])
        Vs, Us, a, u0 = [], [], 0, 0
        for n in np.asarray(z["dims"]):
            Vs.append(V[:, a:a + n])
            Us.append(U[u0:u0 + n * B * B].astype(np.float32).reshape(n, B * B))
            a += n
            u0 += n * B * B
        return cls(Vs, Us, int(z["resolution"]), B, float(z["residual"]))


def fit_block_pca(store: TransportStore, *, block: int = 16, tol: float = 0.02) -> BlockPCA:
    """Per-block uncentred PCA; each block keeps the fewest components with relative residual
    <= ``tol`` (so the whole fit is within ``tol`` too). Streams one strip of blocks at a time."""
    R = store.resolution
    if block < 1 or R % block:
        raise ValueError(f"block must divide the resolution {R}, got {block}")
    arr = store.array
    Vs, Us = [], []
    err2 = tot2 = 0.0
    for by in range(R // block):
        strip = arr[:, by * block * R:(by + 1) * block * R].astype(np.float64)   # (S, B*R)
        strip = strip.reshape(arr.shape[0], block, R)
        for bx in range(R // block):
            X = strip[:, :, bx * block:(bx + 1) * block].reshape(arr.shape[0], -1)  # (S, p)
            u, sv, vt = np.linalg.svd(X, full_matrices=False)
            lam = sv ** 2
            n = components_for_tolerance(lam, tol) if lam.sum() > 0 else 1
            Vs.append(u[:, :n].astype(np.float32))
            Us.append((sv[:n, None] * vt[:n]).astype(np.float32))
            tot2 += lam.sum()
            err2 += lam[n:].sum()
    return BlockPCA(Vs, Us, R, block, float(np.sqrt(err2 / tot2)) if tot2 > 0 else 0.0)


#: Model classes of the NPZ model file, by their ``kind``.
MODEL_KINDS = {cls.kind: cls for cls in (TexturePCA, BlockPCA)}


def save_model(path: str, model, directions_spec: str) -> None:
    """Write a :data:`MODEL_KINDS` model and the spec of the directions it was fitted on to
    ``path`` (NPZ; written under a temporary name and renamed)."""
    from ..io import atomic

    with atomic.atomic_path(path) as tmp:
        save_npz(tmp, directions_spec=np.array(directions_spec), **model.to_arrays(),
                 **{k: np.array(v) for k, v in versions.stamp(MODEL_FORMAT).items()})


def load_model(path: str, store: "TransportStore | None" = None):
    """The model written by :func:`save_model`, read as a file from elsewhere: a capped NPZ
    (:func:`..io.untrusted.open_npz`), every array's header checked before it is read; with
    ``store`` its directions and resolution must be T's. A clear UntrustedFileError (an
    InputError) for an unknown kind or anything else wrong, naming the file."""
    with untrusted.open_npz(path, stored=True) as z:
        if "format" in z:   # (files before versioning have none: version 1)
            versions.check({"format": untrusted.npz_scalar(z, "format", str),
                            "format_version": untrusted.npz_scalar(z, "format_version", int)},
                           MODEL_FORMAT, path, "a transport model")
        kind = untrusted.npz_scalar(z, "kind", str)
        if kind not in MODEL_KINDS:
            raise untrusted.UntrustedFileError(path, f"unknown model kind {kind!r:.40} "
                                                     f"(known: {', '.join(MODEL_KINDS)})")
        model = MODEL_KINDS[kind].from_arrays(z, None if store is None else store.directions.size)
    if store is not None and model.resolution != store.resolution:
        raise untrusted.UntrustedFileError(path, f"is fitted at {model.resolution}^2; its T is "
                                                 f"{store.resolution}^2")
    return model


def quadrature_sampled_lights(store: TransportStore, sampled_basis) -> np.ndarray:
    """Images of the K sampled steerable lights by quadrature over the baked directions:
    ``S_k = sum_s L_k(w_s) dw_s T[s]`` (noise-free; equals an environment bake of light k up to
    the quadrature error). Returns (K, R, R) float32 (white albedo, direct light)."""
    from ..steerable.basis import evaluate_light

    d = store.directions
    L = np.stack([evaluate_light(sampled_basis.basis, d.directions, c) for c in
                  sampled_basis.centres])                      # (K, S)
    L = L * d.solid_angles[None, :]
    L[:, d.directions[:, 2] <= 0] = 0.0
    return np.stack([store.relight_dense(L[k]) for k in range(len(L))])


# ----------------------------------------------------------------------------------------------
# tables over the hemisphere disk (viewport)


def disk_grid(size: int) -> np.ndarray:
    """(D, D, 2) disk coordinates of texel centres, row 0 at y = -1 (bottom, as Blender)."""
    c = -1.0 + (np.arange(size) + 0.5) * 2.0 / size
    x, y = np.meshgrid(c, c)
    return np.stack([x, y], axis=-1)


def disk_kernel_matrix(dset: DirectionSet, size: int = 32, sun_angle_deg: float = 0.0,
                       kernel: str = "linear"):
    """The sun kernel at each disk texel centre as a sparse (D*D, S) matrix (CSR, float64):
    row ``i`` holds :func:`sun_weights` of a sun at texel ``i``'s direction (row-major, row 0
    at y = -1). Texels whose centre lies outside the unit disk (below the horizon) take the
    nearest disk point on the rim, so bilinear lookups of tables made from it stay continuous.
    Kept for the last few (set, size, sun, kernel): the objects baked together share a set, and
    their T, indirect and block groups all tabulate it (read-only: callers must not change it)."""
    key = (set_digest(dset), int(size), float(sun_angle_deg), kernel)
    if key not in _DISK_KERNELS:
        if len(_DISK_KERNELS) >= 4:
            _DISK_KERNELS.clear()
        _DISK_KERNELS[key] = _disk_kernel_matrix(dset, size, sun_angle_deg, kernel)
    return _DISK_KERNELS[key]


_DISK_KERNELS: dict = {}


def _disk_kernel_matrix(dset: DirectionSet, size: int, sun_angle_deg: float, kernel: str):
    import scipy.sparse

    xy = disk_grid(size).reshape(-1, 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    inside = np.where(r > 0.999, 0.999 / np.maximum(r, 1e-12), 1.0)
    dirs = disk_to_hemisphere(xy * inside[:, None])
    rows, cols, vals = [], [], []
    for i, d in enumerate(dirs):
        idx, w = sun_weights(dset, d, sun_angle_deg, kernel)
        rows.append(np.full(len(idx), i))
        cols.append(np.asarray(idx, np.int64))
        vals.append(np.asarray(w, np.float64))
    return scipy.sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                          np.concatenate(cols))),
                                   shape=(size * size, dset.size))


def coefficient_tables(V, dset: DirectionSet, size: int = 32, sun_angle_deg: float = 0.0,
                       kernel: str = "linear") -> np.ndarray:
    """``c_k(w0) = sum_s k_s(w0, a) V[s, k]`` tabulated at the disk texel centres.

    Returns (K, D, D) float32; texels whose centre lies outside the unit disk (below the
    horizon) hold the value at the nearest disk point on the rim (:func:`disk_kernel_matrix`),
    so bilinear lookups stay continuous, and the lookup itself is gated by the light's
    elevation."""
    V = np.asarray(V, np.float64)
    out = disk_kernel_matrix(dset, size, sun_angle_deg, kernel) @ V
    return np.asarray(out).T.reshape(V.shape[1], size, size).astype(np.float32)


def table_lookup(tables, direction) -> np.ndarray:
    """Bilinear lookup of (K, D, D) tables at a light direction's disk point, as a GPU
    sampler with Linear interpolation and Extend does (texel centres at ``(i + 0.5) / D``).
    Returns (K,); zero below the horizon."""
    t = np.asarray(tables, np.float64)
    d = normalize_directions(np.asarray(direction, np.float64).reshape(1, 3))[0]
    if d[2] <= 0:
        return np.zeros(t.shape[0])
    D = t.shape[-1]
    xy = hemisphere_to_disk(d[None])[0]
    fx = np.clip((xy[0] + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0)
    fy = np.clip((xy[1] + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0)
    x0, y0 = min(int(np.floor(fx)), D - 2), min(int(np.floor(fy)), D - 2)
    ax, ay = fx - x0, fy - y0
    return ((1 - ax) * (1 - ay) * t[:, y0, x0] + ax * (1 - ay) * t[:, y0, x0 + 1]
            + (1 - ax) * ay * t[:, y0 + 1, x0] + ax * ay * t[:, y0 + 1, x0 + 1])


def table_weights(dset: DirectionSet, direction, size: int, sun_angle_deg: float = 0.0,
                  kernel: str = "linear") -> tuple[np.ndarray, np.ndarray]:
    """Sparse light weights equal to a bilinear lookup of tables made by
    :func:`coefficient_tables` (or :func:`disk_kernel_matrix`) at ``direction``: the kernels of
    the four surrounding disk texels, weighted bilinearly. ``w @ V[idx]`` is what a viewport
    reading such tables shows, without tabulating every texel. Empty below the horizon."""
    d = normalize_directions(np.asarray(direction, np.float64).reshape(1, 3))[0]
    if d[2] <= 0:
        return np.zeros(0, np.int64), np.zeros(0)
    D = int(size)
    xy = hemisphere_to_disk(d[None])[0]
    f = [float(np.clip((c + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0)) for c in xy]
    x0, y0 = (min(int(np.floor(v)), D - 2) for v in f)
    ax, ay = f[0] - x0, f[1] - y0
    grid = disk_grid(D)
    acc: dict = {}
    for (j, i, fac) in ((x0, y0, (1 - ax) * (1 - ay)), (x0 + 1, y0, ax * (1 - ay)),
                        (x0, y0 + 1, (1 - ax) * ay), (x0 + 1, y0 + 1, ax * ay)):
        if fac <= 0:
            continue
        p = grid[i, j]
        r = float(np.hypot(*p))
        p = p * (0.999 / r if r > 0.999 else 1.0)
        idx, w = sun_weights(dset, disk_to_hemisphere(p[None])[0], sun_angle_deg, kernel)
        for a, b in zip(np.asarray(idx).tolist(), np.asarray(w).tolist()):
            acc[a] = acc.get(a, 0.0) + fac * b
    keys = np.array(sorted(acc), np.int64)
    return keys, np.array([acc[k] for k in keys.tolist()])


def parse_directions(spec: str) -> DirectionSet:
    """A direction set for a texel transport bake: ``hemi:N[:P]`` (default), or any spec of
    :func:`.directions.parse_direction_spec` restricted to its upper hemisphere."""
    dset = parse_direction_spec(spec)
    if dset.kind == "hemi":
        return dset
    up = dset.directions[:, 2] > 0
    return DirectionSet(dset.directions[up], dset.solid_angles[up], "custom",
                        {"from": dset.spec})


def smooth_in_coverage(images, coverage, sigma: float) -> np.ndarray:
    """Gaussian smoothing of texture images inside the UV coverage (normalised convolution).

    The indirect light is smooth across a surface but a low-sample bake of it is noisy; a blur
    of ``sigma`` texels removes much of the noise, but also the term's spatial detail (measured
    on bumps, 400 directions, error of the indirect part relative to the whole image: 0.75 texels
    beat 1.5 and 0.5 at 128^2 and 256^2; docs/bench/2026-transport-log.md). Only covered texels contribute, so the empty space
    between UV islands does not darken their borders; uncovered texels keep their values.

    Parameters
    ----------
    images : ndarray, shape (N, R, R, C) or (R, R, C)
    coverage : ndarray of bool, shape (R, R)
    sigma : float
        Texels; 0 returns the images unchanged.

    Returns
    -------
    ndarray of the input's shape, float32
    """
    from scipy.ndimage import gaussian_filter

    imgs = np.asarray(images, np.float32)
    if sigma <= 0:
        return imgs
    single = imgs.ndim == 3
    if single:
        imgs = imgs[None]
    m = np.asarray(coverage, bool).astype(np.float64)
    wsum = gaussian_filter(m, sigma, mode="nearest")
    out = imgs.copy()
    inside = (m > 0) & (wsum > 1e-6)
    for n in range(imgs.shape[0]):
        for c in range(imgs.shape[3]):
            num = gaussian_filter(imgs[n, :, :, c].astype(np.float64) * m, sigma, mode="nearest")
            out[n, :, :, c][inside] = (num[inside] / wsum[inside]).astype(np.float32)
    return out[0] if single else out
