"""Failure logs (lt_addon/errors.py write_log): when the log folder cannot take one, the
fallback is a fresh private folder, not a fixed name in the shared temporary folder that
another user could have made first or pointed elsewhere by a link (issue 56)."""

import os
import stat
import tempfile

from relightable_textures.lt_addon import errors


def _failure():
    try:
        raise RuntimeError("boom")
    except RuntimeError as exc:
        return exc


def test_the_fallback_log_folder_is_fresh_and_private(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("RELIGHT_LOG_DIR", str(blocker / "logs"))   # cannot be made
    shared = tmp_path / "tmp"
    shared.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(shared))
    elsewhere = tmp_path / "someone-elses"
    elsewhere.mkdir()
    (shared / "relightable-textures").symlink_to(elsewhere, target_is_directory=True)

    path = errors.write_log(_failure(), "relight bake-textures x.blend")
    assert path is not None and "boom" in open(path, encoding="utf-8").read()
    assert list(elsewhere.iterdir()) == [], "the log went through the planted link"
    folder = os.path.dirname(path)
    assert os.path.dirname(folder) == str(shared)
    assert os.path.basename(folder).startswith("relightable-textures-")
    st = os.lstat(folder)
    assert stat.S_ISDIR(st.st_mode) and stat.S_IMODE(st.st_mode) == 0o700
    # a second failure gets a folder of its own
    assert os.path.dirname(errors.write_log(_failure())) != folder


def test_a_log_never_writes_through_an_existing_file(tmp_path, monkeypatch):
    """Two logs of one process in one second get two files; an existing file (or a link) at
    the name is left as it is."""
    monkeypatch.setenv("RELIGHT_LOG_DIR", str(tmp_path))
    monkeypatch.setattr(errors.time, "strftime", lambda fmt, *a: "20270101-000000")
    target = tmp_path / "target"
    target.write_text("keep")
    (tmp_path / f"relight-20270101-000000-{os.getpid()}.log").symlink_to(target)
    first = errors.write_log(_failure())
    second = errors.write_log(_failure())
    assert target.read_text() == "keep"
    assert first != second and os.path.dirname(first) == str(tmp_path)
    assert all("boom" in open(p, encoding="utf-8").read() for p in (first, second))
