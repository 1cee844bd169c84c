"""Storage codecs for stacks of basis images, each with its size and reconstruction error.

Codecs (all take a stack ``images`` of shape (N, ...), e.g. (N, H, W, C), and decode to float32):

``uint8`` -- :func:`encode_uint8`
    The paper's scheme (sec. 6.1): each image is quantised uniformly to [0, 255] between its own
    minimum and maximum, which are stored as float32 (``49 * 3`` bytes per texel for RGB plus
    8 bytes per image). Max error ``(max - min) / 510`` per image. A constant image
    (``min == max``) is stored exactly. Optionally one min/max per channel.
``half`` -- :func:`encode_half`
    IEEE float16. Values with ``|x| > 65504`` overflow to inf: by default this raises
    :class:`HalfOverflowError`; with ``on_overflow="float32"`` the codec falls back to storing
    float32 (flagged ``fell_back = True``, twice the bytes, exact). Relative error <= 2**-11
    for normal numbers.
``pca`` -- :func:`encode_pca`
    The N images as rows of an (N, P) matrix ``X``; its best rank-k approximation (truncated SVD,
    no centring, computed in float64 through the N x N Gram matrix) is ``X ~ A E`` with k
    eigen-images ``E`` (k, P) stored as float32 and coefficients ``A`` (N, k) as float64. At run
    time the steering coefficients ``c`` (N,) become ``c A`` (k,), so relighting costs k image
    reads instead of N.

Errors are reported by :func:`reconstruction_error` (max abs, RMS, relative Frobenius, PSNR
against the stack's peak-to-peak range).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Largest finite float16 value.
HALF_MAX = 65504.0


class HalfOverflowError(OverflowError, ValueError):
    """Values exceed the float16 range (|x| > 65504)."""


def _stack(images, name: str = "images") -> np.ndarray:
    a = np.asarray(images)
    if a.ndim < 1 or a.shape[0] < 1:
        raise ValueError(f"{name} must have shape (N, ...) with N >= 1, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf; codecs need finite values")
    return a


def reconstruction_error(original, decoded) -> dict:
    """Error of a decoded stack against the original (computed in float64).

    Parameters
    ----------
    original, decoded : array_like, same shape (N, ...)

    Returns
    -------
    dict
        ``max_abs``, ``rms``, ``rel_fro`` (``||d - o||_F / ||o||_F``, 0 if both zero) and
        ``psnr_db`` (peak = peak-to-peak range of ``original``; inf if exact).
    """
    o = np.asarray(original, dtype=np.float64)
    d = np.asarray(decoded, dtype=np.float64)
    if o.shape != d.shape:
        raise ValueError(f"shape mismatch: original {o.shape}, decoded {d.shape}")
    e = d - o
    max_abs = float(np.max(np.abs(e))) if e.size else 0.0
    rms = float(np.sqrt(np.mean(e * e))) if e.size else 0.0
    no = float(np.linalg.norm(o.ravel()))
    rel = float(np.linalg.norm(e.ravel()) / no) if no > 0 else (0.0 if max_abs == 0 else np.inf)
    rng = float(np.ptp(o)) if o.size else 0.0
    psnr = float("inf") if rms == 0 else (20.0 * np.log10(rng / rms) if rng > 0 else -np.inf)
    return {"max_abs": max_abs, "rms": rms, "rel_fro": rel, "psnr_db": psnr}


# ----------------------------------------------------------------------------------------------
# 8-bit


@dataclass(frozen=True)
class Uint8Encoded:
    """8-bit quantised stack.

    Attributes
    ----------
    data : ndarray, shape (N, ...), uint8
    lo, hi : ndarray, float32
        Per-image minimum and maximum, shape (N,) or (N, C) if ``per_channel``.
    per_channel : bool
    """

    data: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    per_channel: bool = False

    @property
    def nbytes(self) -> int:
        """Stored bytes (quantised data + min/max)."""
        return int(self.data.nbytes + self.lo.nbytes + self.hi.nbytes)

    def decode(self) -> np.ndarray:
        """Dequantise: ``lo + q / 255 * (hi - lo)``; shape (N, ...), float32."""
        shape = self.lo.shape + (1,) * (self.data.ndim - self.lo.ndim)
        if self.per_channel:  # lo is (N, C) and C is the last axis of data
            lo = self.lo.reshape((self.lo.shape[0],) + (1,) * (self.data.ndim - 2)
                                 + (self.lo.shape[1],))
            hi = self.hi.reshape(lo.shape)
        else:
            lo = self.lo.reshape(shape)
            hi = self.hi.reshape(shape)
        lo64 = lo.astype(np.float64)
        span = hi.astype(np.float64) - lo64
        return (lo64 + self.data.astype(np.float64) * (span / 255.0)).astype(np.float32)


def encode_uint8(images, per_channel: bool = False) -> Uint8Encoded:
    """Quantise each image to 8 bits between its own min and max (paper sec. 6.1).

    Parameters
    ----------
    images : array_like, shape (N, ...)
        Basis images (negative values are fine).
    per_channel : bool
        One min/max per image *and* channel (last axis) instead of per image.

    Returns
    -------
    Uint8Encoded
        Constant images decode exactly (their span is 0, data all 0). ``lo`` / ``hi`` are
        stored as float32; the data are rounded to nearest, so the error is at most
        ``(hi - lo) / 510`` plus float32 rounding of ``lo`` / ``hi``.
    """
    a = _stack(images).astype(np.float64)
    if np.abs(a).max(initial=0.0) > np.finfo(np.float32).max:
        raise ValueError("images exceed the float32 range of the stored min/max; "
                         "rescale them before 8-bit encoding")
    if per_channel:
        if a.ndim < 3:
            raise ValueError("per_channel needs images of shape (N, ..., C)")
        axes = tuple(range(1, a.ndim - 1))
        lo = a.min(axis=axes).astype(np.float32)
        hi = a.max(axis=axes).astype(np.float32)
        lo_b = lo.reshape((a.shape[0],) + (1,) * (a.ndim - 2) + (a.shape[-1],))
    else:
        flat = a.reshape(a.shape[0], -1)
        lo = flat.min(axis=1).astype(np.float32)
        hi = flat.max(axis=1).astype(np.float32)
        lo_b = lo.reshape((a.shape[0],) + (1,) * (a.ndim - 1))
    hi_b = hi.reshape(lo_b.shape)
    span = hi_b.astype(np.float64) - lo_b.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(span > 0, (a - lo_b) / np.where(span > 0, span, 1.0) * 255.0, 0.0)
    data = np.clip(np.rint(q), 0, 255).astype(np.uint8)
    return Uint8Encoded(data=data, lo=lo, hi=hi, per_channel=bool(per_channel))


# ----------------------------------------------------------------------------------------------
# half float


@dataclass(frozen=True)
class HalfEncoded:
    """Half-float stack (or float32 after an overflow fallback).

    Attributes
    ----------
    data : ndarray, shape (N, ...), float16 (float32 if ``fell_back``)
    fell_back : bool
        True if values exceeded 65504 and ``on_overflow="float32"`` stored float32 instead.
    """

    data: np.ndarray
    fell_back: bool = False

    @property
    def nbytes(self) -> int:
        """Stored bytes."""
        return int(self.data.nbytes)

    def decode(self) -> np.ndarray:
        """Shape (N, ...), float32."""
        return self.data.astype(np.float32)


def encode_half(images, on_overflow: str = "raise") -> HalfEncoded:
    """Store a stack as float16, detecting overflow.

    Parameters
    ----------
    images : array_like, shape (N, ...)
    on_overflow : {"raise", "float32"}
        What to do if any ``|x| > 65504`` (would become inf): raise :class:`HalfOverflowError`
        (default) or fall back to float32 storage for the whole stack.

    Returns
    -------
    HalfEncoded
    """
    if on_overflow not in ("raise", "float32"):
        raise ValueError(f"on_overflow must be 'raise' or 'float32', got {on_overflow!r}")
    a = _stack(images)
    with np.errstate(over="ignore"):
        h = a.astype(np.float16)  # |x| >= 65520 rounds to inf; up to that rounds to <= 65504
    if np.any(np.isinf(h)):
        peak = float(np.max(np.abs(a)))
        if on_overflow == "raise":
            raise HalfOverflowError(f"half-float overflow: max |value| = {peak:.6g} exceeds "
                                    f"{HALF_MAX:g}; scale the images or use float32 storage")
        return HalfEncoded(data=a.astype(np.float32), fell_back=True)
    return HalfEncoded(data=h, fell_back=False)


# ----------------------------------------------------------------------------------------------
# PCA


@dataclass(frozen=True)
class PCAEncoded:
    """Rank-k factorisation of a stack: ``images[n] ~ sum_m coefficients[n, m] eigen_images[m]``.

    Attributes
    ----------
    eigen_images : ndarray, shape (k, ...), float32
        Orthonormal (as flattened rows, before the float32 cast) eigen-images.
    coefficients : ndarray, shape (N, k), float64
    singular_values : ndarray, shape (N,), float64
        All singular values of the (N, P) stack, for choosing k.
    """

    eigen_images: np.ndarray
    coefficients: np.ndarray
    singular_values: np.ndarray

    @property
    def k(self) -> int:
        return int(self.eigen_images.shape[0])

    @property
    def nbytes(self) -> int:
        """Stored bytes (eigen-images + coefficients)."""
        return int(self.eigen_images.nbytes + self.coefficients.nbytes)

    def decode(self) -> np.ndarray:
        """Shape (N, ...), float32."""
        E = self.eigen_images.reshape(self.k, -1).astype(np.float64)
        out = self.coefficients @ E
        return out.reshape((self.coefficients.shape[0],) + self.eigen_images.shape[1:]).astype(
            np.float32)

    def project_coefficients(self, coefficients) -> np.ndarray:
        """Steering coefficients in the eigen-image basis, ``c A``.

        Parameters
        ----------
        coefficients : array_like, shape (..., N)

        Returns
        -------
        ndarray, shape (..., k), float64
        """
        return np.asarray(coefficients, dtype=np.float64) @ self.coefficients

    @property
    def captured_energy(self) -> float:
        """Fraction of ``||X||_F**2`` kept by the k components."""
        s2 = self.singular_values ** 2
        tot = float(np.sum(s2))
        return float(np.sum(s2[: self.k]) / tot) if tot > 0 else 1.0


def encode_pca(images, k: int) -> PCAEncoded:
    """Best rank-k approximation of a stack of N images (truncated SVD, float64 fit).

    Parameters
    ----------
    images : array_like, shape (N, ...)
    k : int
        Number of eigen-images, 1 <= k <= N.

    Returns
    -------
    PCAEncoded

    Notes
    -----
    Uses the Gram matrix ``G = X X^T`` (N x N, float64) and ``numpy.linalg.eigh``; eigen-images
    are ``E = diag(1/s) V^T X``. Components with ``s <= 1e-12 s_max`` are dropped from the
    reconstruction (their eigen-images are zero) to avoid dividing by noise.
    """
    a = _stack(images)
    N = a.shape[0]
    if int(k) != k or not 1 <= k <= N:
        raise ValueError(f"k must be an integer in [1, {N}], got {k!r}")
    X = a.reshape(N, -1)
    G = np.zeros((N, N), dtype=np.float64)
    chunk = 1 << 18
    for s in range(0, X.shape[1], chunk):
        Xc = X[:, s:s + chunk].astype(np.float64)
        G += Xc @ Xc.T
    lam, V = np.linalg.eigh(G)
    order = np.argsort(lam)[::-1]
    lam, V = np.clip(lam[order], 0.0, None), V[:, order]
    sv = np.sqrt(lam)
    keep = sv[:k] > 1e-12 * (sv[0] if sv[0] > 0 else 1.0)
    Vk = V[:, :k]
    inv = np.where(keep, 1.0 / np.where(keep, sv[:k], 1.0), 0.0)
    E = np.empty((k, X.shape[1]), dtype=np.float32)
    for s in range(0, X.shape[1], chunk):
        E[:, s:s + chunk] = (inv[:, None] * (Vk.T @ X[:, s:s + chunk].astype(np.float64)))
    A = Vk * np.where(keep, sv[:k], 0.0)  # (N, k)
    return PCAEncoded(eigen_images=E.reshape((k,) + a.shape[1:]), coefficients=A,
                      singular_values=sv)


# ----------------------------------------------------------------------------------------------
# comparison table


def codec_table(images, pca_ks=(4, 9, 16, 25, 36, 49), steering=None) -> list[dict]:
    """Encode a stack with every codec and report bytes and errors.

    Parameters
    ----------
    images : array_like, shape (N, ...)
    pca_ks : sequence of int
        PCA ranks to try (values > N are skipped).
    steering : array_like, shape (M, N), optional
        Steering coefficient vectors; if given, also report the error of the *steered* images
        (what a user sees) for each codec, ``steered_rel_fro`` / ``steered_max_abs``, relative
        to the steered float64 originals.

    Returns
    -------
    rows : list of dict
        Each: ``codec``, ``nbytes``, ``bytes_per_texel`` (per pixel of one image, over all N
        images and channels), ``ratio_vs_float32`` and :func:`reconstruction_error` fields.
    """
    a = _stack(images)
    N = a.shape[0]
    texels = int(np.prod(a.shape[1:-1])) if a.ndim >= 3 else int(np.prod(a.shape[1:]))
    f32 = a.size * 4
    encs = [("float32", None), ("uint8", encode_uint8(a)), ("uint8_per_channel",
            encode_uint8(a, per_channel=True) if a.ndim >= 3 else None)]
    try:
        encs.append(("half", encode_half(a)))
    except HalfOverflowError:
        encs.append(("half->float32", encode_half(a, on_overflow="float32")))
    for k in pca_ks:
        if 1 <= k <= N:
            encs.append((f"pca{k}", encode_pca(a, k)))
    S = None if steering is None else np.asarray(steering, dtype=np.float64)
    ref_steered = None
    if S is not None:
        ref_steered = S @ a.reshape(N, -1).astype(np.float64)
    rows = []
    for name, enc in encs:
        if name == "uint8_per_channel" and enc is None:
            continue
        if enc is None:
            dec = a.astype(np.float32)
            nbytes = f32
        else:
            dec = enc.decode()
            nbytes = enc.nbytes
        row = {"codec": name, "nbytes": int(nbytes), "bytes_per_texel": nbytes / texels,
               "ratio_vs_float32": nbytes / f32}
        row.update(reconstruction_error(a, dec))
        if S is not None:
            st = S @ dec.reshape(N, -1).astype(np.float64)
            e = reconstruction_error(ref_steered, st)
            row["steered_rel_fro"] = e["rel_fro"]
            row["steered_max_abs"] = e["max_abs"]
        rows.append(row)
    return rows
