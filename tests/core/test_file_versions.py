"""Every file a bake writes says its format and version, and a loader refuses a newer version
than it reads in one line naming the file (lt_addon/io/versions.py)."""

import json
import os

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.io import exrio, transaction as tr, versions
from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
from relightable_textures.lt_addon.transport import texture as tt


def _newer(meta):
    return {**meta, "format_version": versions.version_of(meta["format"]) + 1}


def _store(tmp_path):
    dset = parse_direction_spec("hemi:8")
    store = tt.TransportStore.create(str(tmp_path / "A_transport_texture.npy"), dset, 4)
    for s in range(dset.size):
        store.write(s, np.full((4, 4), 0.1 * s))
    store.finish().commit()
    return tmp_path / "A_transport_texture.npy"


def test_the_transport_store_is_versioned_and_a_newer_one_refused(tmp_path):
    path = _store(tmp_path)
    header_path = tmp_path / "A_transport_texture.json"
    header = json.loads(header_path.read_text())
    assert header["format_version"] == versions.version_of(tt.STORE_FORMAT)
    assert tt.TransportStore.open(str(path)).resolution == 4
    header_path.write_text(json.dumps(_newer(header)))
    with pytest.raises(InputError, match=r"A_transport_texture.npy: .*version 2 is newer than "
                                         r"this version of Relightable Textures reads \(1\)"):
        tt.TransportStore.open(str(path))


def test_the_model_file_is_versioned_and_a_newer_one_refused(tmp_path):
    path = str(tmp_path / "A_transport_model.npz")
    model = tt.TexturePCA(np.eye(8, 2), np.ones((2, 16), np.float32), 4, 0.0, np.ones(2))
    tt.save_model(path, model, "hemi:8")
    with np.load(path) as z:
        assert str(z["format"]) == tt.MODEL_FORMAT and int(z["format_version"]) == 1
        arrays = {k: z[k] for k in z.files}
    assert tt.load_model(path).k == 2
    arrays["format_version"] = np.array(2)
    np.savez(path, **arrays)
    with pytest.raises(InputError, match="A_transport_model.npz: .*version 2 is newer"):
        tt.load_model(path)


def test_every_exr_with_a_format_gets_its_version(tmp_path):
    path = str(tmp_path / "a.exr")
    exrio.write_exr(path, {"R": np.zeros((2, 2))}, {"format": "relightable_textures.albedo"})
    meta = exrio.read_exr(path)[1]
    assert meta == {"format": "relightable_textures.albedo", "format_version": 1}
    versions.check(meta, "relightable_textures.albedo", path)
    with pytest.raises(InputError, match="a.exr: .*newer"):
        versions.check(_newer(meta), "relightable_textures.albedo", path)
    with pytest.raises(InputError, match="is not an albedo file"):
        versions.check({"format": "other"}, "relightable_textures.albedo", path, "an albedo")


def test_a_journal_of_a_newer_version_is_left_alone(tmp_path):
    """A stage whose journal a newer version wrote is not interpreted (nor removed) here."""
    import subprocess
    import sys

    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True).stdout)
    from relightable_textures.lt_addon.io import atomic

    stage = tmp_path / f"{tr.STAGE_PREFIX}relight-{atomic._host()}-{dead}-00000000"
    stage.mkdir()
    (stage / ".journal.json").write_text(json.dumps(
        {"format": tr.FORMAT, "format_version": 99, "state": "swapping", "entries": ["x"]}))
    assert tr.sweep(str(tmp_path)) == {"removed": [], "rolled_back": [], "rolled_forward": []}
    assert stage.is_dir()
