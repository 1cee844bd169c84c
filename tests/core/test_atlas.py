"""Atlas packing: exact round trip, and bilinear lookups at tile edges never read a neighbour."""

import numpy as np
import pytest

from relightable_textures.lt_addon.io.atlas import atlas_layout, pack_atlas, unpack_atlas


def bilinear(img, U, V):
    """Blender-style bilinear lookup: texel i has its centre at (i + 0.5) / size."""
    h, w = img.shape[:2]
    x, y = U * w - 0.5, V * h - 0.5
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0
    x0c, x1c = np.clip([x0, x0 + 1], 0, w - 1)
    y0c, y1c = np.clip([y0, y0 + 1], 0, h - 1)
    return ((1 - fx) * (1 - fy) * img[y0c, x0c] + fx * (1 - fy) * img[y0c, x1c]
            + (1 - fx) * fy * img[y1c, x0c] + fx * fy * img[y1c, x1c])


@pytest.mark.parametrize("n, r", [(1, 4), (9, 5), (49, 8), (10, 3)])
def test_round_trip_is_exact(n, r):
    imgs = np.random.default_rng(n).normal(size=(n, r, r, 3)).astype(np.float32)
    atlas = pack_atlas(imgs)
    lay = atlas_layout(n, r)
    assert atlas.shape == (lay["height"], lay["width"], 3)
    np.testing.assert_array_equal(unpack_atlas(atlas, n, r), imgs)


def test_texel_centres_and_edges_map_into_the_right_tile():
    n, r = 9, 4
    imgs = np.stack([np.full((r, r, 1), float(k)) for k in range(n)])
    imgs[4, 0, 0, 0] = 100.0  # a marked corner texel of tile 4
    atlas = pack_atlas(imgs, "edge")
    lay = atlas_layout(n, r)
    for k, (su, sv, ou, ov) in enumerate(lay["tiles"]):
        for u in (0.0, 0.3, 1.0):  # tile edges included: bilinear must stay in the tile
            for v in (0.0, 0.7, 1.0):
                got = bilinear(atlas, ou + u * su, ov + v * sv)[0]
                if k != 4:
                    assert got == pytest.approx(k)
    su, sv, ou, ov = lay["tiles"][4]
    # the centre of texel (0, 0) of tile 4 reads exactly that texel
    assert bilinear(atlas, ou + 0.5 / r * su, ov + 0.5 / r * sv)[0] == pytest.approx(100.0)


def test_wrap_padding_filters_across_the_seam_of_a_tileable_texture():
    r = 4
    tile = np.arange(r * r, dtype=np.float64).reshape(1, r, r, 1)
    atlas = pack_atlas(tile, "wrap")
    su, sv, ou, ov = atlas_layout(1, r)["tiles"][0]
    # at u = 0 (the seam) bilinear averages the first and last columns
    got = bilinear(atlas, ou, ov + 0.5 / r * sv)[0]
    assert got == pytest.approx(0.5 * (tile[0, 0, 0, 0] + tile[0, 0, -1, 0]))
