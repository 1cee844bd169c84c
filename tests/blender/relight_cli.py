"""Run the venv's real ``relight`` console script in a subprocess (shared by the CLI tests)."""

import pathlib
import subprocess
import sys

BIN = pathlib.Path(sys.executable).parent


def relight(*args, cwd=None):
    return subprocess.run([str(BIN / "relight"), *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=600)
