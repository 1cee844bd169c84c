"""Build and validate the extension zips, one per platform, with Blender's own extension tool.

Blender's ``blender_ext.py`` ships inside the ``bpy`` wheel (``bpy/<version>/scripts/addons_core/
bl_pkg/cli/blender_ext.py``) and runs with plain Python; we locate it rather than re-implement
it. The wheels the manifest lists (SciPy and OpenEXR for CPython 3.11 and 3.13 on every platform
in ``platforms``) are downloaded first, pinned in requirements-wheels.txt. ``build
--split-platforms`` then writes one zip per platform holding only that platform's wheels; each
zip is validated by the tool and checked here against the manifest.

Usage: ``python tools/extension_tool.py [--output-dir DIR]`` prints the built zips, one a line,
as ``<blender platform> <path>``.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: The Python versions of the supported Blenders (4.2 LTS-5.0: 3.11; 5.1 and later: 3.13).
PYTHONS = ("3.11", "3.13")

#: Blender platform -> pip ``--platform`` tags that select its wheels (pip also accepts older
#: macOS versions than the one named, so each pair yields exactly one wheel per package).
PIP_PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64",),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_14_0_arm64",),
    "macos-x64": ("macosx_10_15_x86_64",),
}
#: Packages whose wheels need a newer platform than :data:`PIP_PLATFORMS` names (embreex 4.4
#: is built for macOS 13 on Intel Macs), downloaded with these tags instead.
NEWER_PLATFORMS = {"embreex": {"macos-x64": ("macosx_13_0_x86_64",)}}


def requirements() -> list[str]:
    """The pinned lines of requirements-wheels.txt."""
    with open(os.path.join(ROOT, "requirements-wheels.txt")) as fh:
        return [ln.split("#")[0].strip() for ln in fh if ln.split("#")[0].strip()]


def blender_ext_script() -> str:
    """Path of ``blender_ext.py`` inside the installed bpy wheel (bpy is not imported)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("extension_tool: the bpy module is not installed (run `make venv`)")
    base = list(spec.submodule_search_locations)[0]
    found = glob.glob(os.path.join(base, "*", "scripts", "addons_core", "bl_pkg", "cli",
                                   "blender_ext.py"))
    if not found:
        raise SystemExit(f"extension_tool: blender_ext.py not found under {base}")
    return sorted(found)[-1]


def manifest() -> dict:
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as fh:
        return tomllib.load(fh)


def wheel_platform(name: str) -> str | None:
    """The Blender platform a wheel file name is for (by its platform tag), or None."""
    tag = os.path.basename(name)[:-len(".whl")].split("-")[-1]
    if "manylinux" in tag and tag.endswith("x86_64"):
        return "linux-x64"
    if tag == "win_amd64":
        return "windows-x64"
    if tag.startswith("macosx_") and tag.endswith("_arm64"):
        return "macos-arm64"
    if tag.startswith("macosx_") and tag.endswith("_x86_64"):
        return "macos-x64"
    return None


#: Where the manifest's wheels are kept between checkouts (they are pinned by file name, so a
#: file there is the file the manifest names): a fresh clone copies them instead of downloading
#: ~240 MB again (measured 2026-12-02 in a clean-clone CI run).
WHEEL_CACHE = os.path.join(os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")),
                           "relightable-textures", "extension-wheels")


def _copy_atomically(src: str, dst: str) -> None:
    """``src`` copied to ``dst`` whole or not at all, through the project's one rename helper
    (lt_addon/io/atomic.py, loaded by path: this tool runs outside the package)."""
    spec = importlib.util.spec_from_file_location(
        "_relight_atomic", os.path.join(ROOT, "lt_addon", "io", "atomic.py"))
    atomic = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(atomic)
    with atomic.atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def ensure_wheels() -> list[str]:
    """The manifest's wheels in ./wheels: copied from :data:`WHEEL_CACHE`, else downloaded (and
    then kept there); returns their paths."""
    m = manifest()
    wanted = [os.path.normpath(os.path.join(ROOT, w)) for w in m.get("wheels", [])]
    unknown = [p for p in m.get("platforms", []) if p not in PIP_PLATFORMS]
    if unknown:
        raise SystemExit(f"extension_tool: no pip platform tags known for {unknown}")
    for w in wanted:
        cached = os.path.join(WHEEL_CACHE, os.path.basename(w))
        if not os.path.exists(w) and os.path.isfile(cached):
            os.makedirs(os.path.dirname(w), exist_ok=True)
            _copy_atomically(cached, w)
    if any(not os.path.exists(w) for w in wanted):
        for platform in m.get("platforms", []):
            for python in PYTHONS:
                for req in requirements():
                    name = req.split("==")[0].strip().lower()
                    tags = NEWER_PLATFORMS.get(name, {}).get(platform, PIP_PLATFORMS[platform])
                    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                           "--only-binary=:all:", "--python-version", python,
                           "--implementation", "cp", "-d", os.path.join(ROOT, "wheels"), req]
                    for tag in tags:
                        cmd += ["--platform", tag]
                    subprocess.run(cmd, check=True)
    still = [w for w in wanted if not os.path.exists(w)]
    if still:
        raise SystemExit("extension_tool: manifest wheels not downloaded (check the file names "
                         "in blender_manifest.toml against requirements-wheels.txt): "
                         + ", ".join(os.path.basename(w) for w in still))
    try:
        os.makedirs(WHEEL_CACHE, exist_ok=True)
        for w in wanted:
            cached = os.path.join(WHEEL_CACHE, os.path.basename(w))
            if not os.path.exists(cached):
                _copy_atomically(w, cached)
    except OSError as exc:   # a read-only or full cache only costs the next clone a download
        print(f"extension_tool: note: could not keep the wheels in {WHEEL_CACHE}: {exc}",
              file=sys.stderr)
    return wanted


def check_zip(zip_path: str, platform: str, wheels: list[str]) -> None:
    """The zip holds exactly the manifest's wheels for ``platform``: both Pythons, every
    package of requirements-wheels.txt, nothing of another platform."""
    inside = sorted(os.path.basename(n) for n in zipfile.ZipFile(zip_path).namelist()
                    if n.endswith(".whl"))
    expected = sorted(os.path.basename(w) for w in wheels if wheel_platform(w) == platform)
    if inside != expected or len(expected) != len(requirements()) * len(PYTHONS):
        raise SystemExit(f"extension_tool: {os.path.basename(zip_path)} holds wheels {inside}, "
                         f"expected {expected}")


def build(output_dir: str) -> dict[str, str]:
    """Validate the source tree, build one zip per platform into ``output_dir``, validate and
    check each; returns {blender platform: zip path}."""
    wheels = ensure_wheels()
    tool = blender_ext_script()
    os.makedirs(output_dir, exist_ok=True)
    m = manifest()
    base = os.path.join(os.path.abspath(output_dir), f"{m['id']}-{m['version']}.zip")
    subprocess.run([sys.executable, tool, "validate", ROOT], check=True, stdout=sys.stderr)
    subprocess.run([sys.executable, tool, "build", "--source-dir", ROOT, "--split-platforms",
                    "--output-filepath", base], check=True, stdout=sys.stderr)
    zips = {}
    for platform in m["platforms"]:
        zip_path = base[:-len(".zip")] + "-" + platform.replace("-", "_") + ".zip"
        if not os.path.exists(zip_path):
            raise SystemExit(f"extension_tool: the extension tool did not write {zip_path}")
        subprocess.run([sys.executable, tool, "validate", zip_path], check=True,
                       stdout=sys.stderr)
        check_zip(zip_path, platform, wheels)
        zips[platform] = zip_path
    return zips


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", default=os.path.join(ROOT, "dist"))
    args = parser.parse_args()
    for platform, path in build(args.output_dir).items():
        print(platform, path)


if __name__ == "__main__":
    main()
