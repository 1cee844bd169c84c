"""Contact sheet tiling, sRGB encoding and the stdlib PNG writer."""

import zlib

import numpy as np
import pytest

from relightable_textures.lt_addon.io.contact_sheet import linear_to_srgb8, read_png, tile, write_png


def test_srgb_encoding_known_values():
    x = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0, 2.0, -1.0])
    # sRGB: 0.18 -> 0.4614, 0.5 -> 0.7354
    assert linear_to_srgb8(x).tolist() == [0, 10, 118, 188, 255, 255, 0]  # 0.0031308*12.92*255 = 10.3


def test_png_round_trip_and_crc(tmp_path):
    img = np.random.default_rng(0).integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    n = write_png(str(tmp_path / "a.png"), img)
    data = (tmp_path / "a.png").read_bytes()
    assert len(data) == n and data[12:16] == b"IHDR"
    assert int.from_bytes(data[29:33], "big") == zlib.crc32(data[12:29])
    np.testing.assert_array_equal(read_png(str(tmp_path / "a.png")), img)


def test_tile_puts_bottom_first_images_upright():
    a = np.zeros((2, 3, 3))
    a[0] = 1.0  # bottom row of the image
    sheet = tile([[a, 2 * a]], gap=1)
    assert sheet.shape == (2, 7, 3)
    assert sheet[1, 0, 0] == 1.0 and sheet[0, 0, 0] == 0.0  # bottom row stays at the bottom
    assert sheet[1, 4, 0] == 2.0 and np.all(sheet[:, 3] == 0)  # gap column
    with pytest.raises(ValueError, match="all images"):
        tile([[a, np.zeros((3, 3, 3))]])
