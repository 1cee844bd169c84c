"""A bounded smoke of the bake-file fuzz harness (devtools/fuzz_bake_files.py; issue 56): real
bakes of the four kinds made by the real CLI, then damaged files and planted stages loaded as the
CLI loads them. Every case must end loaded (finite output) or refused in one line; no traceback,
hang, memory past 4 GiB or change outside the folder. ``make fuzz`` runs the same for an hour."""

import json
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_fuzz_smoke_every_case_is_loaded_or_refused_in_one_line(tmp_path):
    out = tmp_path / "fuzz.json"
    r = subprocess.run([sys.executable, str(ROOT / "devtools" / "fuzz_bake_files.py"),
                        "--bakes", str(tmp_path / "bakes"), "--cases", "80", "--seed", "56",
                        "--json", str(out)], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-4000:]
    counts = json.loads(out.read_text())
    assert counts["cases"] == 80 and counts["failure"] == 0, counts["failures"][:3]
    # the damage reached both outcomes: the harness is not loading untouched files only
    assert counts["refused"] >= 20 and counts["loaded"] >= 5, counts
