"""Regenerate the stored reference bake used by tests/blender/test_reference_bake.py.

    .venv/bin/python tests/data/make_reference.py

Only after an intended change of the numerics (basis design, calibration, solve, bake
settings); the commit should say why the reference moved.
"""

import os
import sys
import tempfile

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="relight-ref-"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "blender"))

from reference_bake import REFERENCE, bake_reference  # noqa: E402

if __name__ == "__main__":
    texture = bake_reference()
    nbytes = texture.save(REFERENCE, "half")
    print(f"wrote {REFERENCE} ({nbytes} bytes)")
