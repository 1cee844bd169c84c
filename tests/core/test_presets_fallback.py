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
    rows = json.loads((BAKES / filename).read_text(encoding="utf-8"))["presets"]
    assert _fallbacks(name) == {k: v["settings"] for k, v in rows.items()}
