"""The presets built into operators/bakes/presets.py (used only when the JSON files are missing,
e.g. a damaged install) are the files' own values: a bake without the file is the bake the docs
and the panel describe (before, draft had 100 directions built in against the file's 400)."""

import ast
import json
import pathlib

import pytest

BAKES = pathlib.Path(__file__).resolve().parents[2] / "operators" / "bakes"


def _fallbacks(name):
    tree = ast.parse((BAKES / "presets.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name
                                                for t in node.targets):
            table = node.value.args[2]
            return {ast.literal_eval(k): {kw.arg: ast.literal_eval(kw.value)
                                          for kw in v.keywords}
                    for k, v in zip(table.keys, table.values)}
    raise AssertionError(name)


@pytest.mark.parametrize("name, filename", [("LOBES", "presets.json"),
                                            ("TRANSPORT", "transport_presets.json")])
def test_the_built_in_presets_are_the_files(name, filename):
    """Every value a file states is built in alike; the built-ins may add what the file leaves
    out (the transport presets' own tol)."""
    rows = json.loads((BAKES / filename).read_text(encoding="utf-8"))["presets"]
    built = _fallbacks(name)
    assert set(built) == set(rows)
    for preset, row in rows.items():
        assert {k: built[preset].get(k) for k in row["settings"]} == row["settings"], preset
        assert set(built[preset]) - set(row["settings"]) <= {"tol"}, preset
