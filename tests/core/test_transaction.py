"""One bake, one transaction (lt_addon/io/transaction.py): staged, checked, swapped whole; a
kill at any instant (a real SIGKILL of a child process) is finished or undone by the next
run's sweep, which removes only this tool's debris of processes that are gone."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from relightable_textures.lt_addon.io import atomic, transaction as tr


def _state(folder):
    """Every entry of ``folder`` (recursively) with its bytes."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for f in files:
            p = os.path.join(root, f)
            out[os.path.relpath(p, folder)] = open(p, "rb").read()
    return out


def _previous_bake(folder):
    folder.mkdir(exist_ok=True)
    (folder / "A_report.json").write_text(json.dumps({"files": {"t": str(folder / "A_t.npy")}}))
    np.save(folder / "A_t.npy", np.arange(6.0))
    (folder / "A_preview_old.png").write_bytes(b"\x89PNG\r\n\x1a\nold")
    (folder / "notes.txt").write_text("the user's own file")
    return _state(folder)


def _new_bake(stage):
    np.save(os.path.join(stage, "A_t.npy"), np.arange(6.0) * 2)
    atomic.write_json(os.path.join(stage, "A_report.json"),
                      {"files": {"t": os.path.join(stage, "A_t.npy")}})


def test_a_commit_swaps_the_set_whole_and_retires_what_the_new_bake_does_not_write(tmp_path):
    out = tmp_path / "bk"
    _previous_bake(out)
    with tr.BakeTransaction(str(out), retire=["A_preview_*"]) as txn:
        _new_bake(txn.stage)
        assert sorted(os.listdir(out))[0].startswith(tr.STAGE_PREFIX)
        assert txn.commit() == ["A_report.json", "A_t.npy"]
    assert sorted(os.listdir(out)) == ["A_report.json", "A_t.npy", "notes.txt"]
    np.testing.assert_array_equal(np.load(out / "A_t.npy"), np.arange(6.0) * 2)
    # the report's paths point where the files are now, not into the stage
    assert json.loads((out / "A_report.json").read_text())["files"]["t"] == str(out / "A_t.npy")


@pytest.mark.parametrize("where", ["bake", "check", "after-swap"])
def test_a_failure_anywhere_leaves_the_previous_bake_byte_for_byte(tmp_path, where):
    out = tmp_path / "bk"
    before = _previous_bake(out)
    with pytest.raises((RuntimeError, ValueError)):
        with tr.BakeTransaction(str(out), retire=["A_preview_*"]) as txn:
            _new_bake(txn.stage)
            if where == "bake":
                raise RuntimeError("the bake failed")
            if where == "check":   # a truncated array: caught before anything moves
                with open(txn.path("A_t.npy"), "r+b") as fh:
                    fh.truncate(100)
                with pytest.raises(ValueError, match="A_t.npy is truncated"):
                    txn.commit()
                raise RuntimeError("the check refused it")
            txn.commit()
            raise RuntimeError("the .blend could not be saved")   # after the swap
    assert _state(out) == before


def _child(out, blend, fault, body="", retire="[]"):
    """Run a transaction in a child process with RELIGHT_FAULT=``fault``: a real SIGKILL."""
    code = textwrap.dedent(f"""
        import os, numpy as np
        from relightable_textures.lt_addon.io import atomic, transaction as tr
        txn = tr.BakeTransaction({str(out)!r}, blend={blend!r}, retire={retire}).begin()
        np.save(txn.path("A_t.npy"), np.arange(6.0) * 2)
        np.save(txn.path("A_new.npy"), np.ones(3))
        atomic.write_json(txn.path("A_report.json"), {{"v": 2}})
        txn.commit()
        {body}
        txn.finish()
    """)
    env = dict(os.environ, RELIGHT_FAULT=fault)
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          cwd=os.path.dirname(os.path.dirname(os.path.dirname(tr.__file__))))


def test_a_kill_in_the_middle_of_the_swap_is_rolled_back_by_the_next_sweep(tmp_path):
    out = tmp_path / "bk"
    before = _previous_bake(out)
    r = _child(out, None, "commit:kill", retire='["A_preview_*"]')
    assert r.returncode == -9, r.stderr
    # mid-swap: one new file is in, the retired preview is out; the journal says "swapping"
    assert (out / "A_new.npy").exists() and not (out / "A_preview_old.png").exists()
    done = tr.sweep(str(out))
    assert len(done["rolled_back"]) == 1 and not done["removed"]
    assert _state(out) == before


@pytest.mark.parametrize("saved", [False, True])
def test_a_kill_after_the_swap_follows_the_blend(tmp_path, saved):
    """Killed between the swap and the end: if the .blend was saved (new inode), the new bake
    stays (roll forward); if not, the previous bake comes back (roll back)."""
    out = tmp_path / "bk"
    before = _previous_bake(out)
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-old")
    body = ("atomic.write_bytes(%r, b'BLENDER-new'); " % str(blend) if saved else "") + \
        "os.kill(os.getpid(), 9)"
    r = _child(out, str(blend), "", body=body)
    assert r.returncode == -9, r.stderr
    done = tr.sweep(str(out))
    if saved:
        assert len(done["rolled_forward"]) == 1
        assert sorted(os.listdir(out)) == ["A_new.npy", "A_preview_old.png", "A_report.json",
                                           "A_t.npy", "notes.txt"]
        assert json.loads((out / "A_report.json").read_text()) == {"v": 2}
    else:
        assert len(done["rolled_back"]) == 1
        assert _state(out) == before


def test_a_blend_changed_meanwhile_is_refused_before_anything_moves(tmp_path):
    out = tmp_path / "bk"
    before = _previous_bake(out)
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-old")
    with pytest.raises(tr.ChangedMeanwhile, match="changed while the bake ran"):
        with tr.BakeTransaction(str(out), blend=str(blend)) as txn:
            _new_bake(txn.stage)
            atomic.write_bytes(blend, b"BLENDER-saved-by-someone-else")
            txn.commit()
    assert _state(out) == before


def test_the_sweep_removes_only_our_debris_of_dead_processes(tmp_path):
    out = tmp_path / "bk"
    before = _previous_bake(out)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    host = atomic._host()
    ours_dead = [f".A_t.relight-{host}-{dead}-0123abcd.tmp.npy",
                 f"A_rti.relight-{host}-{dead}-89abcdef.tmp",          # an export's staging
                 f".A.npy.{dead}.tmp.npy", f".A_report.{dead}-0badcafe.tmp.json"]   # legacy
    kept = [f".A_t.relight-{host}-{os.getpid()}-0123abcd.tmp.npy",     # alive (this process)
            f".A_t.relight-otherhost-{dead}-0123abcd.tmp.npy",         # another machine's
            ".hidden_user_file", "A.1234.tmp.npy", ".relight-stage-notes.txt"]
    for n in ours_dead + kept:
        (out / n).write_bytes(b"x")
    (out / f"A_rti.relight-{host}-{dead}-89abcdef.tmp").unlink()
    (out / f"A_rti.relight-{host}-{dead}-89abcdef.tmp").mkdir()
    stage = out / f"{tr.STAGE_PREFIX}relight-{host}-{dead}-00000000"   # killed while baking
    stage.mkdir()
    (stage / "A_t.npy").write_bytes(b"half")
    cache = out / ".relight_cache" / "A" / "0123456789abcdef0123"
    cache.mkdir(parents=True)
    (cache / f".direct_00000.relight-{host}-{dead}-11111111.tmp.npy").write_bytes(b"x")
    (cache / "direct_00000.npy").write_bytes(b"a finished chunk")
    done = tr.sweep(str(out))
    assert sorted(done["removed"]) == sorted(
        ours_dead + [stage.name, os.path.join(".relight_cache", "A", "0123456789abcdef0123",
                                              f".direct_00000.relight-{host}-{dead}-11111111.tmp.npy")])
    left = _state(out)
    assert {k: v for k, v in left.items() if k in before} == before
    assert sorted(set(left) - set(before)) == sorted(
        kept + [os.path.join(".relight_cache", "A", "0123456789abcdef0123", "direct_00000.npy")])


def test_check_file_refuses_damaged_files(tmp_path):
    np.save(tmp_path / "a.npy", np.arange(1000.0))
    tr.check_file(str(tmp_path / "a.npy"))
    with open(tmp_path / "a.npy", "r+b") as fh:
        fh.truncate(500)
    with pytest.raises(ValueError, match="truncated"):
        tr.check_file(str(tmp_path / "a.npy"))
    np.savez(tmp_path / "m.npz", x=np.arange(1000.0))
    data = bytearray((tmp_path / "m.npz").read_bytes())
    data[200] ^= 0xFF
    (tmp_path / "m.npz").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="CRC|NPZ"):
        tr.check_file(str(tmp_path / "m.npz"))
    (tmp_path / "r.json").write_text('{"a": ')
    with pytest.raises(ValueError, match="not valid JSON"):
        tr.check_file(str(tmp_path / "r.json"))
    (tmp_path / "x.exr").write_bytes(b"not an exr")
    with pytest.raises(ValueError, match="bad signature"):
        tr.check_file(str(tmp_path / "x.exr"))


def test_rewrite_paths_maps_every_spelling_of_a_staged_path(tmp_path):
    stage = str(tmp_path / "bk" / f"{tr.STAGE_PREFIX}relight-h-1-00000000")
    v = {"a": os.path.join(stage, "x.exr"), "b": ["//bk/" + os.path.basename(stage) + "/y.png",
                                                  "C:\\bk\\" + os.path.basename(stage) + "\\z"],
         "c": 3, "d": "unrelated"}
    assert tr.rewrite_paths(v, stage, str(tmp_path / "bk")) == {
        "a": str(tmp_path / "bk" / "x.exr"), "b": ["//bk/y.png", "C:\\bk\\z"], "c": 3,
        "d": "unrelated"}
    assert tr.target_of(stage) == str(tmp_path / "bk")
    assert tr.target_of(str(tmp_path / "bk")) == str(tmp_path / "bk")


def test_an_undo_that_is_itself_interrupted_can_be_run_again(tmp_path, monkeypatch):
    """The swap finished, then its undo stops half-way (a rename fails: Windows holds a file
    open, or a kill): running the undo again -- the next run's recovery -- restores the
    previous bake byte for byte, never deleting an old file it already put back."""
    out = tmp_path / "bk"
    before = _previous_bake(out)
    txn = tr.BakeTransaction(str(out), retire=["A_preview_*"]).begin()
    _new_bake(txn.stage)
    np.save(txn.path("A_new.npy"), np.ones(3))
    txn.commit()
    real, calls = os.rename, []

    def flaky(src, dst):
        calls.append(src)
        if len(calls) == 3:
            raise PermissionError(13, "held open", src)
        real(src, dst)

    monkeypatch.setattr(tr.os, "rename", flaky)
    with pytest.raises(PermissionError):
        tr._undo(txn.stage, txn.target, txn.entries, txn.retired)
    monkeypatch.setattr(tr.os, "rename", real)
    assert tr.recover(txn.stage) == "rolled back"
    assert _state(out) == before


# ------------------------------------------------------------------------------------------
# issue 56: a bake folder is untrusted input -- a planted stage or chunk cache never reaches
# outside it (sentinel files beside the folder are compared byte for byte afterwards)


def _dead_pid():
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True).stdout)


def _outside(tmp_path):
    """A victim file and folder beside ``bk/``, and what they hold."""
    (tmp_path / "victim.txt").write_bytes(b"the user's file next to the bake folder")
    ext = tmp_path / "elsewhere"
    (ext / "sub").mkdir(parents=True)
    (ext / "keep.txt").write_bytes(b"keep")
    return {"victim.txt": (tmp_path / "victim.txt").read_bytes(), "elsewhere": _state(ext)}


def _assert_outside_unchanged(tmp_path, before):
    assert (tmp_path / "victim.txt").read_bytes() == before["victim.txt"]
    assert _state(tmp_path / "elsewhere") == before["elsewhere"]
    assert (tmp_path / "elsewhere" / "sub").is_dir()


def _plant(stage, entries, state="swapping", old=(), extra=None):
    """A stage as a killed commit would leave it, with a journal naming ``entries``."""
    stage.mkdir()
    atomic.write_json(stage / tr.JOURNAL, {
        "format": tr.FORMAT, "format_version": 1, "state": state, "target": "/",
        "entries": entries, "retired": [], "blend": None, "blend_before": None,
        "blend_tmp": None, "existed": [], **(extra or {})})
    (stage / "victim.txt").write_bytes(b"planted")   # what '../victim.txt' would bring in
    if old is not None:
        (stage / tr.OLD).mkdir()
        for n in old:
            (stage / tr.OLD / n).write_bytes(b"planted old")


@pytest.mark.parametrize("attack", ["dotdot", "absolute", "separator", "legacy-name", "pid-0",
                                    "symlinked-stage", "symlinked-old", "garbage-journal"])
def test_a_planted_stage_never_moves_a_file_outside_the_folder(tmp_path, attack):
    """Issue 56: ``bk/.relight-stage-x.0-deadbeef.tmp/`` (an old-style name, pid 0) with a
    journal in state ``swapping`` naming ``../victim.txt`` made the next bake's sweep replace
    ``victim.txt`` beside ``bk/``. Names from a journal are basenames re-joined under the
    folder, stages of other name formats or pid 0 are never recovered, links never entered;
    each refusal leaves the planted stage alone and is reported."""
    out = tmp_path / "bk"
    inside = _previous_bake(out)
    outside = _outside(tmp_path)
    host, dead = atomic._host(), _dead_pid()
    name = f"{tr.STAGE_PREFIX}relight-{host}-{dead}-0badcafe"
    victim = str(tmp_path / "victim.txt")
    if attack == "dotdot":
        _plant(out / name, ["../victim.txt"], old=["../victim.txt"])
    elif attack == "absolute":
        _plant(out / name, [victim])
    elif attack == "separator":   # a path through a link planted in bk, and Windows' separator
        os.symlink(tmp_path / "elsewhere", out / "link")
        _plant(out / name, ["link/keep.txt", "x\\..\\..\\victim.txt"], old=[])
        (out / name / "link").mkdir()
        (out / name / tr.OLD / "link").mkdir()
        (out / name / tr.OLD / "link" / "keep.txt").write_bytes(b"planted old")
    elif attack == "legacy-name":   # the issue's own stage
        _plant(out / f"{tr.STAGE_PREFIX}x.0-deadbeef.tmp", ["../victim.txt"])
    elif attack == "pid-0":
        _plant(out / f"{tr.STAGE_PREFIX}relight-{host}-0-deadbeef", ["A_t.npy", "notes.txt"])
    elif attack == "symlinked-stage":   # the stage is a link to a folder elsewhere
        ext = tmp_path / "elsewhere"
        atomic.write_json(ext / tr.JOURNAL, {"format": tr.FORMAT, "format_version": 1,
                                              "state": "swapping", "entries": ["keep.txt"],
                                              "retired": [], "existed": []})
        outside["elsewhere"] = _state(ext)
        os.symlink(ext, out / name)
    elif attack == "garbage-journal":   # fields of the wrong type: refused, not a crash
        _plant(out / name, ["A_t.npy"], extra={"format_version": "x", "moved": {"A_t.npy": 1}})
    elif attack == "symlinked-old":     # .old a link: its files would be renamed into bk
        _plant(out / name, ["keep.txt"], old=None)
        os.symlink(tmp_path / "elsewhere", out / name / tr.OLD)
    done = tr.sweep(str(out))
    _assert_outside_unchanged(tmp_path, outside)
    assert {k: v for k, v in _state(out).items() if not k.startswith(tr.STAGE_PREFIX)} == inside
    assert len(done["refused"]) == 1, done
    assert not done["rolled_back"] and not done["rolled_forward"]
    planted = [n for n in os.listdir(out) if n.startswith(tr.STAGE_PREFIX)]
    assert len(planted) == 1 and planted[0] in done["refused"][0]   # left alone, named
    # a real bake into the folder goes on and commits
    with tr.BakeTransaction(str(out)) as txn:
        _new_bake(txn.stage)
        txn.commit()
    _assert_outside_unchanged(tmp_path, outside)
    np.testing.assert_array_equal(np.load(out / "A_t.npy"), np.arange(6.0) * 2)
    assert txn.swept["refused"] == done["refused"]


def test_a_planted_journal_cannot_take_the_users_file_inside_the_folder(tmp_path):
    """A stage of our name format whose journal lists a file of the user's that the swap never
    moved (``notes.txt``): the undo moves back only what the swap moved in (its identity is in
    the journal), so the user's file stays."""
    out = tmp_path / "bk"
    inside = _previous_bake(out)
    stage = out / f"{tr.STAGE_PREFIX}relight-{atomic._host()}-{_dead_pid()}-0badcafe"
    _plant(stage, ["notes.txt", "A_t.npy"], old=[], extra={"moved": {}})
    done = tr.sweep(str(out))
    assert done["rolled_back"] == [stage.name]
    assert _state(out) == inside


def test_the_recovery_never_removes_a_blend_tmp_the_journal_names(tmp_path):
    """``blend_tmp`` came from the journal: a path anywhere (here another process's temporary
    .blend in another folder). The recovery leaves it; the CLI's own sweep of the .blend's
    folder removes our temporary .blend files of dead processes by their token."""
    out = tmp_path / "bk"
    _previous_bake(out)
    (tmp_path / "elsewhere").mkdir()
    other = tmp_path / "elsewhere" / f".scene.relight-{atomic._host()}-{_dead_pid()}-12345678.tmp.blend"
    other.write_bytes(b"BLENDER-someone's")
    stage = out / f"{tr.STAGE_PREFIX}relight-{atomic._host()}-{_dead_pid()}-0badcafe"
    _plant(stage, [], old=[], extra={"blend_tmp": str(other), "moved": {}})
    done = tr.sweep(str(out))
    assert done["rolled_back"] == [stage.name]
    assert other.read_bytes() == b"BLENDER-someone's"


def test_a_symlinked_chunk_cache_is_never_walked_or_pruned(tmp_path):
    """``bk/.relight_cache`` a link to a folder elsewhere holding a key-like folder with our
    debris name and an empty folder: neither the sweep nor the commit's prune of empty cache
    folders reaches through it; the sweep reports it."""
    out = tmp_path / "bk"
    _previous_bake(out)
    ext = tmp_path / "elsewhere"
    (ext / "empty").mkdir(parents=True)
    key = ext / "0123456789abcdef0123"
    key.mkdir()
    (key / f".direct_00000.relight-{atomic._host()}-{_dead_pid()}-11111111.tmp.npy").write_bytes(b"x")
    before = _state(ext)
    os.symlink(ext, out / ".relight_cache")
    with tr.BakeTransaction(str(out)) as txn:
        _new_bake(txn.stage)
        txn.commit()
    assert _state(ext) == before and (ext / "empty").is_dir()
    assert os.path.islink(out / ".relight_cache")
    assert any(".relight_cache" in r for r in txn.swept["refused"]), txn.swept
