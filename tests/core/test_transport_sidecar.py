"""The per-vertex transport sidecar, without Blender: what is saved is what is shaded."""

import numpy as np
import pytest

from relightable_textures.lt_addon.io import exrio
from relightable_textures.lt_addon.sphere import directions as D
from relightable_textures.lt_addon.transport import eigentransport as ET
from relightable_textures.lt_addon.transport.sidecar import (TransportData, read_environment_exr,
                                                             save_sidecar)


@pytest.fixture()
def saved(tmp_path):
    rng = np.random.default_rng(3)
    ds = D.cubemap(2)                                   # 24 directions over the sphere
    V, S = 40, ds.directions.shape[0]
    T = np.maximum(rng.normal(size=(V, 3)) @ rng.normal(size=(3, S)), 0.0)   # rank <= 3 + clip
    model = ET.fit_eigentransport(T, d=min(V, S))      # full rank: exact
    pos, nrm = rng.normal(size=(V, 3)), np.tile([0.0, 0.0, 1.0], (V, 1))
    path = tmp_path / "Obj_transport.npz"
    n = save_sidecar(str(path), model, ds, pos, nrm, {"object": "Obj", "bounces": 0})
    return path, n, T, ds, pos


def test_round_trip_shades_like_the_transport_it_was_fitted_to(saved):
    path, n, T, ds, pos = saved
    assert n == path.stat().st_size and [p.name for p in path.parent.iterdir()] == [path.name]
    data = TransportData(str(path))
    assert data.bake == {"object": "Obj", "bounces": 0}
    np.testing.assert_array_equal(data.direction_set.directions, ds.directions)
    np.testing.assert_allclose(data.positions, pos, rtol=0, atol=1e-6)   # stored as float32
    env = np.random.default_rng(4).uniform(0.2, 1.0, size=(8, 16, 3))   # equirect, bottom first
    Lw = ET.project_environment(env, ds.directions, ds.solid_angles, row_order="bottom_first")
    want = np.maximum(T @ Lw / np.pi, 0.0)              # brute force: B = T Lw / pi, never < 0
    got = data.shade(env)
    # float32 coefficients: relative error ~1e-6 of the largest value
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * want.max())
    # a rotation by 360 degrees is no rotation
    np.testing.assert_allclose(data.shade(env, rotate_deg=360.0), got, rtol=0, atol=1e-12)


def test_missing_sidecar_and_non_rgb_environment_are_clear_errors(tmp_path, saved):
    with pytest.raises(FileNotFoundError, match="transport sidecar not found"):
        TransportData(str(tmp_path / "nope.npz"))
    grey = tmp_path / "grey.exr"
    exrio.write_exr(str(grey), {"Y": np.ones((4, 8), np.float32)})
    with pytest.raises(ValueError, match="no R/G/B channel"):
        read_environment_exr(str(grey))


def test_samples_file_sits_next_to_its_sidecar():
    from relightable_textures.lt_addon.transport.sidecar import samples_path

    assert samples_path("/out/Statue_transport.npz") == "/out/Statue_transport_samples.npy"
    assert samples_path("/out/odd.npz") == "/out/odd_transport_samples.npy"
