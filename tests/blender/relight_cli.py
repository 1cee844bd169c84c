"""Run the venv's real ``relight`` console script in a subprocess (shared by the CLI tests)."""

import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

BIN = pathlib.Path(sys.executable).parent


def relight(*args, cwd=None, env=None):
    return subprocess.run([str(BIN / "relight"), *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=600, env=env)


#: Sample .blend files made once per test session by the real ``relight scene`` (the scenes are
#: deterministic: test_samples.py), copied for each test that needs one to bake or refuse.
_SCENES: dict = {}


def make_scene(name: str, out) -> pathlib.Path:
    """``relight scene NAME --out OUT`` (default size): the first call per session runs the console
    script, later ones copy its file (1.2-1.4 s of Blender start-up and scene building saved per
    call, measured 2026-12-02). Tests of the ``scene`` verb itself call ``relight`` directly."""
    if name not in _SCENES:
        folder = pathlib.Path(tempfile.mkdtemp(prefix=f"relight-test-scene-{name}-"))
        path = folder / f"{name}.blend"
        r = relight("scene", name, "--out", path)
        assert r.returncode == 0, r.stderr[-2000:]
        _SCENES[name] = path
    out = pathlib.Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(_SCENES[name], out)
    return out


#: Blender's own log lines (``00:00.035  color_management | Using OCIO=...``): the relight CLI
#: sends file descriptor 1 to stderr, so Blender 5.2+ logs them there when ``$OCIO`` is set.
BLENDER_LOG = re.compile(r"^\d\d:\d\d\.\d{3}\s+\S+\s+\| ")


def our_lines(stderr: str) -> list:
    """stderr without Blender's own log lines: what the CLI itself wrote."""
    return [ln for ln in stderr.strip().splitlines() if not BLENDER_LOG.match(ln)]


def folder_state(folder):
    """Every file in ``folder`` with its bytes, to prove a refused command changed nothing."""
    return {p.name: p.read_bytes() for p in pathlib.Path(folder).iterdir() if p.is_file()}


def assert_refused(folder, message, *args, env=None):
    """Run ``relight *args`` expecting a one-line ``relight: error:`` containing ``message``
    (case-insensitive), exit code 2, and ``folder`` unchanged."""
    before = folder_state(folder)
    r = relight(*args, env=env)
    assert r.returncode == 2, r.stderr[-2000:]
    last = our_lines(r.stderr)[-1]
    assert last.startswith("relight: error: "), r.stderr[-2000:]
    assert message.lower() in last.lower(), last
    assert folder_state(folder) == before
    return r
