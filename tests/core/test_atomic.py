"""The one atomic-write helper: whole new file or the old one, and no temporary file left."""

import json
import os

import numpy as np
import pytest

from relightable_textures.lt_addon.io import atomic


def _listing(folder):
    return sorted(os.listdir(folder))


def test_write_json_replaces_the_file_and_leaves_nothing_else(tmp_path):
    path = tmp_path / "report.json"
    path.write_text("old")
    n = atomic.write_json(path, {"a": 1, "b": [1.5, 2]})
    assert json.loads(path.read_text()) == {"a": 1, "b": [1.5, 2]}
    assert n == path.stat().st_size
    assert _listing(tmp_path) == ["report.json"]


def test_a_failing_body_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    path = tmp_path / "data.npz"
    path.write_bytes(b"old bytes")
    with pytest.raises(RuntimeError, match="cancelled"):
        with atomic.atomic_path(path) as tmp:
            np.savez(tmp, x=np.arange(3))      # half-way through a multi-file write ...
            assert os.path.exists(tmp)
            raise RuntimeError("cancelled")   # ... the user cancels
    assert path.read_bytes() == b"old bytes"
    assert _listing(tmp_path) == ["data.npz"]


def test_the_temporary_name_keeps_the_extension_for_writers_that_add_one(tmp_path):
    # np.savez appends ".npz" to a name without it, and OpenEXR / Blender choose the format by
    # the extension: the temporary file must end like the destination and sit next to it.
    path = tmp_path / "model.npz"
    with atomic.atomic_path(path) as tmp:
        assert tmp.endswith(".npz") and os.path.dirname(tmp) == str(tmp_path)
        assert os.path.basename(tmp).startswith(".")   # hidden while it is incomplete
        np.savez(tmp, x=np.arange(4.0))
    assert np.load(path)["x"].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert _listing(tmp_path) == ["model.npz"]


def test_writing_nothing_is_an_error_and_changes_nothing(tmp_path):
    path = tmp_path / "x.png"
    path.write_bytes(b"keep")
    with pytest.raises(FileNotFoundError, match="nothing was written"):
        with atomic.atomic_path(path):
            pass
    assert path.read_bytes() == b"keep" and _listing(tmp_path) == ["x.png"]


def test_data_that_cannot_be_encoded_changes_nothing(tmp_path):
    path = tmp_path / "r.json"
    path.write_text('{"old": true}')
    with pytest.raises(TypeError):
        atomic.write_json(path, {"array": np.zeros(2)})   # not JSON without default=
    assert json.loads(path.read_text()) == {"old": True} and _listing(tmp_path) == ["r.json"]
    atomic.write_json(path, {"v": np.float32(0.5)}, default=float)
    assert json.loads(path.read_text()) == {"v": 0.5}


def test_no_other_module_renames_files_itself():
    """One helper everywhere: no module of the product or the tooling calls os.replace /
    os.rename except atomic.py, the transport store's two-file commit and the bake transaction."""
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2]
    allowed = {"lt_addon/io/atomic.py", "lt_addon/transport/texture.py",
                   "lt_addon/io/transaction.py"}
    offenders = []
    for folder in ("lt_addon", "operators", "samples", "devtools", "benchmarks", "tools"):
        for p in (root / folder).rglob("*.py"):
            rel = str(p.relative_to(root))
            text = p.read_text()
            if rel not in allowed and ("os.replace(" in text or "os.rename(" in text):
                offenders.append(rel)
    assert offenders == []


def test_a_temporary_name_with_pid_0_is_no_process_of_ours(tmp_path):
    """Issue 56: pid 0 is no process's (``os.kill(0, 0)`` signals the caller's group), so a
    name carrying it was made by hand: never counted ours, never removed by a sweep."""
    from relightable_textures.lt_addon.io import transaction

    host = atomic._host()
    assert atomic.owner_of(f".A.relight-{host}-0-deadbeef.tmp.npy") is None
    assert atomic.owner_of(f".A.relight-{host}-12-deadbeef.tmp.npy") == (host, 12)
    names = [f".A.relight-{host}-0-deadbeef.tmp.npy", ".A.npy.0.tmp.npy",
             ".A_report.0-0badcafe.tmp.json"]
    for n in names:
        (tmp_path / n).write_bytes(b"someone's")
    assert transaction.sweep(str(tmp_path))["removed"] == []
    assert _listing(tmp_path) == sorted(names)
