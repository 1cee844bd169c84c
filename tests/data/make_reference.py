"""Regenerate the stored reference bake used by tests/blender/test_reference_bake.py.

    .venv/bin/python tests/data/make_reference.py      # Blender 5.0.1: bumps_tiny_reference.exr
    <5.2.3 venv>/bin/python tests/data/make_reference.py  # bumps_tiny_reference_5.2.exr

Only after an intended change of the numerics (basis design, calibration, solve, bake
settings); the commit should say why the reference moved.
"""

import os
import sys
import tempfile

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="relight-ref-"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "blender"))

from reference_bake import bake_reference, reference_for  # noqa: E402

if __name__ == "__main__":
    import bpy

    texture = bake_reference()
    path = reference_for(bpy.app.version)  # 5.0.1's, or 5.2.3's for Blender 5.1 and later
    nbytes = texture.save(path, "half")
    print(f"wrote {path} ({nbytes} bytes) with Blender {bpy.app.version_string}")
