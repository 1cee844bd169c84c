"""EXR round trips through the real OpenEXR package."""

import os

import numpy as np
import pytest

from relightable_textures.lt_addon.io import exrio


def test_round_trip_float_exact_and_half_within_half_precision(tmp_path):
    rng = np.random.default_rng(0)
    img = rng.normal(size=(8, 5)) * 10.0
    meta = {"order": 7, "centres": [[0.1, -0.2]], "name": "bake"}
    size = exrio.write_exr(str(tmp_path / "f.exr"), {"b00.R": img, "b01.R": -img}, meta, "float")
    assert size == os.path.getsize(tmp_path / "f.exr") > 0
    ch, got = exrio.read_exr(str(tmp_path / "f.exr"))
    assert got == meta
    np.testing.assert_array_equal(ch["b00.R"], img.astype(np.float32))
    np.testing.assert_array_equal(ch["b01.R"], -img.astype(np.float32))
    exrio.write_exr(str(tmp_path / "h.exr"), {"Y": img}, pixel_type="half")
    ch, got = exrio.read_exr(str(tmp_path / "h.exr"))
    assert got == {} and ch["Y"].dtype == np.float16
    # half keeps 11 significant bits: relative error <= 2^-11
    np.testing.assert_allclose(ch["Y"].astype(np.float64), img, rtol=2.0 ** -11)


def test_rows_are_stored_top_first_in_the_file(tmp_path):
    """Row 0 of our arrays is the bottom; in the file the first scanline is the top."""
    import OpenEXR

    img = np.arange(6, dtype=np.float32).reshape(3, 2)
    exrio.write_exr(str(tmp_path / "r.exr"), {"Y": img}, pixel_type="float")
    with OpenEXR.File(str(tmp_path / "r.exr")) as f:
        np.testing.assert_array_equal(f.channels()["Y"].pixels, img[::-1])


def test_half_overflow_nan_and_shapes_are_refused_and_nothing_is_written(tmp_path):
    target = tmp_path / "x.exr"
    target.write_bytes(b"previous")
    with pytest.raises(ValueError, match="half-float range"):
        exrio.write_exr(str(target), {"Y": np.full((2, 2), 70000.0)}, pixel_type="half")
    with pytest.raises(ValueError, match="NaN or inf"):
        exrio.write_exr(str(target), {"Y": np.array([[np.nan]])})
    with pytest.raises(ValueError, match="one shape"):
        exrio.write_exr(str(target), {"A": np.zeros((2, 2)), "B": np.zeros((3, 2))})
    assert target.read_bytes() == b"previous"
    assert sorted(os.listdir(tmp_path)) == ["x.exr"]
    exrio.write_exr(str(target), {"Y": np.full((2, 2), 70000.0)}, pixel_type="float")
    np.testing.assert_array_equal(exrio.read_exr(str(target))[0]["Y"], 70000.0)


def test_layer_channel_names_stay_separate(tmp_path):
    """OpenEXR groups "layer.R/G/B" into one array by default; we keep named channels apart."""
    chans = {f"b00.{c}": np.full((2, 3), i, dtype=np.float32) for i, c in enumerate("RGB")}
    exrio.write_exr(str(tmp_path / "l.exr"), chans, pixel_type="float")
    back, _ = exrio.read_exr(str(tmp_path / "l.exr"))
    assert sorted(back) == ["b00.B", "b00.G", "b00.R"]
    np.testing.assert_array_equal(back["b00.G"], 1.0)
