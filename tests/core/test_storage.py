"""Storage codecs: 8-bit min/max, half float, PCA eigen-images."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from relightable_textures.lt_addon.io import storage as sto

FAST = settings(max_examples=40, deadline=None)


def _stack(seed=0, n=12):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 16, 16, 3)).cumsum(axis=1) * 0.1


def test_uint8_error_bound_and_bytes():
    x = _stack()
    enc = sto.encode_uint8(x)
    dec = enc.decode()
    assert dec.dtype == np.float32 and enc.data.dtype == np.uint8
    span = (x.reshape(12, -1).max(1) - x.reshape(12, -1).min(1))
    err = np.abs(dec - x).reshape(12, -1).max(1)
    assert np.all(err <= span / 510 * (1 + 1e-5) + 1e-6)
    assert enc.nbytes == x.size + 2 * 4 * 12
    pc = sto.encode_uint8(x, per_channel=True)
    assert pc.lo.shape == (12, 3)
    assert np.abs(pc.decode() - x).max() <= np.abs(dec - x).max() + 1e-6


@FAST
@given(value=st.floats(-1e6, 1e6, allow_nan=False, width=32), n=st.integers(1, 4))
def test_uint8_exact_for_constant_images(value, n):
    x = np.full((n, 3, 5, 2), value, dtype=np.float32)
    assert np.array_equal(sto.encode_uint8(x).decode(), x)
    assert np.array_equal(sto.encode_uint8(x, per_channel=True).decode(), x)


def test_half_overflow_detected():
    x = _stack()
    x[3, 2, 2, 1] = 7.0e4
    with pytest.raises(sto.HalfOverflowError, match="65504"):
        sto.encode_half(x)
    with pytest.raises(OverflowError):  # also catchable as OverflowError / ValueError
        sto.encode_half(-x)
    fb = sto.encode_half(x, on_overflow="float32")
    assert fb.fell_back and fb.data.dtype == np.float32
    assert np.array_equal(fb.decode(), x.astype(np.float32))
    # largest finite half values are fine
    ok = sto.encode_half(np.array([[65504.0, -65504.0, 65519.0]]))
    assert not ok.fell_back and np.all(np.isfinite(ok.decode()))


def test_half_relative_error():
    x = _stack() + 3.0
    enc = sto.encode_half(x)
    assert enc.nbytes == x.size * 2
    normal = np.abs(x) > 6.2e-5
    rel = np.abs(enc.decode() - x)[normal] / np.abs(x)[normal]
    assert rel.max() <= 2.0 ** -11 * (1 + 1e-6)


def test_pca_matches_eckart_young():
    x = _stack(1)
    X = x.reshape(12, -1)
    s = np.linalg.svd(X, compute_uv=False)  # independent SVD
    for k in (1, 4, 8, 12):
        enc = sto.encode_pca(x, k)
        assert enc.eigen_images.dtype == np.float32
        err = np.linalg.norm(enc.decode().reshape(12, -1) - X)
        assert np.isclose(err, np.sqrt(np.sum(s[k:] ** 2)), rtol=1e-3, atol=1e-4 * s[0])
        assert np.isclose(enc.captured_energy, np.sum(s[:k] ** 2) / np.sum(s ** 2))
    full = sto.encode_pca(x, 12).decode()
    assert sto.reconstruction_error(x, full)["rel_fro"] < 1e-6


def test_pca_steering_in_eigen_basis():
    x = _stack(2)
    enc = sto.encode_pca(x, 5)
    c = np.random.default_rng(3).normal(size=12)
    direct = np.tensordot(c, enc.decode().astype(np.float64), axes=1)
    via = np.tensordot(enc.project_coefficients(c), enc.eigen_images.astype(np.float64), axes=1)
    assert np.allclose(direct, via, atol=1e-5)


def test_pca_rank_deficient_stack():
    x = np.zeros((5, 4, 4))
    x[0] = 1.0
    enc = sto.encode_pca(x, 3)
    assert np.allclose(enc.decode(), x)


def test_codec_table_and_validation():
    x = _stack()
    rows = sto.codec_table(x, pca_ks=(2, 12, 99), steering=np.ones((2, 12)))
    names = [r["codec"] for r in rows]
    assert names == ["float32", "uint8", "uint8_per_channel", "half", "pca2", "pca12"]
    by = {r["codec"]: r for r in rows}
    assert by["half"]["rel_fro"] < by["uint8"]["rel_fro"] < by["pca2"]["rel_fro"]
    assert by["uint8"]["bytes_per_texel"] == pytest.approx(12 * 3 + 96 / 256)
    with pytest.raises(ValueError, match="NaN or inf"):
        sto.encode_uint8(np.array([[np.nan]]))
    with pytest.raises(ValueError, match="k must be"):
        sto.encode_pca(x, 0)


def test_uint8_refuses_values_beyond_float32_min_max():
    import pytest

    with pytest.raises(ValueError, match="float32 range"):
        sto.encode_uint8(np.array([[0.0, 1e39]]))
