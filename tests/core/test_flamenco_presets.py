"""The Flamenco job type (tools/flamenco) splits a bake into chunk tasks by the preset's
direction count, which it keeps in its own table: it must be the presets' (a stale count
leaves the missing directions to the final task, one machine)."""

import json
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_flamenco_preset_direction_counts_are_the_presets():
    js = (ROOT / "tools" / "flamenco" / "relight_transport_bake.js").read_text()
    (table,) = re.findall(r"const PRESET_DIRECTIONS = \{([^}]*)\}", js)
    counts = {k: int(v) for k, v in re.findall(r"(\w+):\s*(\d+)", table)}
    presets = json.loads((ROOT / "operators" / "bakes" / "transport_presets.json").read_text())["presets"]
    assert counts == {name: int(p["settings"]["directions"].split(":")[1])
                      for name, p in presets.items()}
