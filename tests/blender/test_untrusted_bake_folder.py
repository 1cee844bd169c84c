"""A bake folder is untrusted input (issue 56), tested on real tiny bakes of the real CLI.

Someone who can write a bake folder (an asset pack, a colleague, a farm share) plants what a
killed run would leave: a stage with a journal, a chunk cache. The next ordinary
``relight bake-textures ... --force`` must never reach outside the folder through it:

(a) a planted commit stage (an old-style name, pid 0) whose journal names ``../victim.txt``:
    the file beside the folder stays byte for byte, the bake succeeds and says what it left;
(b) ``.relight_cache`` a symlink to a folder elsewhere: that folder and its contents stay, the
    bake refuses in one ``relight: error:`` line naming the link (exit 2); the panel's
    *Discard Kept Chunks* deletes nothing through it either;
(c) chunks with valid *unkeyed* SHA-256 checksums planted in the very folder the real cache
    key maps to: not reused (the checksum is an HMAC under this user's key), so the output
    equals an uninterrupted bake's.

Bakes: the test-size bumps at 16^2, 64 directions baked by Cycles calls (the direct stage keeps
chunks), draft preset, no truth lights: about 3-4 s each here.
"""

import json
import os
import pathlib
import shutil
import signal
import subprocess

import numpy as np
import pytest

from relightable_textures.lt_addon.io import chunk_cache
from relight_cli import BIN, make_scene, our_lines, relight


def _args(blend, out, seed=1):
    return ["bake-textures", str(blend), "--object", "Bumps", "--preset", "draft",
            "--directions", "hemi:64", "--resolution", "16", "--direct", "cycles",
            "--no-compare", "--seed", str(seed), "--out", str(out), "--force"]


def _tree(folder):
    """Every entry under ``folder`` (links not followed) with its bytes (None: a folder)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for d in dirs:
            out[os.path.relpath(os.path.join(root, d), folder)] = None
        for f in files:
            p = os.path.join(root, f)
            out[os.path.relpath(p, folder)] = pathlib.Path(p).read_bytes()
    return out


def _data(folder):
    """The bake's arrays and images (reports carry timings and paths)."""
    out = {}
    for p in sorted(pathlib.Path(folder).iterdir()):
        if p.is_file() and p.suffix == ".npy":
            out[p.name] = np.load(p)
        elif p.is_file() and p.suffix == ".npz":
            with np.load(p) as z:
                out.update({f"{p.name}:{k}": z[k] for k in z.files})
        elif p.is_file() and p.suffix in (".exr", ".png"):
            out[p.name] = p.read_bytes()
    return out


def _assert_same_data(a, b):
    assert sorted(a) == sorted(b)
    for name in a:
        if isinstance(a[name], np.ndarray):
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
        else:
            assert a[name] == b[name], name


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """One uninterrupted bake (seed 1) in ``bk/`` next to its .blend: the previous bake every
    test plants into a copy of, and the reference of (c)."""
    root = tmp_path_factory.mktemp("untrusted")
    blend = make_scene("bumps", root / "b.blend")
    r = relight(*_args(blend, root / "bk"))
    assert r.returncode == 0, r.stderr[-3000:]
    return root


@pytest.fixture
def scene(baked, tmp_path):
    """A copy of the bake and its .blend (same layout: the .blend's records stay valid)."""
    shutil.copyfile(baked / "b.blend", tmp_path / "b.blend")
    shutil.copytree(baked / "bk", tmp_path / "bk")
    return tmp_path / "b.blend", tmp_path / "bk"


def test_a_planted_stage_never_replaces_a_file_beside_the_folder(scene, tmp_path):
    """The issue's report: ``bk/.relight-stage-x.0-deadbeef.tmp/`` with a journal in state
    ``swapping`` naming ``../victim.txt`` replaced ``victim.txt`` beside ``bk/``."""
    blend, bk = scene
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"the user's file beside the bake folder\n")
    stage = bk / ".relight-stage-x.0-deadbeef.tmp"
    (stage / ".old").mkdir(parents=True)
    (stage / ".journal.json").write_text(json.dumps({
        "format": "relightable_textures.commit_journal", "format_version": 1,
        "state": "swapping", "target": str(tmp_path), "entries": ["../victim.txt"],
        "retired": [], "blend": None, "blend_before": None,
        "blend_tmp": str(tmp_path / "b.blend"), "existed": ["../victim.txt"]}))
    (stage / "victim.txt").write_bytes(b"planted\n")          # what stage/.old/../victim.txt is
    r = relight(*_args(blend, bk))
    assert r.returncode == 0, r.stderr[-3000:]
    assert victim.read_bytes() == b"the user's file beside the bake folder\n"
    assert blend.exists() and (bk / "Bumps_transport_texture.npy").exists()
    assert (stage / ".journal.json").exists()                  # left alone, and said so
    said = [ln for ln in our_lines(r.stderr) if "left alone" in ln]
    assert len(said) == 1 and stage.name in said[0], r.stderr[-3000:]


def _elsewhere(tmp_path):
    """A folder outside the bake folder with a key-like folder holding a file, and an empty
    folder: what the old bake's prune removed through a symlinked cache."""
    ext = tmp_path / "elsewhere"
    (ext / "0123456789abcdef0123").mkdir(parents=True)
    (ext / "0123456789abcdef0123" / "direct_00000.npy").write_bytes(b"someone's data")
    (ext / "Bumps" / "fedcba9876543210fedc").mkdir(parents=True)
    (ext / "Bumps" / "fedcba9876543210fedc" / "direct_00016.npy").write_bytes(b"more data")
    (ext / "empty").mkdir()
    return ext, _tree(ext)


def test_a_symlinked_chunk_cache_is_refused_in_one_line_and_nothing_outside_goes(
        scene, tmp_path):
    blend, bk = scene
    ext, before = _elsewhere(tmp_path)
    os.symlink(ext, bk / ".relight_cache")
    files = {p.name: p.read_bytes() for p in bk.iterdir() if p.is_file()}
    r = relight(*_args(blend, bk))
    assert r.returncode == 2, r.stderr[-3000:]
    ours = [ln for ln in our_lines(r.stderr) if ln.startswith("relight: ")]
    assert len(ours) == 1 and ours[0].startswith("relight: error: "), r.stderr[-3000:]
    assert str(bk / ".relight_cache") in ours[0] and "symbolic link" in ours[0]
    assert "remove it" in ours[0] and "Traceback" not in r.stderr
    assert _tree(ext) == before                               # every file and folder there
    assert os.path.islink(bk / ".relight_cache")
    assert {p.name: p.read_bytes() for p in bk.iterdir() if p.is_file()} == files


def test_discard_kept_chunks_deletes_nothing_through_a_symlinked_cache(fresh_scene, tmp_path):
    """The panel's *Discard Kept Chunks* (in process) on a folder whose ``.relight_cache`` is a
    link to a folder holding ``Bumps/<key>/direct_00016.npy``: an error line, nothing gone."""
    import bpy

    import relightable_textures
    from relightable_textures import samples

    samples.build("bumps", fresh_scene, "test")
    ext, before = _elsewhere(tmp_path)
    (tmp_path / "bk").mkdir()
    os.symlink(ext, tmp_path / "bk" / ".relight_cache")
    relightable_textures.register()
    try:
        fresh_scene.relight.output_dir = str(tmp_path / "bk") + os.sep
        bpy.context.view_layer.objects.active = bpy.data.objects["Bumps"]
        with pytest.raises(RuntimeError, match="symbolic link"):
            bpy.ops.relight.discard_chunks()
    finally:
        relightable_textures.unregister()
    assert _tree(ext) == before


def test_planted_chunks_with_valid_unkeyed_checksums_are_not_reused(scene, baked, tmp_path):
    """A kill after the first chunk leaves the real key's folder; every chunk in it is then
    replaced by other values with a valid SHA-256 of shape, dtype and bytes (what anyone can
    compute). The next run rejects them all, bakes them again, and its output equals the
    uninterrupted bake's."""
    blend, _ = scene
    out = tmp_path / "bk2"
    env = dict(os.environ, RELIGHT_FAULT="directions:kill")
    r = subprocess.run([str(BIN / "relight"), *_args(blend, out)], capture_output=True,
                       text=True, timeout=600, env=env)
    assert r.returncode == -signal.SIGKILL, r.stderr[-3000:]
    chunks = sorted(out.glob(".relight_cache/Bumps/*/direct_*.npy"))
    assert chunks, sorted(p.name for p in out.rglob("*"))
    for p in chunks:
        real = np.load(p)
        planted = np.full_like(real, 0.5)
        np.save(p, planted)
        p.with_name(p.name + ".sha256").write_text(chunk_cache.checksum(planted) + "\n")
    r = relight(*_args(blend, out))
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads((out / "Bumps_texture_report.json").read_text())
    assert rep["chunks_reused"] == 0 and rep["chunks_rejected"] == len(chunks)
    _assert_same_data(_data(out), _data(baked / "bk"))


def test_a_report_naming_another_folder_for_its_indirect_term_writes_nothing_there(tmp_path):
    """``files.indirect`` of a report from elsewhere named where the preview writes the steerable
    term's atlas (``<that path>_atlas.exr``): a report edited to name a folder outside wrote
    there when the panel loaded the bake. Now the atlas goes beside the indirect file the bake
    folder holds (its basename), and the folder named stays untouched. In process, as the
    panel's *Load* does (operators/ui/bake_ops.py: load_bake + install_transport_preview)."""
    import bpy

    from relightable_textures.operators.bakes import texture_transport as tx

    blend = make_scene("bumps", tmp_path / "b.blend")
    bk = tmp_path / "bk"
    r = relight("bake-textures", blend, "--object", "Bumps", "--preset", "draft", "--directions",
                "hemi:16", "--resolution", "16", "--indirect", "steerable", "--no-compare",
                "--truth", "0", "--out", bk, "--force")
    assert r.returncode == 0, r.stderr[-3000:]
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim.txt").write_bytes(b"mine")
    report_path = bk / "Bumps_texture_report.json"
    report = json.loads(report_path.read_text())
    name = os.path.basename(report["files"]["indirect"])
    assert name.endswith(".exr")   # the steerable term: its atlas is written beside it
    report["files"]["indirect"] = str(outside / name)
    report_path.write_text(json.dumps(report))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    bake, store, rep = tx.load_bake(str(report_path))
    tx.install_transport_preview(bpy.context.scene, bpy.data.objects["Bumps"], rep, bake, store)
    assert sorted(p.name for p in outside.iterdir()) == ["victim.txt"]
    assert (bk / (os.path.splitext(name)[0] + "_atlas.exr")).is_file()
