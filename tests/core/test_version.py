"""The version lives in one place, blender_manifest.toml; everything else reads it."""

import importlib.metadata
import pathlib
import tomllib

import relightable_textures

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_version_comes_from_the_manifest_only():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())["version"]
    assert relightable_textures.__version__ == manifest
    assert importlib.metadata.version("relightable-textures") == manifest   # pyproject: dynamic
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" not in pyproject and "version" in pyproject["dynamic"]
