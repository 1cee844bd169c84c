"""A received .blend runs, contacts and sweeps nothing the user did not choose (issue 56).

The .blend is made by someone else: another Blender process (the sender's session) saves it
beside a script of the sender's, with the panel's legacy *Relight Command* pointing at that
script, a *Dask Scheduler* address, a last-export-page record naming a ``.desktop`` file and an
*Output* folder that climbs out of the pack. This process (the user's session) opens it with
the extension registered and presses the real operators:

- Bake with Run On = Local Dask Workers runs no program the file names (the script's marker is
  never created) and says in one line that the Relight Command is set in Preferences; the
  preferences' command is what runs.
- Run On = Dask Scheduler never hands the file's address to the command: with no scheduler in
  the preferences it refuses in one line; with one, that one is passed.
- Open Web Page never opens the file's page record; it opens a page this session exported, as a
  file:// URL of an .html (the opener is the one observation point patched: no browser here).
- An Output folder outside the .blend's folder is refused in one line (nothing swept there)
  until the user sets it in this session.
"""

import os
import pathlib
import stat
import subprocess
import sys
import textwrap

import pytest

HOSTILE = "tcp://10.255.255.1:8786"

_SENDER = textwrap.dedent("""
    import os, sys
    import bpy
    import relightable_textures

    pack = sys.argv[-1]
    with open(os.path.join(pack, "evil.sh"), "w") as fh:
        fh.write('#!/bin/sh\\ntouch "$(dirname "$0")/EVIL_RAN"\\necho "$@" > '
                 '"$(dirname "$0")/EVIL_ARGV"\\nexit 1\\n')
    os.chmod(os.path.join(pack, "evil.sh"), 0o755)
    with open(os.path.join(pack, "evil.desktop"), "w") as fh:
        fh.write("[Desktop Entry]\\nType=Application\\nExec=touch /tmp/pwned\\n")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    relightable_textures.register()
    bpy.ops.mesh.primitive_cube_add()
    scene = bpy.context.scene
    props = scene.relight
    props.method, props.directions, props.resolution = "transport", 8, 16
    props.run_on, props.dask_workers = "WORKERS", 1
    props.dask_command = "//evil.sh"
    props.dask_scheduler = "%s"
    scene["relight_last_export_page"] = os.path.join(pack, "evil.desktop")
    props.output_dir = "//relight/"
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(pack, "scene.blend"))
    props.output_dir = "//../victim/"
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(pack, "escape.blend"))
""" % HOSTILE)


@pytest.fixture(scope="module")
def pack(tmp_path_factory):
    """The sender's folder: scene.blend (Output //relight/), escape.blend (Output
    //../victim/), evil.sh, evil.desktop; made in another process (the sender's session)."""
    root = tmp_path_factory.mktemp("received")
    folder = root / "pack"
    folder.mkdir()
    (root / "victim").mkdir()
    r = subprocess.run([sys.executable, "-c", _SENDER, str(folder)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return folder


@pytest.fixture
def opened(pack, monkeypatch, tmp_path):
    """Open a .blend of the pack (name -> scene) with the extension registered, the Cube
    active, no ``relight`` on PATH; unregistered and the preferences entry removed after."""
    import bpy

    import relightable_textures

    empty = tmp_path / "bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty) + os.pathsep + "/usr/bin" + os.pathsep + "/bin")
    registered = []

    def open_(name):
        bpy.ops.wm.open_mainfile(filepath=str(pack / name), load_ui=False)
        if not registered:
            relightable_textures.register()
            registered.append(True)
        bpy.context.view_layer.objects.active = bpy.data.objects["Cube"]
        bpy.data.objects["Cube"].select_set(True)
        return bpy.context.scene

    try:
        yield open_
    finally:
        entry = bpy.context.preferences.addons.get(_addon_id())
        if entry is not None:
            bpy.context.preferences.addons.remove(entry)
        if registered:
            relightable_textures.unregister()
        for name in ("EVIL_RAN", "EVIL_ARGV"):
            (pack / name).unlink(missing_ok=True)


def _addon_id():
    import relightable_textures

    return relightable_textures.__name__


def _preferences(**values):
    """The add-on's preferences entry (as an installed, enabled extension has), with values."""
    import bpy

    entry = bpy.context.preferences.addons.get(_addon_id())
    if entry is None:
        entry = bpy.context.preferences.addons.new()
        entry.module = _addon_id()
    for k, v in values.items():
        setattr(entry.preferences, k, v)
    return entry.preferences


def _recorder(folder: pathlib.Path, name: str) -> pathlib.Path:
    """A stand-in ``relight`` of the user's: records its arguments, then fails in one line."""
    path = folder / name
    path.write_text(f'#!/bin/sh\necho "$@" > "{folder}/{name}.argv"\n'
                    'echo "relight: error: recorded" >&2\nexit 2\n')
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def test_bake_runs_no_relight_command_from_the_blend(opened, pack, tmp_path):
    import bpy

    scene = opened("scene.blend")
    assert scene.relight.run_on == "WORKERS" and scene.relight.dask_command == "//evil.sh"
    with pytest.raises(RuntimeError) as err:
        bpy.ops.relight.bake_textures()
    assert not (pack / "EVIL_RAN").exists(), "Bake ran the program the .blend names"
    message = str(err.value).strip()
    assert len(message.splitlines()) == 1
    assert "Relight Command" in message and "Preferences" in message

    # the panel says the file's value is ignored, and where the command is set
    from relightable_textures.operators.ui import panel

    lines = " | ".join(text for text, _ in panel.run_on_lines(scene.relight))
    assert "'//evil.sh'" in lines and "ignored" in lines and "Preferences" in lines
    scene.relight.run_on = "HERE"      # said also when the bake runs here
    assert any("'//evil.sh' is ignored" in t for t, _ in panel.run_on_lines(scene.relight))
    scene.relight.run_on = "WORKERS"

    # the user's own command, from the preferences, is what runs (the helper reads it there)
    mine = _recorder(tmp_path, "my-relight")
    _preferences(relight_command=str(mine))
    from relightable_textures.operators.farm import external_bake as eb

    assert eb.farm_preferences().relight_command == str(mine)
    with pytest.raises(RuntimeError, match="recorded"):
        bpy.ops.relight.bake_textures()
    assert (tmp_path / "my-relight.argv").is_file() and not (pack / "EVIL_RAN").exists()
    assert "--workers 1" in (tmp_path / "my-relight.argv").read_text()


def test_preferences_fall_back_to_defaults_without_an_addon_entry(opened):
    """Registered from a path (not an installed extension) there is no preferences entry:
    no command (``relight`` on PATH) and no scheduler, never the .blend's values."""
    import bpy

    from relightable_textures.operators.farm import external_bake as eb

    opened("scene.blend")
    assert bpy.context.preferences.addons.get(_addon_id()) is None
    prefs = eb.farm_preferences()
    assert (prefs.relight_command, prefs.scheduler) == ("", "")
    _preferences(relight_command="/opt/relight", dask_scheduler="tcp://farm:8786")
    prefs = eb.farm_preferences()
    assert (prefs.relight_command, prefs.scheduler) == ("/opt/relight", "tcp://farm:8786")


def test_the_blends_scheduler_address_is_never_used(opened, pack, tmp_path):
    import bpy

    scene = opened("scene.blend")
    scene.relight.run_on = "SCHEDULER"
    mine = _recorder(tmp_path, "my-relight")
    # the legacy field names a command of the user's, so a bake that read the .blend's fields
    # would run it and show the address it was handed
    scene.relight.dask_command = str(mine)
    assert scene.relight.dask_scheduler == HOSTILE
    with pytest.raises(RuntimeError) as err:
        bpy.ops.relight.bake_textures()
    argv = tmp_path / "my-relight.argv"
    assert not argv.exists() or HOSTILE not in argv.read_text(), "the .blend's address was used"
    message = str(err.value).strip()
    assert len(message.splitlines()) == 1 and "Scheduler" in message and "Preferences" in message
    assert not argv.exists()
    _preferences(relight_command=str(mine))     # a command, still no scheduler: refused
    with pytest.raises(RuntimeError, match="Scheduler.*Preferences"):
        bpy.ops.relight.bake_textures()
    assert not argv.exists()

    from relightable_textures.operators.ui import panel

    lines = " | ".join(text for text, _ in panel.run_on_lines(scene.relight))
    assert HOSTILE in lines and "ignored" in lines and "trust" in lines

    _preferences(dask_scheduler="tcp://127.0.0.1:1")
    with pytest.raises(RuntimeError, match="recorded"):
        bpy.ops.relight.bake_textures()
    text = argv.read_text()
    assert "--scheduler tcp://127.0.0.1:1" in text and HOSTILE not in text


def test_the_blends_export_page_record_is_not_opened(opened, pack, tmp_path, monkeypatch):
    import bpy

    from relightable_textures.operators.ui import export_ops

    scene = opened("scene.blend")
    assert scene["relight_last_export_page"].endswith("evil.desktop")
    monkeypatch.setattr(export_ops, "_SESSION_PAGE", {}, raising=False)  # none this session
    assert not bpy.ops.relight.open_export_page.poll(), "the .blend's page record would open"
    opened_urls = []
    monkeypatch.setattr(export_ops, "open_url", opened_urls.append)
    with pytest.raises(RuntimeError):
        bpy.ops.relight.open_export_page()
    assert opened_urls == []

    # a page this session exported opens, as a file:// URL of the .html
    page = tmp_path / "Cube_rti-hsh9" / "index.html"
    page.parent.mkdir()
    page.write_text("<html></html>")
    export_ops.remember_page(str(page))
    assert export_ops.last_export_page() == str(page)
    assert bpy.ops.relight.open_export_page() == {"FINISHED"}
    assert opened_urls == [page.as_uri()]
    # ... but not once it is a link to something else, nor a page that is not .html
    page.unlink()
    page.symlink_to(pack / "evil.desktop")
    assert not bpy.ops.relight.open_export_page.poll()
    export_ops.remember_page(str(pack / "evil.desktop"))
    assert not bpy.ops.relight.open_export_page.poll()
    assert opened_urls == [page.as_uri()]


def test_an_output_folder_outside_the_blends_folder_is_refused(opened, pack):
    import bpy

    from relightable_textures.operators.ui import bake_ops

    victim = pack.parent / "victim"
    (victim / "keep.txt").write_text("mine")
    scene = opened("escape.blend")
    props = scene.relight
    props.run_on = "HERE"
    assert props.output_dir == "//../victim/"
    with pytest.raises(RuntimeError) as err:
        bpy.ops.relight.bake_textures()
    message = str(err.value).strip()
    assert len(message.splitlines()) == 1 and "Output" in message and "again" in message
    assert sorted(p.name for p in victim.iterdir()) == ["keep.txt"]

    # a folder inside the .blend's folder is used as it is; a link inside it to elsewhere not
    props.run_on = "WORKERS"   # (no bake below: the decision alone)
    scene2 = opened("scene.blend")
    assert os.path.normpath(bake_ops._output_dir(scene2.relight)) == str(pack / "relight")
    link = pack / "out-link"
    link.symlink_to(victim, target_is_directory=True)
    try:
        scene2.relight["output_dir"] = "//out-link/"   # as a file would carry it (no update)
        with pytest.raises(bake_ops.BakeInputError, match="Output"):
            bake_ops._output_dir(scene2.relight)
    finally:
        link.unlink()

    # the user choosing the same folder in this session is their decision
    scene3 = opened("escape.blend")
    with pytest.raises(bake_ops.BakeInputError, match="again"):
        bake_ops._output_dir(scene3.relight)
    scene3.relight.output_dir = "//../victim/"
    assert os.path.normpath(bake_ops._output_dir(scene3.relight)) == str(victim)
