"""Test configuration shared by all tests.

Blender writes its user configuration on ``import bpy``; point it at a throw-away directory
*before* anything imports bpy, so tests never touch the real ``~/.config/blender``.
Subprocesses started by tests inherit this environment.
"""

from __future__ import annotations

import os
import pathlib
import tempfile

import pytest

_USER_RESOURCES = tempfile.mkdtemp(prefix="relight-test-blender-user-")
os.environ["BLENDER_USER_RESOURCES"] = _USER_RESOURCES
# The chunk caches' HMAC key (lt_addon/io/chunk_cache.py): one per test session, never the
# user's ~/.cache/relightable-textures/chunk-key; the CLI's subprocesses and Dask workers share it.
os.environ["RELIGHT_CHUNK_KEY_FILE"] = os.path.join(
    tempfile.mkdtemp(prefix="relight-test-chunk-key-"), "chunk-key")
# Bakes of the CLI (and its Dask workers) on the CPU, as in-process bakes that choose no device,
# even on a machine with a GPU: the tests compare against CPU references and Cycles truths.
# Tests of --device auto / gpu pass it explicitly.
os.environ["RELIGHT_DEVICE"] = "cpu"

ROOT = pathlib.Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "tests/blender" in str(item.path).replace(os.sep, "/"):
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def repo_root() -> pathlib.Path:
    return ROOT


@pytest.fixture
def fresh_scene():
    """An empty factory session; yields its scene (bpy module, in process)."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield bpy.context.scene
