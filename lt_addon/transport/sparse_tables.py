"""Sparse kernel tables: the viewport relights from T itself, a few baked directions per pixel.

A global PCA of ``T`` smears a cast shadow over a large receiver (a ground plane) unless it
keeps hundreds of components; relighting from ``T`` needs only the few directions the sun
kernel touches -- three for a point sun with the ``"linear"`` kernel (barycentric weights over
the triangulated direction set), a handful for a small disc. The viewport stores:

* ``T`` packed three directions per RGB tile of an atlas (direction ``s`` in tile ``s // 3``,
  channel ``s % 3``);
* for each texel of a ``D x D`` grid over the hemisphere disk (:func:`.texture.disk_grid`,
  texel centres at ``(i + 0.5) / D``), the ``K`` largest kernel weights of a sun at that
  texel's direction and their direction indices, the weights rescaled to the kernel's own sum
  (:func:`sparse_weight_tables`).

A light direction is looked up bilinearly *in the weights*: the four table texels around its
disk point each contribute their ``K`` taps times their bilinear factor, so the light moves
continuously and at a table texel centre the relight is exactly the (truncated) kernel's
(:func:`sparse_weights_at`). The node tree does the same with Closest lookups of the index and
weight tables at the four corners (``operators/transport_preview.py``). Per pixel: 4 corners x
(2 table lookups + K atlas lookups).

All arrays: indices int64 ``(D, D, K)``, weights float32 ``(D, D, K)`` (dimensionless, summing
to 1 per texel above the horizon, as :func:`.texture.sun_weights`).
"""

from __future__ import annotations

import numpy as np

from ..sphere.directions import DirectionSet
from ..sphere.hemisphere import disk_to_hemisphere, hemisphere_to_disk, normalize_directions
from .texture import disk_grid, sun_weights

#: Taps per table texel: one RGB table lookup holds three indices, another three weights.
TAPS = (3, 6)
#: Texels across the disk of the sparse tables. Measured on bumps demo (400 directions, 256^2,
#: 2-degree sun, the four held-out lights of issue 13): the viewport's relight vs T's own was
#: 0.028 at 32, 0.0047 at 64, 0.0004 at 128 (tabulation 0.2 / 0.5 / 2.0 s).
TABLE_SIZE = 64
#: ``auto`` shows T itself when its atlas (three directions per RGB tile, plus the albedo
#: tile) takes at most this much of Blender's memory as a float RGBA image: 400 directions at
#: 256^2 take 146 MiB, 1600 directions 585 MiB (the GPU holds half of it in half floats).
AUTO_BYTES = 256 << 20


def atlas_layout_bytes(n_directions: int, resolution: int) -> tuple[int, int]:
    """(atlas side in texels -- the larger of width and height --, bytes as float32 RGBA) of
    the T preview atlas (``ceil(S/3)`` direction tiles + the albedo tile, 1-texel padding)."""
    from ..io.atlas import atlas_layout

    lay = atlas_layout(-(-int(n_directions) // 3) + 1, int(resolution))
    return max(lay["width"], lay["height"]), lay["width"] * lay["height"] * 16


def choose_viewport(setting: str, n_directions: int, resolution: int,
                    max_side: int = 16384) -> tuple[str, str]:
    """``("transport" | "pca", why)`` for a viewport setting ``auto|transport|pca``.

    ``transport`` is refused (ValueError with the figure) when the atlas side exceeds
    ``max_side`` (the usual GPU texture limit)."""
    side, nbytes = atlas_layout_bytes(n_directions, resolution)
    mib = nbytes / 2**20
    if setting == "pca":
        return "pca", "asked for"
    if setting == "transport":
        if side > max_side:
            raise ValueError(f"the T preview atlas would be {side} texels across (over "
                             f"{max_side}); use the PCA viewport or fewer directions")
        return "transport", f"asked for ({mib:.0f} MiB atlas)"
    if setting != "auto":
        raise ValueError(f"viewport must be auto, transport or pca, got {setting!r}")
    if nbytes <= AUTO_BYTES and side <= max_side:
        return "transport", f"auto: the T atlas takes {mib:.0f} MiB (at most {AUTO_BYTES >> 20})"
    return "pca", f"auto: the T atlas would take {mib:.0f} MiB (over {AUTO_BYTES >> 20})"


_TABLES: dict = {}


def cached_tables(dset: DirectionSet, size: int, sun_angle_deg: float, kernel: str,
                  taps: int = 3):
    """:func:`sparse_weight_tables`, memoised per (direction set, size, sun, kernel, taps)."""
    key = (dset.spec, dset.size, int(size), float(sun_angle_deg), kernel, taps)
    if dset.kind == "custom":
        key = key + (id(dset),)
    if key not in _TABLES:
        if len(_TABLES) > 8:
            _TABLES.clear()
        _TABLES[key] = sparse_weight_tables(dset, size, sun_angle_deg, kernel, taps)
    return _TABLES[key]


def sparse_weight_tables(dset: DirectionSet, size: int, sun_angle_deg: float = 0.0,
                         kernel: str = "linear", taps: int = 3) -> tuple[np.ndarray, np.ndarray,
                                                                           float]:
    """Top-``taps`` kernel weights of a sun at every disk texel centre.

    Texels whose centre lies outside the unit disk hold the rim's weights (as
    :func:`.texture.coefficient_tables`), so bilinear weights stay continuous up to the horizon.

    Returns
    -------
    indices : ndarray, shape (D, D, taps), int64 (unused taps: index 0, weight 0)
    weights : ndarray, shape (D, D, taps), float32, rescaled to sum to 1
    kept : float
        The smallest fraction of a texel's kernel mass the kept taps held before rescaling
        (1.0 when no texel needed more than ``taps``): how much truncation changed the kernel.
    """
    if taps not in TAPS:
        raise ValueError(f"taps must be one of {TAPS}, got {taps!r}")
    if size < 2:
        raise ValueError(f"table size must be >= 2, got {size}")
    xy = disk_grid(size).reshape(-1, 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    inside = np.where(r > 0.999, 0.999 / np.maximum(r, 1e-12), 1.0)
    dirs = disk_to_hemisphere(xy * inside[:, None])
    idx = np.zeros((size * size, taps), np.int64)
    wts = np.zeros((size * size, taps), np.float64)
    kept = 1.0
    for i, d in enumerate(dirs):
        ii, w = sun_weights(dset, d, sun_angle_deg, kernel)
        if len(ii) == 0:
            continue
        order = np.argsort(-w, kind="stable")[:taps]
        total = float(w.sum())
        part = float(w[order].sum())
        kept = min(kept, part / total)
        idx[i, :len(order)] = ii[order]
        wts[i, :len(order)] = w[order] * (total / part)
    return (idx.reshape(size, size, taps), wts.reshape(size, size, taps).astype(np.float32),
            kept)


def corners(size: int, direction) -> list[tuple[int, int, float]]:
    """The four table texels around a light's disk point and their bilinear factors, as a
    GPU sampler with Linear interpolation and Extend weighs them: ``[(row, col, factor)]``;
    empty below the horizon."""
    d = normalize_directions(np.asarray(direction, np.float64).reshape(1, 3))[0]
    if d[2] <= 0:
        return []
    D = int(size)
    xy = hemisphere_to_disk(d[None])[0]
    fx = np.clip((xy[0] + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0)
    fy = np.clip((xy[1] + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0)
    x0, y0 = min(int(np.floor(fx)), D - 2), min(int(np.floor(fy)), D - 2)
    ax, ay = fx - x0, fy - y0
    return [(y0, x0, (1 - ax) * (1 - ay)), (y0, x0 + 1, ax * (1 - ay)),
            (y0 + 1, x0, (1 - ax) * ay), (y0 + 1, x0 + 1, ax * ay)]


def sparse_weights_at(indices, weights, direction) -> tuple[np.ndarray, np.ndarray]:
    """The viewport's kernel for a light direction: bilinear in the table texels' weights.

    Returns (indices (M,), weights (M,) float64) with repeated directions merged; empty below
    the horizon. ``store.relight(*sparse_weights_at(...))`` is the viewport's irradiance/pi."""
    idx = np.asarray(indices)
    w = np.asarray(weights, np.float64)
    acc: dict[int, float] = {}
    for row, col, f in corners(idx.shape[0], direction):
        for s, ws in zip(idx[row, col], w[row, col]):
            if ws != 0.0:
                acc[int(s)] = acc.get(int(s), 0.0) + f * float(ws)
    keys = sorted(acc)
    return np.array(keys, np.int64), np.array([acc[k] for k in keys])


def pack_directions(T: np.ndarray) -> np.ndarray:
    """(S, R, R) -> (ceil(S/3), R, R, 3): direction ``s`` in tile ``s // 3``, channel ``s % 3``
    (zero-padded)."""
    T = np.asarray(T)
    S, R = T.shape[0], T.shape[1]
    n = -(-S // 3)
    out = np.zeros((n * 3, R, R), T.dtype)
    out[:S] = T
    return out.reshape(n, 3, R, R).transpose(0, 2, 3, 1)


def viewport_relight(tiles, indices, weights, direction) -> np.ndarray:
    """NumPy twin of the sparse node group's direct irradiance/pi: (R, R) float64 from the
    packed (half-float) tiles (:func:`pack_directions`)."""
    tiles = np.asarray(tiles, np.float64)
    ii, ww = sparse_weights_at(indices, weights, direction)
    out = np.zeros(tiles.shape[1:3])
    for s, w in zip(ii, ww):
        out += w * tiles[s // 3, :, :, s % 3]
    return out
