"""A trial of the horizon map on sampled tiles, before its whole cost is spent.

``--viewport auto`` shows an object's horizon map only where it is closer than T to rays at
held-out suns (:func:`.horizon_map.heldout_errors`). Finding the horizons of every texel costs
more than T itself (the statue demo at 256^2: 3.5 s of its 10.5 s of rays), and on curved
objects T wins (statue 0.084 against the map's 0.160), so the map was found and thrown away.

The trial finds the horizons of the texels of a seeded sample of ``TILE x TILE`` tiles of the
horizon grid (:func:`pick`), and compares both viewports at the texture texels whose bilinear
footprint lies wholly inside those tiles: there the map's values are the whole map's, bit for
bit (a texel's horizons do not depend on which other texels are asked; the margin fill only
writes uncovered texels). When one viewport errs more than :data:`DECISIVE` times the other the
choice is made on the sample (:func:`decide`); otherwise the whole map and the whole check
are computed as before. Units: texel indices are flat ``row * side + col``.
"""

from __future__ import annotations

import numpy as np

#: Side of a sampled tile, in horizon texels (a tile of the statue's 128^2 map is 8 x 8 cm of
#: its ground: long enough for a cast shadow's edge and its penumbra to fall inside).
TILE = 8
#: Share of the covered tiles sampled (at least :data:`MIN_TILES` of them).
FRACTION = 1 / 8
#: Fewest tiles worth a trial; with fewer than twice as many covered tiles the trial would cost
#: half the map, and the whole map is found instead.
MIN_TILES = 16
#: Ratio of the two errors above which the sample decides.
DECISIVE = 1.3


def pick(h_texel, h_side: int, texel, side: int, seed: int = 0, tile: int = TILE,
         fraction: float = FRACTION, min_tiles: int = MIN_TILES):
    """The sampled tiles' points: ``(h_rows, t_rows)`` -- indices into ``h_texel`` (the
    horizon grid's covered texels, flat indices at ``h_side``) of the texels inside the sampled
    tiles, and into ``texel`` (the texture's covered texels at ``side``) of those whose bilinear
    footprint (:func:`.horizon_map.upsample`, edges clamped) is four sampled covered horizon
    texels. None when there are too few covered tiles for a trial to save anything."""
    h_texel = np.asarray(h_texel, np.int64)
    texel = np.asarray(texel, np.int64)
    Rh, R = int(h_side), int(side)
    per_row = -(-Rh // tile)
    tile_of = (h_texel // Rh) // tile * per_row + (h_texel % Rh) // tile
    tiles = np.unique(tile_of)
    count = max(min_tiles, int(np.ceil(fraction * len(tiles))))
    if 2 * count > len(tiles):
        return None
    # stratified: one tile at random from each run of consecutive covered tiles (row-major),
    # so the sample spreads over the whole texture (shadows gather in a few places: on the
    # statue's ground a random sample of as many tiles misjudged the ratio of the two errors
    # by up to 1.6x, seeds 0-4)
    rng = np.random.default_rng(seed)
    edges = np.linspace(0, len(tiles), count + 1).astype(np.int64)
    chosen = tiles[edges[:-1] + (rng.random(count) * np.diff(edges)).astype(np.int64)]
    in_tile = np.isin(tile_of, chosen)
    h_rows = np.nonzero(in_tile)[0]
    sampled = np.zeros(Rh * Rh, bool)
    sampled[h_texel[in_tile]] = True
    # the texture texels' bilinear corners in the horizon grid (as upsample reads them)
    x = (np.arange(R) + 0.5) * (Rh / R) - 0.5
    i0 = np.floor(x).astype(np.int64)
    a, b = np.clip(i0, 0, Rh - 1), np.clip(i0 + 1, 0, Rh - 1)
    row, col = texel // R, texel % R
    ok = np.ones(len(texel), bool)
    for r in (a[row], b[row]):
        for c in (a[col], b[col]):
            ok &= sampled[r * Rh + c]
    return h_rows, np.nonzero(ok)[0]


def decide(horizon: float, transport: float, decisive: float = DECISIVE):
    """``"horizon"`` or ``"transport"`` when one errs more than ``decisive`` times the other
    on the sample, else None (find the whole map and check it whole)."""
    if horizon * decisive < transport:
        return "horizon"
    if transport * decisive < horizon:
        return "transport"
    return None
