"""Contact sheet sRGB encoding and the stdlib PNG writer."""

import zlib

import numpy as np

from relightable_textures.lt_addon.io.contact_sheet import linear_to_srgb8, read_png, write_png


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
