"""Captions burnt into comparison pictures: where the ink lands, and what does not fit."""

import numpy as np
import pytest

from relightable_textures.lt_addon.io import label


def test_caption_adds_a_band_on_top_and_leaves_the_picture_alone():
    img = np.full((20, 200, 3), 128, np.uint8)
    out = label.caption(img, "Cycles Sun 2 deg", scale=2)
    band = (label.GLYPH_H + 4) * 2
    assert out.shape == (20 + band, 200, 3)
    np.testing.assert_array_equal(out[band:], img)                 # the picture is untouched
    ink = np.all(out[:band] == 255, axis=2)
    # the ink is exactly the text's bitmap, 4 px in from the top left corner
    mask = label.text_mask("Cycles Sun 2 deg", 2)
    assert ink.sum() == mask.sum()
    np.testing.assert_array_equal(ink[4:4 + mask.shape[0], 4:4 + mask.shape[1]], mask)


def test_text_that_does_not_fit_is_cut_with_an_ellipsis():
    img = np.zeros((10, 60, 3), np.uint8)                          # room for 4 glyphs at scale 2
    out = label.caption(img, "preview (baked, relit)", scale=2)
    band = out[:(label.GLYPH_H + 4) * 2]
    assert np.all(band == 255, axis=2).sum() == label.text_mask("p...", 2).sum()


def test_glyphs_are_distinct_and_unknown_characters_are_boxes():
    chars = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.,:|()-"
    bitmaps = {c: label.glyph(c).tobytes() for c in chars}
    assert len(set(bitmaps.values())) == len(chars)
    assert label.glyph("\u00b0").tobytes() == label.glyph("\u2603").tobytes()   # both the box


def test_labelled_row_puts_captioned_panels_side_by_side():
    a, b = np.zeros((16, 30, 3), np.uint8), np.full((16, 40, 3), 200, np.uint8)
    row = label.labelled_row([(a, "a"), (b, "b")], gap=4, scale=1)
    assert row.shape == (16 + label.GLYPH_H + 4, 30 + 4 + 40, 3)
    with pytest.raises(ValueError, match="one height"):
        label.labelled_row([(a, "a"), (np.zeros((8, 8, 3), np.uint8), "c")])


def test_labelled_grid_enlarges_small_panels_so_captions_fit_and_keeps_row_order():
    """A 32-texel bake would fit 3 letters per caption; the grid enlarges it by a whole factor
    (nearest texel, so the picture's values are kept exactly) to >= min_width."""
    top, bottom = np.full((8, 32, 3), 10, np.uint8), np.full((8, 32, 3), 250, np.uint8)
    grid = label.labelled_grid([[(top, "top a"), (top, "top b")],
                                [(bottom, "bottom a"), (bottom, "bottom b")]],
                               gap=4, min_width=100, scale=1)
    k = 4                                                  # ceil(100 / 32)
    band = label.GLYPH_H + 4
    assert grid.shape == (2 * (band + 8 * k) + 4, 2 * 32 * k + 4, 3)
    np.testing.assert_array_equal(grid[band:band + 8 * k, :32 * k], 10)      # top row first
    y = band + 8 * k + 4 + band
    np.testing.assert_array_equal(grid[y:y + 8 * k, :32 * k], 250)
    caption = grid[band + 8 * k + 4:y, :32 * k]                            # 2nd row's band
    assert np.all(caption == 255, axis=2).sum() == label.text_mask("bottom a", 1).sum()
    with pytest.raises(ValueError, match="nothing"):
        label.labelled_grid([])
