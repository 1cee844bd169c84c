"""One bake, one transaction, tested with real faults on real bakes (issue 34).

A good bake (seed 1) is in ``bk/``; a second bake into the same folder (``--force --seed 7``)
is killed (a real SIGKILL) or fails at each stage. Afterwards the previous bake's files and the
``.blend`` are byte-identical, the failure is one line with exit code 2, and the next run leaves
no debris and gives bit for bit what an uninterrupted bake gives. The stages are reached through
``RELIGHT_FAULT`` (:mod:`lt_addon.faults`); disk full is a real ``RLIMIT_FSIZE``, a path in the
way a real folder, a bad chunk a real file.

Bakes: the test-size bumps at 16^2, 64 directions baked by Cycles calls (so the direct stage
keeps chunks), bounces on (an indirect stage), one held-out truth light, PCA and the preview:
every stage a default bake has, about 4 s per run here (2026-12-02).
"""

import json
import os
import pathlib
import re
import shutil
import signal
import subprocess
import time

import numpy as np
import pytest

from relightable_textures.lt_addon.io import transaction as tr
from relight_cli import BIN, make_scene, our_lines, relight

STAGES = ("directions", "indirect", "fit", "write", "preview", "commit", "blend")


def _args(blend, out, seed):
    return ["bake-textures", str(blend), "--object", "Bumps", "--preset", "draft",
            "--directions", "hemi:64", "--resolution", "16", "--direct", "cycles",
            "--truth", "1", "--truth-samples", "16", "--no-compare", "--seed", str(seed),
            "--out", str(out), "--force"]


#: what a committed bake holds that must not change between runs of the same seed (reports and
#: the preview's metadata carry timings and paths)
_DATA = (".npy", ".npz", ".exr", ".png")


def _files(folder):
    """The bake's files (the chunk cache is resume state, not the bake) with their bytes."""
    folder = pathlib.Path(folder)
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def _data(folder):
    out = {}
    for name, raw in _files(folder).items():
        if name.endswith(".npz"):
            with np.load(pathlib.Path(folder) / name) as z:
                out[name] = {k: z[k] for k in z.files}
        elif name.endswith(".npy"):
            out[name] = np.load(pathlib.Path(folder) / name)
        elif name.endswith(_DATA):
            out[name] = raw
    return out


def _assert_same_data(a, b):
    assert sorted(a) == sorted(b)
    for name in a:
        if isinstance(a[name], dict):
            for k in a[name]:
                np.testing.assert_array_equal(a[name][k], b[name][k], err_msg=f"{name}:{k}")
        elif isinstance(a[name], np.ndarray):
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
        else:
            assert a[name] == b[name], name


_DEBRIS = re.compile(r"relight-.+-\d+-[0-9a-f]{8}|\.relight-stage-|\.tmp\b")


def _debris(folder):
    """Every name under ``folder`` that is a temporary of ours, and an empty chunk cache."""
    found = []
    for root, dirs, files in os.walk(folder):
        found += [n for n in dirs + files if _DEBRIS.search(n)]
    cache = pathlib.Path(folder) / ".relight_cache"
    if cache.exists() and not any(p.is_file() for p in cache.rglob("*")):
        found.append(".relight_cache (empty)")
    return found


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """The previous bake (seed 1) in ``bk/`` next to its .blend, and the reference: an
    uninterrupted bake of seed 7 of the same .blend in another folder."""
    root = tmp_path_factory.mktemp("faults")
    blend = make_scene("bumps", root / "b.blend")
    r = relight(*_args(blend, root / "bk", 1))
    assert r.returncode == 0, r.stderr[-3000:]
    ref_blend = root / "ref.blend"
    shutil.copyfile(blend, ref_blend)
    r = relight(*_args(ref_blend, root / "ref", 7))
    assert r.returncode == 0, r.stderr[-3000:]
    assert not _debris(root / "bk") and not _debris(root / "ref")
    return root


@pytest.fixture
def scene(baked, tmp_path):
    """A fresh copy of the previous bake and its .blend; returns (blend, bk, before)."""
    blend = tmp_path / "b.blend"
    shutil.copyfile(baked / "b.blend", blend)
    shutil.copytree(baked / "bk", tmp_path / "bk")
    # the .blend records the bake's paths relative to itself: same layout, same records
    return blend, tmp_path / "bk", (_files(tmp_path / "bk"), blend.read_bytes())


def _run(blend, out, fault=None, seed=7, **kw):
    env = {k: v for k, v in os.environ.items() if k != "RELIGHT_FAULT"}
    if fault:
        env["RELIGHT_FAULT"] = fault
    return subprocess.run([str(BIN / "relight"), *_args(blend, out, seed)], capture_output=True,
                          text=True, timeout=600, env=env, **kw)


def _assert_one_line(r, *needles):
    assert r.returncode == 2, r.stderr[-3000:]
    ours = [ln for ln in our_lines(r.stderr) if ln.startswith("relight: ")]
    assert len(ours) == 1 and ours[0].startswith("relight: error: "), r.stderr[-3000:]
    assert "Traceback" not in r.stderr
    for n in needles:
        assert n in ours[0], ours[0]
    log = re.search(r"\(details: (.+\.log)\)", ours[0])
    assert log and "Traceback" in pathlib.Path(log.group(1)).read_text()
    return ours[0]


@pytest.mark.parametrize("stage", STAGES)
def test_a_kill_at_any_stage_keeps_the_previous_bake_and_the_next_run_resumes_bit_for_bit(
        scene, baked, stage):
    blend, bk, (files, blend_bytes) = scene
    r = _run(blend, bk, f"{stage}:kill")
    assert r.returncode == -signal.SIGKILL, r.stderr[-3000:]
    if stage == "commit":   # killed between two renames of the swap: the journal says what to
        assert len(tr.sweep(str(bk))["rolled_back"]) == 1   # undo, the next run's sweep does it
    assert _files(bk) == files                  # every file of the previous bake, byte for byte
    assert blend.read_bytes() == blend_bytes    # and the .blend
    r = _run(blend, bk)
    assert r.returncode == 0, r.stderr[-3000:]
    assert _debris(bk) == []
    _assert_same_data(_data(bk), _data(baked / "ref"))
    rep = json.loads((bk / "Bumps_texture_report.json").read_text())
    assert rep["files"]["transport"] == str(bk / "Bumps_transport_texture.npy")
    if stage == "directions":   # killed after its first chunk: the rerun reused it
        assert rep["chunks_reused"] >= 1


@pytest.mark.parametrize("stage", STAGES)
def test_a_failure_at_any_stage_is_one_line_and_changes_nothing(scene, stage):
    blend, bk, (files, blend_bytes) = scene
    r = _run(blend, bk, f"{stage}:raise")
    _assert_one_line(r, f"injected fault at the {stage} stage", f"nothing was replaced in {bk}")
    assert _files(bk) == files and blend.read_bytes() == blend_bytes
    assert _debris(bk) == []


@pytest.mark.parametrize("stage", ["preview", "blend"])
def test_ctrl_c_after_the_last_step_cancels_instead_of_committing(scene, stage):
    """A Ctrl-C (a real SIGINT) that lands after the bake's last progress step (``preview``)
    or while the new .blend is being saved aside (``blend``, before the first rename) cancels:
    exit 130, nothing replaced. (Before issue 56 both committed with exit 0.)"""
    blend, bk, (files, blend_bytes) = scene
    r = _run(blend, bk, f"{stage}:sigint")
    assert r.returncode == 130, (r.returncode, r.stderr[-3000:])
    assert "cancelled" in r.stderr and "Traceback" not in r.stderr
    assert _files(bk) == files and blend.read_bytes() == blend_bytes
    assert _debris(bk) == []


def test_a_full_disk_is_one_line_and_changes_nothing(scene):
    """RLIMIT_FSIZE below the size of T (64 x 256 half floats, 32 KiB): writing the store fails
    with EFBIG, as on a full disk (SIGXFSZ ignored, as a shell's ulimit -f leaves it)."""
    import resource

    blend, bk, (files, blend_bytes) = scene

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (24 * 1024, 24 * 1024))

    r = _run(blend, bk, preexec_fn=limit)
    _assert_one_line(r, "larger than this system allows", f"nothing was replaced in {bk}")
    assert _files(bk) == files and blend.read_bytes() == blend_bytes
    assert _debris(bk) == []


def test_a_full_disk_inside_an_npz_write_is_one_line_without_a_second_traceback(scene):
    """RLIMIT_FSIZE at 200 KiB: T (32 KiB) and the chunks fit, the gathered indirect term's NPZ
    (~390 KiB) does not. np.savez left its ZipFile open, and the garbage collector's
    ``ZipFile.__del__`` then printed ``Exception ignored`` with a traceback after the one line
    (issue 56); io.npz.save_npz closes it on every path."""
    import resource

    blend, bk, (files, blend_bytes) = scene

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (200 * 1024, 200 * 1024))

    r = _run(blend, bk, preexec_fn=limit)
    _assert_one_line(r, "larger than this system allows", "Bumps_indirect.npz")
    assert "Exception ignored" not in r.stderr
    assert _files(bk) == files and blend.read_bytes() == blend_bytes
    assert _debris(bk) == []


def test_permission_denied_is_one_line_and_changes_nothing(scene):
    """A folder the bake cannot write. Root is not stopped by permissions, so there the
    same error is injected where the bake writes its first file (EACCES, as the OS raises it)."""
    blend, bk, (files, blend_bytes) = scene
    if os.geteuid() != 0:
        os.chmod(bk, 0o555)
        try:
            r = _run(blend, bk)
        finally:
            os.chmod(bk, 0o755)
        assert r.returncode == 2 and "not writable" in our_lines(r.stderr)[-1]
    r = _run(blend, bk, "write:eacces")
    _assert_one_line(r, "permission denied: ", str(bk / "Bumps_albedo.exr"))
    assert _files(bk) == files and blend.read_bytes() == blend_bytes
    assert _debris(bk) == []


def test_a_folder_in_the_way_of_a_file_is_one_line_and_changes_nothing(scene):
    blend, bk, (files, blend_bytes) = scene
    (bk / "Bumps_texture_report.json").unlink()
    (bk / "Bumps_texture_report.json").mkdir()
    (bk / "Bumps_texture_report.json" / "the user's.txt").write_text("keep me")
    files = _files(bk)
    r = _run(blend, bk)
    _assert_one_line(r, "a folder is in the way where a file goes: "
                        f"{bk / 'Bumps_texture_report.json'}")
    assert _files(bk) == files and blend.read_bytes() == blend_bytes
    assert (bk / "Bumps_texture_report.json" / "the user's.txt").read_text() == "keep me"
    assert _debris(bk) == []


@pytest.mark.parametrize("damage", ["nan", "truncated"])
def test_a_bad_chunk_is_baked_again_and_counted(scene, baked, damage):
    """A kill after the first chunk keeps it; the chunk is then damaged: NaN values in a valid
    .npy (a faulty worker or disk), or cut short. The next run refuses it, bakes it again,
    counts it in the report, and its result equals the uninterrupted bake's."""
    blend, bk, _ = scene
    assert _run(blend, bk, "directions:kill").returncode == -signal.SIGKILL
    chunks = list(bk.glob(".relight_cache/Bumps/*/direct_00000.npy"))
    assert len(chunks) == 1
    if damage == "nan":
        arr = np.load(chunks[0])
        arr[0, 0, :7] = np.nan
        np.save(chunks[0], arr)
    else:
        data = chunks[0].read_bytes()
        chunks[0].write_bytes(data[: len(data) // 2])
    r = _run(blend, bk)
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads((bk / "Bumps_texture_report.json").read_text())
    assert rep["chunks_rejected"] == 1 and rep["chunks_reused"] == 0
    _assert_same_data(_data(bk), _data(baked / "ref"))
    assert _debris(bk) == []


def test_a_blend_saved_by_someone_else_meanwhile_is_not_overwritten(scene):
    blend, bk, (files, _) = scene
    proc = subprocess.Popen([str(BIN / "relight"), *_args(blend, bk, 7)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(bk.glob(".relight-stage-*")):
        time.sleep(0.01)
    other = blend.with_name("other.blend")
    other.write_bytes(blend.read_bytes() + b"\0")   # another program saves the file
    os.replace(other, blend)
    saved = blend.read_bytes()
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, err[-3000:]
    line = [ln for ln in our_lines(err) if ln.startswith("relight: ")]
    assert len(line) == 1 and "changed while the bake ran" in line[0], err[-3000:]
    assert _files(bk) == files and blend.read_bytes() == saved
    assert _debris(bk) == []


#: the other bakes, at their smallest: (scene, the command's arguments after FILE, its files)
OTHER_BAKES = {
    "vertex": ("statue", ["bake-transport", "--object", "Statue", "--directions", "cube:2"],
               ("Statue_transport.npz", "Statue_transport.json")),
    "lobes": ("statue", ["bake-textures", "--object", "Statue", "--method", "lobes", "--order",
                         "2", "--resolution", "8", "--samples", "2", "--no-compare"],
              ("Statue_steerable.exr", "Statue_steerable.json")),
    "materials": ("room", ["bake-materials", "--object", "Floor", "--object", "WallLeft",
                           "--region", "RedMaterial", "--directions", "hemi:4",
                           "--one-bounce-directions", "hemi:4", "--two-bounce-directions",
                           "hemi:4", "--samples", "4"],
                  ("Floor_materials.npz", "Floor_materials.json")),
}


@pytest.mark.parametrize("kind", sorted(OTHER_BAKES))
@pytest.mark.parametrize("stage", ["commit", "blend"])
def test_every_bake_commits_as_a_unit(tmp_path, kind, stage):
    """The per-vertex, lobes and material bakes go through the same transaction: killed in
    the middle of the swap or before the .blend is saved, the previous bake and the .blend are
    as they were; the next run rolls the half-commit back, bakes, and leaves no debris."""
    name, args, expected = OTHER_BAKES[kind]
    blend = make_scene(name, tmp_path / f"{name}.blend")
    out = tmp_path / "out"
    cmd = [args[0], str(blend), *args[1:], "--out", str(out), "--force"]
    r = relight(*cmd)
    assert r.returncode == 0, r.stderr[-3000:]
    assert set(expected) <= set(os.listdir(out))
    files, blend_bytes = _files(out), blend.read_bytes()
    env = dict(os.environ, RELIGHT_FAULT=f"{stage}:kill")
    r = subprocess.run([str(BIN / "relight"), *cmd], capture_output=True, text=True,
                       timeout=600, env=env)
    assert r.returncode == -signal.SIGKILL, r.stderr[-3000:]
    if stage == "commit":   # killed between two renames: the journal says what to undo
        assert len(tr.sweep(str(out))["rolled_back"]) == 1
    assert _files(out) == files and blend.read_bytes() == blend_bytes
    r = relight(*cmd)
    assert r.returncode == 0, r.stderr[-3000:]
    if stage == "blend":    # the stage and the half-saved .blend of the killed run go
        assert "removed 2 temporary file(s) of killed runs" in r.stderr, r.stderr[-2000:]
    assert blend.read_bytes() != blend_bytes and _debris(blend.parent) == []
    assert _debris(out) == [] and set(expected) <= set(os.listdir(out))


@pytest.mark.parametrize("stage", ["write", "preview", "commit"])
def test_the_panel_reports_a_failed_bake_in_one_line_and_keeps_the_previous(
        fresh_scene, tmp_path, monkeypatch, stage):
    """The panel's Bake (bpy.ops, in process) failing while writing, after installing its
    preview, or at the commit's check (a folder where the report goes): one error line with
    the log, the folder byte for byte as before, no debris, and the object's bake record and
    preview images back on the previous bake's files."""
    import bpy

    import relightable_textures
    from relightable_textures import samples
    from relightable_textures.operators.base.blend_files import object_bakes

    samples.build("bumps", fresh_scene, "test")
    obj = bpy.data.objects["Bumps"]
    relightable_textures.register()
    try:
        props = fresh_scene.relight
        props.preset = "draft"
        props.directions, props.resolution, props.indirect_samples = 24, 16, 4
        props.truth_lights, props.device = 0, "cpu"
        props.output_dir = str(tmp_path / "bk") + os.sep
        for o in fresh_scene.objects:
            o.select_set(o == obj)
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.relight.bake_textures() == {"FINISHED"}
        record = object_bakes(obj)
        if stage == "commit":
            (tmp_path / "bk" / "Bumps_texture_report.json").unlink()
            (tmp_path / "bk" / "Bumps_texture_report.json").mkdir()
            want = "Bake failed: a folder is in the way where a file goes"
        else:
            monkeypatch.setenv("RELIGHT_FAULT", f"{stage}:raise")
            want = f"Bake failed: injected fault at the {stage} stage"
        files = _files(tmp_path / "bk")
        with pytest.raises(RuntimeError) as err:
            bpy.ops.relight.bake_textures()
        line = str(err.value).strip().splitlines()[-1]
        assert want in line, line
        assert f"nothing was replaced in {tmp_path / 'bk'}" in line and "(details: " in line
        assert _files(tmp_path / "bk") == files and _debris(tmp_path / "bk") == []
        assert object_bakes(obj) == record
        stale = [im.filepath for im in bpy.data.images if tr.STAGE_PREFIX in im.filepath]
        assert stale == []
    finally:
        relightable_textures.unregister()


def unversioned(folder) -> list:
    """Files of a bake in ``folder`` that do not say their format version: JSON documents by
    ``format_version``, EXRs in their metadata, NPZs in an array or their header; an NPY or
    PNG (no room for metadata) counts when a versioned JSON of the bake names it."""
    from relightable_textures.lt_addon.io import exrio

    folder = pathlib.Path(folder)
    docs = {}
    for p in folder.glob("*.json"):
        docs[p.name] = json.loads(p.read_text())
    named = " ".join(json.dumps(d) for d in docs.values() if "format_version" in d)
    bad = []
    for p in sorted(folder.iterdir()):
        if not p.is_file():
            continue
        if p.suffix == ".json":
            ok = "format_version" in docs[p.name]
        elif p.suffix == ".exr":
            ok = "format_version" in exrio.read_exr(str(p))[1]
        elif p.suffix == ".npz":
            with np.load(p) as z:
                ok = "format_version" in z.files or (
                    "header" in z.files and "version" in json.loads(bytes(z["header"]).decode())) \
                    or ("metadata" in z.files and "format_version" in str(z["metadata"]))
        else:
            ok = p.name in named
        if not ok:
            bad.append(p.name)
    return bad


def test_every_file_of_every_bake_says_its_format_version(baked, tmp_path):
    assert unversioned(baked / "bk") == []
    for kind, (name, args, expected) in OTHER_BAKES.items():
        blend = make_scene(name, tmp_path / f"{name}.blend")
        r = relight(args[0], str(blend), *args[1:], "--out", str(tmp_path / kind))
        assert r.returncode == 0, r.stderr[-3000:]
        assert unversioned(tmp_path / kind) == [], kind
