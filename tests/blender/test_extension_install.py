"""The real extension zip: built and validated by Blender's own tool, installed into a temporary
Blender user directory through bpy, enabled, exercised, disabled and removed."""

import ast
import json
import os
import pathlib
import subprocess
import sys
import textwrap

import pytest

#: Also run on 5.2 LTS by the matrix: Blender's extension installer.
pytestmark = pytest.mark.version_sensitive

ROOT = pathlib.Path(__file__).resolve().parents[2]

INSTALL_SCRIPT = textwrap.dedent(r"""
    import json, os, sys
    import bpy, addon_utils

    zip_path, blend_out = sys.argv[1], sys.argv[2]
    user = os.environ["BLENDER_USER_RESOURCES"]
    site = os.path.join(user, "extensions", ".local", "lib",
                        f"python{sys.version_info.major}.{sys.version_info.minor}", "site-packages")

    # The test venv has its own scipy/OpenEXR; hide them, so these imports (the extension's
    # too) can only find the wheels Blender extracted from the zip into the extension site.
    import importlib.machinery

    class OnlyBundledWheels:
        def find_spec(self, name, path=None, target=None):
            if "." not in name and name in ("scipy", "OpenEXR", "embreex", "tzdata"):
                return importlib.machinery.PathFinder.find_spec(name, [site]) or \
                    importlib.machinery.ModuleSpec(name, None)  # None loader: ImportError
            return None

    sys.meta_path.insert(0, OnlyBundledWheels())
    report = {"user_resource": bpy.utils.resource_path("USER")}
    mod = "bl_ext.user_default.relightable_textures"
    report["install"] = list(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))
    report["enabled"] = mod in bpy.context.preferences.addons
    report["wheels_installed"] = sorted(n for n in os.listdir(site) if not n.startswith("_")) \
        if os.path.isdir(site) else []
    # hasattr() on bpy.ops.relight is true for any name; dir() lists registered operators.
    report["operators"] = [n for n in ("add_sample_scene", "analyze", "bake_materials",
                                       "bake_textures", "bake_transport", "discard_chunks",
                                       "export", "follow_sun", "open_export_page",
                                       "remove_preview", "show_preview")
                           if n in dir(bpy.ops.relight)]
    report["operator_types"] = [n for n in ("RELIGHT_OT_add_sample_scene",
                                            "RELIGHT_OT_analyze", "RELIGHT_OT_bake_materials",
                                            "RELIGHT_OT_bake_textures",
                                            "RELIGHT_OT_bake_transport",
                                            "RELIGHT_OT_discard_chunks", "RELIGHT_OT_export",
                                            "RELIGHT_OT_follow_sun",
                                            "RELIGHT_OT_open_export_page",
                                            "RELIGHT_OT_remove_preview",
                                            "RELIGHT_OT_show_preview") if n in dir(bpy.types)]
    # The bundled wheels import from the extension's own site-packages.
    import scipy, scipy.linalg, OpenEXR, embreex, tzdata
    report["site"] = site
    report["imported_from"] = {m.__name__: m.__file__
                               for m in (scipy, OpenEXR, embreex, tzdata)}
    # zoneinfo with no system database (as on Windows) reads the bundled tzdata
    import zoneinfo
    zoneinfo.reset_tzpath(to=[])
    try:
        report["zone_without_system_db"] = str(zoneinfo.ZoneInfo.no_cache("Europe/London"))
    except Exception as ex:
        report["zone_without_system_db"] = repr(ex)
    finally:
        zoneinfo.reset_tzpath()
    report["property"] = hasattr(bpy.types.Scene, "relight") and \
        bpy.context.scene.relight.preset == "balanced"
    report["panels"] = [n for n in ("VIEW3D_PT_relight", "VIEW3D_PT_relight_bake",
                                    "VIEW3D_PT_relight_light", "VIEW3D_PT_relight_vertex",
                                    "VIEW3D_PT_relight_materials", "VIEW3D_PT_relight_export",
                                    "VIEW3D_PT_relight_samples")
                        if n in dir(bpy.types)]
    # The operator really builds a scene into the open file.
    report["op_result"] = list(bpy.ops.relight.add_sample_scene(name="bumps", size="test"))
    report["op_vertices"] = len(bpy.data.objects["Bumps"].data.vertices)
    # The installed bake operator (bundled wheels, relative imports) bakes and previews.
    props = bpy.context.scene.relight
    props.preset = "draft"
    props.method = "lobes"
    props.order, props.resolution, props.samples = 3, 16, 2
    props.output_dir = os.path.join(os.path.dirname(blend_out), "op_bake") + os.sep
    bpy.context.view_layer.objects.active = bpy.data.objects["Bumps"]
    report["bake"] = list(bpy.ops.relight.bake_textures())
    report["bake_files"] = sorted(os.listdir(props.output_dir))
    # ... and the default transport bake, its direct light by the bundled ray engine
    props.method = "transport"
    props.directions, props.resolution, props.bounces = 16, 16, 0
    props.output_dir = os.path.join(os.path.dirname(blend_out), "op_transport") + os.sep
    report["transport_bake"] = list(bpy.ops.relight.bake_textures())
    with open(os.path.join(props.output_dir, "Bumps_texture_report.json")) as fh:
        report["transport_direct"] = json.load(fh)["direct"]
    # The same CLI verbs, registered as Blender's `--command relight`; the bpy module cannot
    # dispatch --command, so call the registered function itself.
    from bl_ext.user_default.relightable_textures.operators import cli, registration
    report["cli_registered"] = len(registration._cli_handles)
    report["cli_verbs"] = sorted(cli.build_parser()._subparsers._group_actions[0].choices)
    report["cli_scene"] = cli.run(["scene", "noise", "--out", blend_out])
    report["cli_bad"] = cli.run(["scene", "castle", "--out", blend_out + "2.blend"])
    report["enabled_after_cli"] = mod in bpy.context.preferences.addons
    repo_index = [r.module for r in bpy.context.preferences.extensions.repos].index("user_default")
    report["uninstall"] = list(bpy.ops.extensions.package_uninstall(
        repo_index=repo_index, pkg_id="relightable_textures"))
    report["enabled_after_uninstall"] = mod in bpy.context.preferences.addons
    report["property_after_uninstall"] = hasattr(bpy.types.Scene, "relight")
    report["panel_after_uninstall"] = "VIEW3D_PT_relight" in dir(bpy.types)
    report["operators_after_uninstall"] = [n for n in dir(bpy.ops.relight) if not n.startswith("_")]
    report["files_left"] = os.path.exists(os.path.join(user, "extensions", "user_default",
                                                       "relightable_textures"))
    print("REPORT " + json.dumps(report))
""")


def _snapshot(path: pathlib.Path):
    if not path.exists():
        return None
    return sorted((str(p), p.stat().st_mtime_ns) for p in path.rglob("*"))


@pytest.fixture(scope="module")
def extension_zips(tmp_path_factory):
    """{Blender platform: zip}: the four zips of tools/extension_tool.py (``make dist``)."""
    out = tmp_path_factory.mktemp("dist")
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "extension_tool.py"),
                        "--output-dir", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    zips = {k: pathlib.Path(v) for k, v in
            (line.split(" ", 1) for line in r.stdout.strip().splitlines())}
    assert sorted(zips) == ["linux-x64", "macos-arm64", "macos-x64", "windows-x64"], r.stdout
    assert all(z.exists() for z in zips.values())
    return zips


@pytest.fixture(scope="module")
def extension_zip(extension_zips):
    return extension_zips["linux-x64"]


def _tzdata_wheel() -> str:
    """The tzdata wheel's file name, as the manifest names it (requirements-wheels.txt pins
    its version)."""
    import tomllib

    wheels = tomllib.loads((ROOT / "blender_manifest.toml").read_text())["wheels"]
    names = [w.rsplit("/", 1)[-1] for w in wheels if w.rsplit("/", 1)[-1].startswith("tzdata-")]
    assert len(names) == 1, f"the manifest names {names} for tzdata, not its one wheel"
    (name,) = names
    pin = [ln.split("#")[0].strip() for ln in
           (ROOT / "requirements-wheels.txt").read_text().splitlines()
           if ln.split("#")[0].strip().startswith("tzdata==")]
    assert pin == ["tzdata==" + name.split("-")[1]], (pin, name)
    return name


def test_zip_contents(extension_zip):
    import zipfile

    names = set(zipfile.ZipFile(extension_zip).namelist())
    for required in ("blender_manifest.toml", "__init__.py", "lt_addon/__init__.py",
                     "operators/registration.py", "samples/__init__.py"):
        assert required in names
    assert not any(n.startswith(("tests/", ".venv/", ".git/", "tools/", "benchmarks/",
                                 "devtools/")) for n in names)
    assert not {"setup.py", "pyproject.toml", "Makefile"} & names       # the wheel's build files
    # only the product: no benchmark, Pareto or chart code anywhere in the zip, and no module
    # that imports matplotlib (Blender does not ship it)
    modules = sorted(n for n in names if n.endswith(".py"))
    assert not [n for n in modules if any(w in pathlib.PurePosixPath(n).stem
                                          for w in ("bench", "pareto", "plot", "chart"))]
    z = zipfile.ZipFile(extension_zip)
    imported = {(n, node.module if isinstance(node, ast.ImportFrom) else alias.name)
                for n in modules for node in ast.walk(ast.parse(z.read(n)))
                if isinstance(node, (ast.Import, ast.ImportFrom))
                for alias in node.names}
    assert not [(n, m) for n, m in imported if m and m.split(".")[0] == "matplotlib"]
    # the development tools reach the product by entry points only (lt_addon/plugins.py)
    assert sorted(n for n, m in imported if m and "devtools" in m) == []
    # every module of the checkout's product folders is in the zip (nothing dropped by mistake)
    product = sorted(str(p.relative_to(ROOT)) for d in ("lt_addon", "operators", "samples")
                     for p in (ROOT / d).rglob("*.py") if "__pycache__" not in p.parts)
    assert set(product) <= names
    # the exported RTI page's viewer travels with the extension
    assert {"lt_addon/export/web/viewer.js", "lt_addon/export/web/template.html"} <= names
    # This platform's SciPy, OpenEXR and embreex (the ray engine) for both Pythons Blender uses
    # (3.11 and 3.13), no other, and the one pure-Python tzdata wheel for every Python.
    wheels = sorted(n.split("-")[0] + "-" + n.split("-")[2] for n in names
                    if n.startswith("wheels/") and n.endswith(".whl"))
    assert wheels == ["wheels/embreex-cp311", "wheels/embreex-cp313", "wheels/openexr-cp311",
                      "wheels/openexr-cp313", "wheels/scipy-cp311", "wheels/scipy-cp313",
                      "wheels/tzdata-py2.py3"]
    assert all("x86_64" in n for n in names if n.endswith(".whl")
               and not n.endswith("-none-any.whl"))


#: Each platform's tag in its wheels' file names.
PLATFORM_TAGS = {"linux-x64": "manylinux", "windows-x64": "win_amd64",
                 "macos-arm64": "_arm64", "macos-x64": "_x86_64"}


def test_every_platform_zip_bundles_tzdata(extension_zips):
    """zoneinfo has no IANA database on Windows but the tzdata package's: the one pure-Python
    wheel is in every platform's zip (Blender's split keeps ``any`` wheels in each) and in the
    wheels list Blender's build writes into each zip's manifest, which Blender installs from."""
    import tomllib
    import zipfile

    tz = _tzdata_wheel()
    assert tz.endswith("-py2.py3-none-any.whl")
    payloads = set()
    for platform, path in extension_zips.items():
        with zipfile.ZipFile(path) as z:
            wheels = sorted(n for n in z.namelist() if n.endswith(".whl"))
            generated = tomllib.loads(z.read("blender_manifest.toml").decode())["build"][
                "generated"]
            payloads.add(z.read("wheels/" + tz))
        assert "wheels/" + tz in wheels, (platform, wheels)
        assert [w for w in wheels if "tzdata" in w] == ["wheels/" + tz], platform
        assert generated["platforms"] == [platform]
        assert "./wheels/" + tz in generated["wheels"], (platform, generated["wheels"])
        assert sorted(w.removeprefix("./") for w in generated["wheels"]) == wheels, platform
        # the rest is the platform's own: 3 packages x 2 Pythons
        own = [w for w in wheels if not w.endswith("-none-any.whl")]
        assert len(own) == 6 and all(PLATFORM_TAGS[platform] in w for w in own), (platform, own)
    assert len(payloads) == 1      # the same file in all four


def test_the_bundled_tzdata_serves_zoneinfo_without_a_system_database(extension_zips, tmp_path):
    """Where the system has no zone database (Windows: PYTHONTZPATH points to an empty folder
    here), zoneinfo reads the tzdata package: the wheel out of the Windows zip, on sys.path,
    gives Europe/London its summer time; without it the name is not found. ``-S``: the venv's
    own tzdata (pvlib's dependency there) stays out of the path."""
    import zipfile

    tz = _tzdata_wheel()
    wheel = tmp_path / tz
    wheel.write_bytes(zipfile.ZipFile(extension_zips["windows-x64"]).read("wheels/" + tz))
    empty = tmp_path / "no-zoneinfo"
    empty.mkdir()
    script = textwrap.dedent("""
        import datetime, sys, zoneinfo
        try:
            z = zoneinfo.ZoneInfo("Europe/London")
        except zoneinfo.ZoneInfoNotFoundError:
            print("NOT FOUND"); sys.exit(3)
        import tzdata
        print(tzdata.__file__, tzdata.IANA_VERSION,
              datetime.datetime(2026, 7, 1, 12, tzinfo=z).utcoffset().total_seconds(),
              datetime.datetime(2026, 1, 1, 12, tzinfo=z).utcoffset().total_seconds())
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PYTHONTZPATH"] = str(empty)
    run = [sys.executable, "-S", "-c", script]
    r = subprocess.run(run, capture_output=True, text=True, timeout=60,
                       env={**env, "PYTHONPATH": str(wheel)})
    assert r.returncode == 0, r.stdout + r.stderr
    origin, iana, summer, winter = r.stdout.split()
    assert pathlib.Path(origin).is_relative_to(wheel), origin     # read out of the wheel
    assert iana.startswith(tz.split("-")[1].split(".")[0])          # 2026.6: IANA 2026f
    assert (float(summer), float(winter)) == (3600.0, 0.0)            # BST, GMT
    # the same Python without the wheel has no database at all: the check above is the wheel's
    r = subprocess.run(run, capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 3 and r.stdout.strip() == "NOT FOUND", r.stdout + r.stderr


def test_install_enable_use_uninstall_in_temporary_user_dir(extension_zip, tmp_path):
    real_config = pathlib.Path.home() / ".config" / "blender"
    before = _snapshot(real_config)
    user = tmp_path / "blender-user"
    user.mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    blend_out = tmp_path / "from-blender-cli.blend"
    r = subprocess.run([sys.executable, "-c", INSTALL_SCRIPT, str(extension_zip), str(blend_out)],
                       capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("REPORT ")]
    assert r.returncode == 0 and lines, r.stdout[-3000:] + r.stderr[-3000:]
    rep = json.loads(lines[-1][len("REPORT "):])
    assert rep["user_resource"].startswith(str(user))
    assert rep["install"] == ["FINISHED"] and rep["enabled"]
    assert "scipy" in rep["wheels_installed"] and any(
        n.lower().startswith("openexr") for n in rep["wheels_installed"])
    assert rep["operators"] == ["add_sample_scene", "analyze", "bake_materials",
                                "bake_textures", "bake_transport", "discard_chunks",
                                "export", "follow_sun", "open_export_page", "remove_preview",
                                "show_preview"]
    assert len(rep["operator_types"]) == 11
    assert "tzdata" in rep["wheels_installed"]
    assert sorted(rep["imported_from"]) == ["OpenEXR", "embreex", "scipy", "tzdata"]
    for name, path in rep["imported_from"].items():
        assert path.startswith(rep["site"]), f"{name} imported from {path}, not the extension"
    assert rep["zone_without_system_db"] == "Europe/London", rep["zone_without_system_db"]
    assert rep["property"]
    assert rep["panels"] == ["VIEW3D_PT_relight", "VIEW3D_PT_relight_bake",
                             "VIEW3D_PT_relight_light", "VIEW3D_PT_relight_vertex",
                             "VIEW3D_PT_relight_materials", "VIEW3D_PT_relight_export",
                             "VIEW3D_PT_relight_samples"]
    assert rep["bake"] == ["FINISHED"]
    assert rep["transport_bake"] == ["FINISHED"]
    assert rep["transport_direct"]["engine"] == "rays", rep["transport_direct"]
    assert rep["transport_direct"]["library"].startswith("embreex")
    assert rep["bake_files"] == ["Bumps_steerable.exr", "Bumps_steerable.json",
                                 "Bumps_steerable_atlas.exr"]
    assert rep["op_result"] == ["FINISHED"] and rep["op_vertices"] == 33 * 33
    assert rep["cli_registered"] == 1
    # the development verb `bench` is not in the extension; every product verb is
    assert "bench" not in rep["cli_verbs"] and {
        "scene", "bake-textures", "bake-transport", "analyze", "relight", "bake-materials",
        "relight-materials", "export"} <= set(rep["cli_verbs"])
    assert rep["cli_scene"] == 0 and blend_out.exists()
    assert rep["cli_bad"] == 2 and not pathlib.Path(str(blend_out) + "2.blend").exists()
    assert rep["enabled_after_cli"]
    assert rep["uninstall"] == ["FINISHED"] and not rep["enabled_after_uninstall"]
    assert not rep["property_after_uninstall"] and not rep["panel_after_uninstall"]
    assert rep["operators_after_uninstall"] == []
    assert not rep["files_left"]
    assert _snapshot(real_config) == before, "the real ~/.config/blender was modified"
