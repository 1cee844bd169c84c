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
