"""Sparse kernel tables: the viewport relights from T itself, a few baked directions per pixel.

A global PCA of ``T`` smears a cast shadow over a large receiver (a ground plane) unless it
keeps hundreds of components; relighting from ``T`` needs only the few directions the sun
kernel touches -- three for a point sun with the ``"linear"`` kernel (barycentric weights over
the triangulated direction set), a handful for a small disc. The viewport stores:

* ``T`` packed three directions per RGB tile of an 8-bit atlas (direction ``s`` in tile
  ``s // 3``, channel ``s % 3``; one scale per direction, folded into the weights:
  :func:`quantize_directions`);
* for each texel of a ``D x D`` grid over the hemisphere disk (:func:`.texture.disk_grid`,
  texel centres at ``(i + 0.5) / D``), the ``K`` largest kernel weights of a sun at that
  texel's direction and their direction indices, the weights rescaled to the kernel's own sum
  (:func:`sparse_weight_tables`).

A light direction is looked up bilinearly *in the weights*: the four table texels around its
disk point each contribute their ``K`` taps times their bilinear factor, so the light moves
continuously and at a table texel centre the relight is exactly the (truncated) kernel's
(:func:`sparse_weights_at`). The node tree does the same with Closest lookups of the index and
weight tables at the four corners (``operators/preview/transport_preview.py``; ``K`` from
:func:`choose_taps`, 3 to 12, the tables stored as ``K / 3`` RGB parts side by side). Per
pixel: 4 corners x (2 K / 3 table lookups + K atlas lookups).

All arrays: indices int64 ``(D, D, K)``, weights float32 ``(D, D, K)`` (dimensionless, summing
to the kernel's own mass: 1 inside the baked directions' hull, less towards the horizon, as
:func:`.texture.sun_weights`).
"""

from __future__ import annotations

import numpy as np

from ..sphere.directions import DirectionSet
from ..sphere.hemisphere import disk_to_hemisphere, hemisphere_to_disk, normalize_directions
from .texture import disk_grid, set_digest, sun_weights

#: Taps per table texel, a multiple of three: one RGB lookup of each table holds three indices
#: or three weights.
TAPS = (3, 6, 9, 12)
#: The viewport takes the fewest taps that hold this share of every table texel's kernel.
#: Measured on bumps demo (400 directions, 256^2, 64^2 tables, the four held-out lights)
#: against T's own relight: a 2-degree sun 0.0047 with 3 or 6 taps (3 hold 95 % of its
#: kernel), a 5-degree sun 0.0059 / 0.0043 (3 hold 72 %, 6 98 %), a 10-degree sun 0.034 /
#: 0.0057 (64 % / 89 %).
MIN_KEPT = 0.85
#: Texels across the disk of the sparse tables. Measured on bumps demo (400 directions, 256^2,
#: 2-degree sun, the four held-out lights of issue 13): the viewport's relight vs T's own was
#: 0.028 at 32, 0.0047 at 64, 0.0004 at 128 (tabulation 0.2 / 0.5 / 2.0 s).
TABLE_SIZE = 64
#: ``auto`` shows T itself when its atlas (RGBA bytes in Blender's memory; the GPU holds the
#: same) fits the GPU budget (``--gpu-budget``, MiB, 512 by default): 400 directions at 256^2
#: take 37 MiB, 1600 directions 140 MiB, 1600 at 512^2 556 MiB.
DEFAULT_BUDGET_MIB = 512


def atlas_layout_bytes(n_directions: int, resolution: int) -> tuple[int, int]:
    """(atlas side in texels -- the larger of width and height --, bytes in Blender's memory
    as an 8-bit RGBA image) of the T preview atlas (``ceil(S/3)`` tiles, 1-texel padding)."""
    from ..io.atlas import atlas_layout

    lay = atlas_layout(-(-int(n_directions) // 3), int(resolution))
    return max(lay["width"], lay["height"]), lay["width"] * lay["height"] * 4


def choose_viewport(setting: str, n_directions: int, resolution: int,
                    max_side: int = 16384, budget_mib: float = DEFAULT_BUDGET_MIB,
                    table_size: int = 32) -> tuple[str, str]:
    """``("transport" | "blocks" | "pca", why)`` for a viewport setting
    ``auto|transport|blocks|pca`` and a GPU budget of ``budget_mib``.

    ``auto``: T itself when its atlas fits the budget, else the block viewport when a block
    size fits it (:func:`.block_viewport.candidates`; after the fit the bake keeps the PCA
    instead when the PCA is measured closer to T), else the PCA. ``transport`` is refused
    (ValueError with the figure) when the atlas side exceeds ``max_side`` (the usual GPU texture
    limit), ``blocks`` when not three components per block fit the budget."""
    from . import block_viewport as bv

    side, nbytes = atlas_layout_bytes(n_directions, resolution)
    mib = nbytes / 2**20
    budget = int(budget_mib * 2**20)
    if setting == "pca":
        return "pca", "asked for"
    if setting == "horizon":   # (shown when the bake made the map: bundle.fit_viewport)
        shows, why = choose_viewport("auto", n_directions, resolution, max_side, budget_mib,
                                     table_size)
        return shows, "no horizon map (its direct light was not baked by rays); " + why
    if setting == "transport":
        if side > max_side:
            raise ValueError(f"the T preview atlas would be {side} texels across (over "
                             f"{max_side}); use the block or PCA viewport or fewer directions")
        return "transport", f"asked for ({mib:.0f} MiB atlas)"
    blocks = bv.candidates(resolution, table_size, budget)
    if setting == "blocks":
        if not blocks:
            raise ValueError(f"the block viewport does not fit {budget_mib:g} MiB of GPU memory "
                             f"at {resolution}^2 (raise --gpu-budget or use the PCA viewport)")
        return "blocks", f"asked for (within {budget_mib:g} MiB)"
    if setting != "auto":
        raise ValueError(f"viewport must be auto, transport, blocks or pca, got {setting!r}")
    if nbytes <= budget and side <= max_side:
        return "transport", f"auto: the T atlas takes {mib:.0f} MiB (at most {budget_mib:g})"
    if blocks:
        return "blocks", (f"auto: the T atlas would take {mib:.0f} MiB (over {budget_mib:g}); "
                          "a PCA per texel block fits")
    return "pca", f"auto: the T atlas would take {mib:.0f} MiB (over {budget_mib:g})"


_TABLES: dict = {}


def cached_tables(dset: DirectionSet, size: int, sun_angle_deg: float, kernel: str,
                  taps: int | None = None):
    """:func:`sparse_weight_tables` (``taps=None``: :func:`choose_taps`), memoised per
    (direction set, size, sun, kernel, taps). Returns (indices, weights, kept)."""
    # (by the directions' bytes: every bake's set is a custom one since the band under the
    # horizon, and a collected set's id() is reused)
    key = (set_digest(dset), int(size), float(sun_angle_deg), kernel, taps)
    if key not in _TABLES:
        if len(_TABLES) > 8:
            _TABLES.clear()
        if taps is None:
            _TABLES[key] = choose_taps(dset, size, sun_angle_deg, kernel)
        else:
            _TABLES[key] = sparse_weight_tables(dset, size, sun_angle_deg, kernel, taps)
    return _TABLES[key]


def _top_weights(dset, size, sun_angle_deg, kernel, taps):
    """Per disk texel: the ``taps`` largest kernel weights (unscaled, descending), their
    indices and the kernel's total mass; (D*D, taps), (D*D, taps), (D*D,)."""
    if size < 2:
        raise ValueError(f"table size must be >= 2, got {size}")
    xy = disk_grid(size).reshape(-1, 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    inside = np.where(r > 0.999, 0.999 / np.maximum(r, 1e-12), 1.0)
    dirs = disk_to_hemisphere(xy * inside[:, None])
    idx = np.zeros((size * size, taps), np.int64)
    wts = np.zeros((size * size, taps), np.float64)
    total = np.zeros(size * size)
    for i, d in enumerate(dirs):
        ii, w = sun_weights(dset, d, sun_angle_deg, kernel)
        if len(ii) == 0:
            continue
        order = np.argsort(-w, kind="stable")[:taps]
        total[i] = float(w.sum())
        idx[i, :len(order)] = ii[order]
        wts[i, :len(order)] = w[order]
    return idx, wts, total


def _truncate(idx, wts, total, size, taps):
    part = wts[:, :taps].sum(1)
    ok = total > 0
    kept = float(np.min(part[ok] / total[ok])) if ok.any() else 1.0
    scale = np.where(ok, total / np.where(part > 0, part, 1.0), 0.0)
    w = wts[:, :taps] * scale[:, None]
    return (idx[:, :taps].reshape(size, size, taps).copy(),
            w.reshape(size, size, taps).astype(np.float32), kept)


def sparse_weight_tables(dset: DirectionSet, size: int, sun_angle_deg: float = 0.0,
                         kernel: str = "linear", taps: int = 3) -> tuple[np.ndarray, np.ndarray,
                                                                           float]:
    """Top-``taps`` kernel weights of a sun at every disk texel centre.

    Texels whose centre lies outside the unit disk hold the rim's weights (as
    :func:`.texture.coefficient_tables`), so bilinear weights stay continuous up to the horizon.

    Returns
    -------
    indices : ndarray, shape (D, D, taps), int64 (unused taps: index 0, weight 0)
    weights : ndarray, shape (D, D, taps), float32, rescaled to the kernel's own sum
    kept : float
        The smallest fraction of a texel's kernel mass the kept taps held before rescaling
        (1.0 when no texel needed more than ``taps``): how much truncation changed the kernel.
    """
    if taps not in TAPS:
        raise ValueError(f"taps must be one of {TAPS}, got {taps!r}")
    return _truncate(*_top_weights(dset, size, sun_angle_deg, kernel, taps), size, taps)


def choose_taps(dset: DirectionSet, size: int, sun_angle_deg: float = 0.0,
                kernel: str = "linear", min_kept: float = MIN_KEPT):
    """:func:`sparse_weight_tables` with the fewest :data:`TAPS` whose ``kept`` reaches
    ``min_kept`` (else the most): a point sun takes 3, a wide sun over dense directions 12."""
    top = _top_weights(dset, size, sun_angle_deg, kernel, TAPS[-1])
    for taps in TAPS:
        out = _truncate(*top, size, taps)
        if out[2] >= min_kept:
            return out
    return out


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
        if f == 0.0:
            continue
        for s, ws in zip(idx[row, col], w[row, col]):
            if ws != 0.0:
                acc[int(s)] = acc.get(int(s), 0.0) + f * float(ws)
    keys = sorted(acc)
    return np.array(keys, np.int64), np.array([acc[k] for k in keys])


def quantize_directions(T) -> tuple[np.ndarray, np.ndarray]:
    """T as 8-bit tiles with one scale per direction (the viewport's atlas).

    ``T`` (S, P) or (S, R, R), any real dtype (a memmap is read one direction at a time).
    Returns ``tiles`` (ceil(S/3), R, R, 3) uint8 -- direction ``s`` in tile ``s // 3``, channel
    ``s % 3``, ``q = rint(255 T[s] / scale[s])`` -- and ``scales`` (S,) float64, each
    direction's maximum (1 for an all-zero direction). A texel reads back as
    ``q / 255 * scale[s]``: at most half a step, ``scale[s] / 510``, from T. The scales go into
    the weight tables (:func:`scaled_weights`), so the node tree pays nothing for them, and a
    grazing direction, whose values are all small, keeps its relative precision. 8 bits make
    the atlas a quarter of a float one in Blender's memory and on the GPU."""
    S = T.shape[0]
    R = int(round(np.sqrt(np.prod(T.shape[1:]))))
    n = -(-S // 3)
    tiles = np.zeros((n, R, R, 3), np.uint8)
    scales = np.ones(S)
    for s in range(S):
        row = np.asarray(T[s], np.float64).reshape(R, R)
        if np.any(row < 0) or not np.all(np.isfinite(row)):
            raise ValueError(f"direction {s} has negative or non-finite transport values")
        top = float(row.max())
        if top > 0:
            scales[s] = top
            tiles[s // 3, :, :, s % 3] = np.rint(row * (255.0 / top)).astype(np.uint8)
    return tiles, scales


def scaled_weights(indices, weights, scales) -> np.ndarray:
    """Weights times their directions' atlas scales (:func:`quantize_directions`), float32."""
    idx = np.asarray(indices)
    w = np.asarray(weights, np.float64)
    return np.where(w != 0.0, w * np.asarray(scales, np.float64)[idx], 0.0).astype(np.float32)


def viewport_relight(tiles, indices, weights, direction, unit: float = 1.0) -> np.ndarray:
    """NumPy twin of the sparse node group's direct irradiance/pi: (R, R) float64 from packed
    tiles (direction ``s`` in tile ``s // 3``, channel ``s % 3``) as the GPU reads them times
    ``unit`` -- the uint8 tiles of :func:`quantize_directions` with ``unit = 1/255`` and
    :func:`scaled_weights`. Reads only the tiles the light touches."""
    tiles = np.asarray(tiles)
    ii, ww = sparse_weights_at(indices, weights, direction)
    out = np.zeros(tiles.shape[1:3])
    for s, w in zip(ii, ww):
        out += (w * unit) * tiles[s // 3, :, :, s % 3].astype(np.float64)
    return out
