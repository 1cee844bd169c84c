"""Build and validate the extension zip with Blender's own extension tool.

Blender's ``blender_ext.py`` ships inside the ``bpy`` wheel (``bpy/5.0/scripts/addons_core/
bl_pkg/cli/blender_ext.py``) and runs with plain Python; we locate it rather than re-implement
it. The wheels the manifest lists are downloaded first (pinned in requirements-wheels.txt).

Usage: ``python tools/extension_tool.py [--output-dir DIR]`` prints the path of the built zip.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import os
import subprocess
import sys
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


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


def ensure_wheels() -> list[str]:
    """Download the manifest's wheels into ./wheels unless already there; returns their paths."""
    wanted = [os.path.normpath(os.path.join(ROOT, w)) for w in manifest().get("wheels", [])]
    missing = [w for w in wanted if not os.path.exists(w)]
    if missing:
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
               "--only-binary=:all:", "--python-version", "3.11", "--implementation", "cp",
               "--platform", "manylinux_2_28_x86_64", "--platform", "manylinux_2_17_x86_64",
               "-d", os.path.join(ROOT, "wheels"),
               "-r", os.path.join(ROOT, "requirements-wheels.txt")]
        subprocess.run(cmd, check=True)
    still = [w for w in wanted if not os.path.exists(w)]
    if still:
        raise SystemExit("extension_tool: manifest wheels not downloaded (check the file names "
                         "in blender_manifest.toml against requirements-wheels.txt): "
                         + ", ".join(os.path.basename(w) for w in still))
    return wanted


def build(output_dir: str) -> str:
    """Validate the source tree, build the zip into ``output_dir``, validate the zip; returns it."""
    ensure_wheels()
    tool = blender_ext_script()
    os.makedirs(output_dir, exist_ok=True)
    m = manifest()
    zip_path = os.path.join(os.path.abspath(output_dir), f"{m['id']}-{m['version']}.zip")
    subprocess.run([sys.executable, tool, "validate", ROOT], check=True)
    subprocess.run([sys.executable, tool, "build", "--source-dir", ROOT,
                    "--output-filepath", zip_path], check=True)
    subprocess.run([sys.executable, tool, "validate", zip_path], check=True)
    return zip_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", default=os.path.join(ROOT, "dist"))
    args = parser.parse_args()
    print(build(args.output_dir))


if __name__ == "__main__":
    main()
