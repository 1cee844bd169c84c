"""The documented defaults are the code's: the presets' settings and measured figures, the
default preset, direction set, GPU budget, indirect settings, sun size and output folders that
docs/transport-textures.md states, the lobes presets' table in docs/lobes.md and the default
values the tutorial's command-line overview shows.

The figures come from the presets files themselves (operators/bakes/transport_presets.json,
presets.json), merged over the built-in fallbacks of operators/bakes/presets.py as
:class:`Presets` merges them, then the settings dataclass's defaults. Panel and CLI defaults are
read from their source with ``ast`` (those modules import bpy): the panel's property defaults,
the CLI's --preset default, and the output-folder function that both the CLI
(``check_output_dir``) and the panel (``default_output_dir``) call, which runs here on its own.
A documented number must equal the code's value rounded to the digits the doc shows. No bpy,
well under a second.
"""

from __future__ import annotations

import ast
import dataclasses
import json
import os
import pathlib
import re

import pytest

from relightable_textures.lt_addon.transport import sparse_tables
from relightable_textures.lt_addon.transport.bundle import TransportTextureSettings

ROOT = pathlib.Path(__file__).resolve().parents[2]
BAKES = ROOT / "operators" / "bakes"
USER_PAGE = ROOT / "docs" / "transport-textures.md"
USER_PAGE_MAX_LINES = 250
PRESET_NAMES = ("draft", "balanced", "production")


# -- reading the docs ---------------------------------------------------------------------------

def section(path: pathlib.Path, heading: str) -> str:
    """The text under the Markdown heading ``heading`` (any level) up to the next heading of the
    same or a higher level."""
    lines = path.read_text(encoding="utf-8").split("\n")
    for i, line in enumerate(lines):
        m = re.match(r"^(#{1,6})\s+(.*?)\s*$", line)
        if m and m.group(2) == heading:
            level, out = len(m.group(1)), []
            for rest in lines[i + 1:]:
                n = re.match(r"^(#{1,6})\s", rest)
                if n and len(n.group(1)) <= level:
                    break
                out.append(rest)
            return "\n".join(out)
    raise AssertionError(f"{path.name} has no heading {heading!r}")


def table(text: str) -> list[dict]:
    """The first Markdown table in ``text``: one dict per row, keyed by the header cells."""
    rows = [line for line in text.split("\n") if line.startswith("|")]
    assert len(rows) >= 3, "no table found"
    cells = [[c.strip() for c in r.strip().strip("|").split("|")] for r in rows]
    header = cells[0]
    return [dict(zip(header, c)) for c in cells[2:]]


def by_first_column(rows: list[dict]) -> dict:
    """The rows by their first cell, emphasis (``**``) and '(default)' notes dropped, lowercase."""
    out = {}
    for row in rows:
        key = next(iter(row.values()))
        out[re.sub(r"\*|\(default\)", "", key).strip().lower()] = row
    return out


def number(cell: str) -> tuple[float, int]:
    """The first number in a table cell and its count of decimals."""
    m = re.search(r"-?\d+(?:\.(\d+))?", cell.replace(",", ""))
    assert m, f"no number in {cell!r}"
    return float(m.group(0)), len(m.group(1) or "")


def assert_shown(cell: str, value: float, what: str):
    """``cell``'s number is ``value`` rounded to the decimals the cell shows."""
    shown, decimals = number(cell)
    assert abs(shown - value) <= 0.5 * 10.0 ** -decimals + 1e-9, (
        f"{what}: the docs say {cell!r}, the code's value is {value}")


def code(cell: str) -> str:
    m = re.search(r"`([^`]+)`", cell)
    assert m, f"no `code` in {cell!r}"
    return m.group(1)


# -- reading the code ---------------------------------------------------------------------------

def _tree(path: pathlib.Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def fallbacks(name: str) -> dict:
    """The built-in preset values ``Presets(cls, file, {preset: dict(...)})`` of the module-level
    ``name`` in operators/bakes/presets.py (LOBES or TRANSPORT), as literals."""
    for node in _tree(BAKES / "presets.py").body:
        if (isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name
                                                 for t in node.targets)):
            table_node = node.value.args[2]
            return {ast.literal_eval(k): {kw.arg: ast.literal_eval(kw.value)
                                          for kw in v.keywords}
                    for k, v in zip(table_node.keys, table_node.values)}
    raise AssertionError(f"operators/bakes/presets.py defines no {name}")


def presets_file(filename: str) -> dict:
    with open(BAKES / filename, encoding="utf-8") as fh:
        return json.load(fh)["presets"]


def transport_settings(name: str) -> dict:
    """What a transport bake of preset ``name`` is given: the file's settings over the built-in
    fallback (as :class:`Presets` merges them), over the dataclass's defaults."""
    defaults = {f.name: f.default for f in dataclasses.fields(TransportTextureSettings)}
    return {**defaults, **fallbacks("TRANSPORT")[name],
            **presets_file("transport_presets.json")[name]["settings"]}


def lobes_settings(name: str) -> dict:
    return {**fallbacks("LOBES")[name], **presets_file("presets.json")[name]["settings"]}


def property_default(prop: str):
    """The ``default=`` literal of the panel property ``prop`` (``prop: XxxProperty(...)`` in
    operators/ui/*.py)."""
    found = []
    for path in sorted((ROOT / "operators" / "ui").glob("*.py")):
        for node in ast.walk(_tree(path)):
            # bpy declares a property as an annotation: ``prop: XxxProperty(default=...)``
            if (isinstance(node, ast.AnnAssign) and getattr(node.target, "id", None) == prop
                    and isinstance(node.annotation, ast.Call)):
                for kw in node.annotation.keywords:
                    if kw.arg == "default":
                        found.append(ast.literal_eval(kw.value))
    assert len(found) == 1, f"panel property {prop!r}: found defaults {found}"
    return found[0]


def cli_preset_defaults() -> set:
    """The ``default=`` of every ``add_argument("--preset", ...)`` of the CLI."""
    found = set()
    for path in sorted((ROOT / "operators" / "cli").glob("*.py")):
        for node in ast.walk(_tree(path)):
            if (isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument"
                    and node.args and isinstance(node.args[0], ast.Constant)
                    and node.args[0].value == "--preset"):
                found |= {ast.literal_eval(kw.value) for kw in node.keywords
                          if kw.arg == "default"}
    assert found, "no --preset option with a default in operators/cli"
    return found


def _function(module_path: pathlib.Path, name: str):
    """The module-level function ``name`` of ``module_path``, compiled on its own with ``os`` as
    its only global (the modules import bpy; these functions use ``os`` only)."""
    for node in _tree(module_path).body:
        if isinstance(node, ast.FunctionDef) and node.name == name:
            namespace = {"os": os}
            exec(compile(ast.Module([node], []), str(module_path), "exec"), namespace)
            return namespace[name]
    raise AssertionError(f"{module_path.relative_to(ROOT)} has no function {name}")


def _module_file(package_dir: pathlib.Path, module: str, level: int) -> pathlib.Path:
    """The file of ``from <level dots><module> import ...`` written in ``package_dir``."""
    base = package_dir
    for _ in range(level - 1):
        base = base.parent
    return base.joinpath(*module.split(".")).with_suffix(".py")


def output_folder_rule(path: pathlib.Path, caller: str):
    """The function that names the default output folder in ``caller`` of ``path``: the one it
    imports from this package and calls with the .blend's path, found with ``ast``."""
    fn = next(n for n in ast.walk(_tree(path))
              if isinstance(n, ast.FunctionDef) and n.name == caller)
    imports = {alias.asname or alias.name: (node.module, node.level)
               for node in ast.walk(fn) if isinstance(node, ast.ImportFrom)
               for alias in node.names}
    called = {n.func.id for n in ast.walk(fn)
              if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
    rules = sorted(name for name in called & set(imports) if "output" in name)
    assert len(rules) == 1, f"{path.name}:{caller} calls {sorted(called)}; no one output rule"
    module, level = imports[rules[0]]
    return rules[0], _function(_module_file(path.parent, module, level), rules[0])


# -- the tests ----------------------------------------------------------------------------------

def test_the_preset_table_holds_the_presets_settings():
    rows = by_first_column(table(section(USER_PAGE, "Choosing a preset")))
    assert set(rows) == set(PRESET_NAMES)
    for name in PRESET_NAMES:
        s, row = transport_settings(name), rows[name]
        side = s["horizon_resolution"] or min(s["resolution"], 1024)
        want = {"directions": f"`{s['directions']}`", "texture": f"{s['resolution']}²",
                "indirect grid": f"{s['indirect_resolution']}²",
                "horizons": f"{s['horizon_azimuths']} azimuths at {side}²",
                "PCA components": str(s["components"])}
        got = {k: row[k] for k in want}
        assert got == want, f"the {name} preset: the docs say {got}, the code {want}"


def test_the_measured_table_holds_the_presets_figures():
    rows = by_first_column(table(section(USER_PAGE,
                                         "What it costs and how close it gets (measured)")))
    assert set(rows) == set(PRESET_NAMES)
    for name in PRESET_NAMES:
        fig = presets_file("transport_presets.json")[name]["figures"]
        row = rows[name]
        assert_shown(row["bake"], fig["bake_seconds"], f"{name} bake seconds")
        assert_shown(row["× one 64-spp bake"], fig["single_bakes"], f"{name} single bakes")
        assert_shown(row["error, 0.526° Sun"], fig["rel_rmse_0526deg"], f"{name} error at 0.526°")
        assert_shown(row["error, 2° Sun"], fig["rel_rmse_2deg"], f"{name} error at 2°")
        assert_shown(row["error, 10° Sun"], fig["rel_rmse"], f"{name} error at 10°")
        assert_shown(row["T on disk"], fig["transport_bytes"] / 2 ** 20, f"{name} T MiB")
        assert_shown(row["preview GPU memory"], fig["viewport_gpu_mib"], f"{name} GPU MiB")
        assert_shown(row["peak memory"], fig["peak_mem_mb"], f"{name} peak MB")


def test_the_defaults_table_holds_the_codes_defaults(tmp_path):
    rows = by_first_column(table(section(USER_PAGE, "Defaults")))
    default = TransportTextureSettings()

    preset = rows["preset"]["default"].lower()
    assert cli_preset_defaults() == {preset}
    assert property_default("preset") == preset
    balanced = transport_settings(preset)

    directions = code(rows["direction set"]["default"])
    assert directions == default.directions == balanced["directions"]

    budget, _ = number(rows["gpu budget per object"]["default"])
    assert "MiB" in rows["gpu budget per object"]["default"]
    assert budget == default.gpu_budget == balanced["gpu_budget"] \
        == sparse_tables.DEFAULT_BUDGET_MIB

    assert number(rows["indirect rays per texel"]["default"])[0] == balanced["indirect_rays"]
    assert number(rows["indirect components"]["default"])[0] \
        == balanced["indirect_components"]

    # the bake's own default: -1, the scene's (operators/base/scene_sun.py); the panel's
    # Scene's Sun (on) gives the bake -1 and the preview the same size
    from relightable_textures.operators.base.scene_sun import DEFAULT_SUN_ANGLE
    assert balanced["sun_angle"] == -1 and balanced["bounces"] == -1
    assert property_default("scene_sun_size") is True
    row = rows["sun size of the bake, its truths and the preview"]
    truths = row["default"]
    assert "scene's Sun" in truths and "0.526°" in truths
    assert f"{DEFAULT_SUN_ANGLE:g}° without a Sun" in truths
    assert "*Scene's Sun*" in row["where to change it"]
    assert "scene's own" in rows["diffuse bounces"]["default"]
    assert rows["texel sampling"]["default"] == default.texel_sampling

    # one folder for the CLI and the panel: <name>_relight/ next to the .blend
    rule = rows["output folder"]["default"]
    assert "next to the .blend" in rule
    name, cli_rule = output_folder_rule(ROOT / "operators" / "cli" / "common.py",
                                        "check_output_dir")
    panel_name, panel_rule = output_folder_rule(ROOT / "operators" / "ui" / "bake_ops.py",
                                                "default_output_dir")
    assert panel_name == name, f"the panel names its folder by {panel_name}, the CLI by {name}"
    assert property_default("output_dir") == "", "the panel's Output field is not empty"
    folder = code(rule).replace("<name>", "scene").rstrip("/")
    assert cli_rule(str(tmp_path / "scene.blend")) == str(tmp_path / folder)
    # an unsaved file (the panel's): ~/relight/untitled-<date-time>_relight/
    unsaved = code(rows["output folder of an unsaved file"]["default"])
    home = tmp_path / "home"
    want = unsaved.replace("~", str(home)).replace("<date-time>", "20261206-031500").rstrip("/")
    assert cli_rule("", home=str(home), stamp="20261206-031500") == want


def test_the_tutorials_command_line_shows_the_default_values():
    block = section(ROOT / "docs" / "tutorial.md", "Command line")
    commands = re.split(r"\n(?=relight |blender )", block)
    transport = next(c for c in commands if c.startswith("relight bake-textures")
                     and "--method lobes" not in c)
    lobes = next(c for c in commands if c.startswith("relight bake-textures")
                 and "--method lobes" in c)
    balanced_t, balanced_l = transport_settings("balanced"), lobes_settings("balanced")
    checked = 0
    for text, settings in ((transport, balanced_t), (lobes, balanced_l)):
        for opt, value in re.findall(r"\[--([a-z-]+) ([^\s\]|]+)\]", text):
            key = opt.replace("-", "_")
            if key not in settings:
                continue
            want = settings[key]
            got = type(want)(value) if isinstance(want, (int, float)) else value
            assert got == want, (f"docs/tutorial.md shows --{opt} {value}; the default "
                                 f"(balanced preset) is {want}")
            checked += 1
    assert checked >= 8, f"only {checked} default values found in the tutorial's overview"


def test_the_lobes_preset_table_holds_the_presets():
    rows = by_first_column(table(section(
        ROOT / "docs" / "lobes.md",
        "Steerable illumination textures (Ashikhmin & Shirley 2002): `--method lobes`")))
    assert set(rows) == set(PRESET_NAMES)
    for name in PRESET_NAMES:
        s = lobes_settings(name)
        fig = presets_file("presets.json")[name]["figures"]
        assert rows[name]["settings"] == (f"N1 {s['order']}, {s['resolution']}², "
                                          f"{s['samples']} spp, {s['bounces']} bounces, "
                                          f"{s['storage']}"), name
        assert_shown(rows[name]["bake"], fig["bake_seconds"], f"lobes {name} bake")
        assert_shown(rows[name]["rel. RMSE"], fig["rel_rmse"], f"lobes {name} error")


def test_the_user_page_stays_a_user_page():
    text = USER_PAGE.read_text(encoding="utf-8")
    n = len(text.splitlines())
    assert n <= USER_PAGE_MAX_LINES, (
        f"docs/transport-textures.md has {n} lines (at most {USER_PAGE_MAX_LINES}): "
        "measurements go to docs/bench/ as dated records")
    for pattern, what in ((r"\b20\d\d-\d\d-\d\d\b", "a date"),
                          (r"\b\d{1,2}:\d\d\b", "a clock time"),
                          (r"\b[Ii]ssues? \d+", "an issue number"),
                          (r"(?<![`\w])(I|we|We|our|Our)\b(?!['’]s)", "a first-person note")):
        m = re.search(pattern, text)
        assert not m, (f"docs/transport-textures.md holds {what}: "
                       f"{text[max(0, m.start() - 40):m.end() + 40]!r}; dated measurements "
                       "go to docs/bench/")


@pytest.mark.parametrize("cell, value, ok", [("6.6 s", 6.57, True), ("6.5 s", 6.57, False),
                                             ("0.020", 0.0199, True), ("50 MiB", 50.0001, True),
                                             ("**0.039**", 0.0393, True), ("0.04", 0.0393, True),
                                             ("0.038", 0.0393, False)])
def test_a_shown_number_is_the_value_rounded_to_its_digits(cell, value, ok):
    if ok:
        assert_shown(cell, value, "x")
    else:
        with pytest.raises(AssertionError):
            assert_shown(cell, value, "x")
