"""A transport-texture bundle is written, read back and relit from plain Python (no bpy): the
format of lt_addon/transport/bundle.py, checked against the sum it stands for.

The relit radiance of a point sun at a baked direction ``s`` is ``albedo * T[s]`` exactly (the
linear kernel puts all its weight on ``s``); between directions it is ``albedo * sum_i w_i
T[i]`` with :func:`sun_weights`' weights, computed here by hand from the array. T is stored as
float16, so the tolerance is float16's relative step (2^-11 ~ 4.9e-4) on values <= 1."""

import json

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.sphere.directions import hemisphere_fibonacci
from relightable_textures.lt_addon.transport import bundle, texture as tt

R, S = 8, 40
HALF = 2.0 ** -11


def _bundle(tmp_path, model="none"):
    dset = hemisphere_fibonacci(S, 1.5)
    rng = np.random.default_rng(3)
    T = rng.uniform(0.0, 1.0 / np.pi, size=(S, R, R)).astype(np.float32)   # direct: <= 1/pi
    store = tt.TransportStore.create(str(tmp_path / "Patch_transport.npy"), dset, R)
    for s in range(S):
        store.write(s, T[s])
    store = store.finish()          # a reader of the still-temporary store, as a bake has
    albedo = rng.uniform(0.1, 0.9, size=(R, R, 3)).astype(np.float32)
    settings = bundle.TransportTextureSettings(directions=f"hemi:{S}:1.5", resolution=R,
                                               bounces=0, model=model, sun_angle=2.0)
    fitted = bundle.fit_model(store, settings, albedo)
    ob = bundle.ObjectBake("Patch", store.path, albedo, None, fitted, 0.0, store)
    result = bundle.TransportTextureResult([ob], dset, settings, {"bake_total": 1.0}, S)
    (report,) = bundle.write_bundle(result, ["Patch"], str(tmp_path), device={"device": "CPU"},
                                    version="test")
    return report, T, albedo, dset


def test_a_bundle_reads_back_and_relights_as_its_sum(tmp_path):
    report, T, albedo, dset = _bundle(tmp_path)
    assert report["kind"] == bundle.KIND and report["format"] == bundle.FORMAT
    bake, store, rep = bundle.load_bake(report["report"])
    assert rep["object"] == "Patch" and rep["objects_baked_together"] == ["Patch"]
    np.testing.assert_allclose(bake.albedo, albedo, rtol=HALF, atol=HALF)   # a half EXR
    for s in (0, 17, 39):                       # a baked direction: exactly that image
        got = bundle.relight(bake, store, dset.directions[s])
        np.testing.assert_allclose(got, bake.albedo * T[s][..., None], rtol=2 * HALF,
                                   atol=2 * HALF)
    d = np.array([0.3, -0.2, 0.93])
    d /= np.linalg.norm(d)
    idx, w = tt.sun_weights(dset, d, 2.0, "linear")
    want = bake.albedo * np.tensordot(w, T[idx], axes=1)[..., None]
    got = bundle.relight(bake, store, d, sun_angle=2.0)
    np.testing.assert_allclose(got, want, rtol=2 * HALF, atol=2 * HALF)


def test_the_pca_model_of_a_bundle_relights_within_its_tolerance(tmp_path):
    report, T, _, dset = _bundle(tmp_path, model="pca")
    bake, store, _ = bundle.load_bake(report["report"])
    d = dset.directions[5]
    full = bundle.relight(bake, store, d, source="transport")
    model = bundle.relight(bake, store, d, source="model")
    # tol 0.02 is the PCA's residual of all of T; one light's error is within a few times it
    assert bundle.rel_rmse(model, full) < 0.1


def test_a_newer_bundle_and_another_kind_are_refused_in_one_line(tmp_path):
    report, *_ = _bundle(tmp_path)
    path = report["report"]
    data = json.loads(open(path).read())
    data["format"] = bundle.FORMAT + 1
    open(path, "w").write(json.dumps(data))
    with pytest.raises(InputError, match="newer than this version reads"):
        bundle.load_bake(path)
    data["format"], data["kind"] = bundle.FORMAT, "material_tensors"
    open(path, "w").write(json.dumps(data))
    with pytest.raises(InputError, match="not a transport texture bake"):
        bundle.load_bake(path)


def test_one_entry_point_reads_every_kind_of_bake(tmp_path):
    """lt_addon/bundles.load_bake: a transport report, a steerable texture (its basis images
    back as written, float storage) and a per-vertex sidecar each come back as the object that
    relights them; another file, or none, is refused in one line."""
    from relightable_textures.lt_addon import bundles
    from relightable_textures.lt_addon.sphere import directions as D
    from relightable_textures.lt_addon.steerable.texture import (SteerableTexture,
                                                                 build_from_sampled_bakes)
    from relightable_textures.lt_addon.transport import eigentransport as ET
    from relightable_textures.lt_addon.transport.sidecar import TransportData, save_sidecar

    report, T, _, dset = _bundle(tmp_path)
    bake, store, rep = bundles.load_bake(report["report"])
    assert rep["object"] == "Patch" and store.directions.size == S

    rng = np.random.default_rng(0)
    stack = rng.uniform(0.0, 1.0, size=(25, 6, 6, 3)).astype(np.float32)
    tex = build_from_sampled_bakes(stack, order=5, frame="tangent")
    tex.save(str(tmp_path / "P_steerable.exr"), "float")
    back = bundles.load_bake(str(tmp_path / "P_steerable.exr"))
    assert isinstance(back, SteerableTexture)
    np.testing.assert_allclose(back.basis_images, tex.basis_images, rtol=1e-6, atol=1e-6)

    ds = D.cubemap(2)
    Tv = np.maximum(rng.normal(size=(40, 3)) @ rng.normal(size=(3, ds.directions.shape[0])), 0)
    model = ET.fit_eigentransport(Tv, d=24)
    save_sidecar(str(tmp_path / "O_transport.npz"), model, ds, rng.normal(size=(40, 3)),
                 np.tile([0.0, 0.0, 1.0], (40, 1)), {"object": "O", "bounces": 0})
    assert isinstance(bundles.load_bake(str(tmp_path / "O_transport.npz")), TransportData)

    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match="not a bake file"):
        bundles.load_bake(str(tmp_path / "notes.txt"))
    with pytest.raises(InputError, match="no bake file"):
        bundles.load_bake(str(tmp_path / "missing.exr"))
