"""The Flamenco job type (tools/flamenco) splits a bake into chunk tasks by the preset's
direction set, which it keeps in its own table: it must be the presets' (a stale count
leaves the missing directions to the final task, one machine). Its count of the directions the
bake adds under the horizon is checked by tests/blender/test_distributed.py (every chunk a
task of its own)."""

import json
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_flamenco_preset_direction_sets_are_the_presets():
    js = (ROOT / "tools" / "flamenco" / "relight_transport_bake.js").read_text()
    (table,) = re.findall(r"const PRESET_DIRECTIONS = \{([^}]*)\}", js)
    specs = dict(re.findall(r'(\w+):\s*"([^"]*)"', table))
    presets = json.loads((ROOT / "operators" / "bakes" / "transport_presets.json").read_text())["presets"]
    assert specs == {name: p["settings"]["directions"] for name, p in presets.items()}
