"""Packing N basis textures into one padded atlas image for GPU previews.

GPUs give a material a limited number of image samplers (EEVEE here: 24; 25-28 fail
*silently*, DESIGN.md sec. 4), so the N = N1^2 basis textures are packed into one atlas that
the preview samples N times at different offsets (one sampler).

Layout: ``cols = ceil(sqrt(N))`` tiles per row; tile ``k`` sits at column ``k % cols`` and row
``k // cols`` counted from the bottom. Each R x R tile has a one-texel border (stride R + 2) so
bilinear filtering at a tile edge never reads a neighbour: ``"edge"`` repeats the edge texels
(objects), ``"wrap"`` copies the opposite edge (tileable patches, so the seam filters
across). A UV ``(u, v)`` in [0, 1]^2 of tile ``k`` maps to atlas UV::

    U = (col * (R + 2) + 1 + u * R) / width,   V = (row * (R + 2) + 1 + v * R) / height

which puts texel centres of the tile exactly on texel centres of the atlas.
"""

from __future__ import annotations

import math

import numpy as np

PADDING_MODES = ("edge", "wrap")


def atlas_layout(n_tiles: int, resolution: int) -> dict:
    """Grid, size and per-tile UV transform of the atlas.

    Returns
    -------
    dict
        ``cols``, ``rows``, ``stride`` (R + 2), ``width``, ``height`` (texels), and ``tiles``:
        a list of ``(scale_u, scale_v, offset_u, offset_v)`` with ``U = offset_u + u * scale_u``.
    """
    if n_tiles < 1 or resolution < 1:
        raise ValueError(f"need n_tiles >= 1 and resolution >= 1, got {n_tiles}, {resolution}")
    cols = math.ceil(math.sqrt(n_tiles))
    rows = math.ceil(n_tiles / cols)
    stride = resolution + 2
    width, height = cols * stride, rows * stride
    tiles = []
    for k in range(n_tiles):
        col, row = k % cols, k // cols
        tiles.append((resolution / width, resolution / height,
                      (col * stride + 1) / width, (row * stride + 1) / height))
    return {"cols": cols, "rows": rows, "stride": stride, "width": width, "height": height,
            "tiles": tiles}


def pack_atlas(images: np.ndarray, padding: str = "edge") -> np.ndarray:
    """Pack tiles into a padded atlas.

    Parameters
    ----------
    images : ndarray, shape (N, R, R, C)
        Row 0 at the bottom.
    padding : {"edge", "wrap"}

    Returns
    -------
    atlas : ndarray, shape (height, width, C), dtype of ``images``; unused tiles are 0.
    """
    if padding not in PADDING_MODES:
        raise ValueError(f"padding must be one of {PADDING_MODES}, got {padding!r}")
    imgs = np.asarray(images)
    if imgs.ndim != 4 or imgs.shape[1] != imgs.shape[2]:
        raise ValueError(f"images must have shape (N, R, R, C), got {imgs.shape}")
    n, r = imgs.shape[0], imgs.shape[1]
    lay = atlas_layout(n, r)
    atlas = np.zeros((lay["height"], lay["width"], imgs.shape[3]), dtype=imgs.dtype)
    s = lay["stride"]
    for k in range(n):
        col, row = k % lay["cols"], k // lay["cols"]
        padded = np.pad(imgs[k], ((1, 1), (1, 1), (0, 0)), mode=padding)
        atlas[row * s:(row + 1) * s, col * s:(col + 1) * s] = padded
    return atlas


def unpack_atlas(atlas: np.ndarray, n_tiles: int, resolution: int) -> np.ndarray:
    """Inverse of :func:`pack_atlas`: shape (N, R, R, C)."""
    lay = atlas_layout(n_tiles, resolution)
    s = lay["stride"]
    out = np.empty((n_tiles, resolution, resolution, atlas.shape[2]), dtype=atlas.dtype)
    for k in range(n_tiles):
        col, row = k % lay["cols"], k // lay["cols"]
        out[k] = atlas[row * s + 1:row * s + 1 + resolution, col * s + 1:col * s + 1 + resolution]
    return out
