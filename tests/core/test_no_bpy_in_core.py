"""lt_addon is the bpy-free core: no bpy/mathutils imports, relative imports inside the core.

Every module of every subpackage is checked (the walk recurses), so a new subpackage cannot
slip past the guard."""

import ast
import pathlib
import subprocess
import sys

import pytest

CORE = pathlib.Path(__file__).resolve().parents[2] / "lt_addon"
FORBIDDEN = {"bpy", "mathutils", "bmesh", "gpu", "bgl", "blf", "aud", "addon_utils"}
SOURCES = sorted(CORE.rglob("*.py"))
#: dotted module names below lt_addon, e.g. "steerable.basis" (packages by their __init__)
MODULES = sorted(".".join(p.relative_to(CORE).with_suffix("").parts).removesuffix(".__init__")
                 for p in SOURCES if p != CORE / "__init__.py")


def _imports(path):
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, 0
        elif isinstance(node, ast.ImportFrom):
            yield node.lineno, node.module or "", node.level


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(CORE)))
def test_no_blender_imports_in_source(path):
    # how many leading dots reach lt_addon itself from this file's package
    depth = len(path.relative_to(CORE).parts)
    for lineno, name, level in _imports(path):
        top = name.split(".")[0]
        assert level > 0 or top not in FORBIDDEN, f"{path.name}:{lineno} imports {name}"
        # inside the extension, the package itself is imported relatively only
        assert level > 0 or top != "relightable_textures", (
            f"{path.name}:{lineno}: absolute import of the package; use a relative import")
        # relative imports must stay inside the core (never ..operators or ..devtools)
        assert level <= depth, f"{path}:{lineno}: lt_addon must not import outside itself"


def test_the_walk_sees_every_subpackage():
    packages = {p.parent.name for p in CORE.glob("*/__init__.py")}
    assert packages == {"checks", "export", "geometry", "io", "rays", "sphere", "steerable",
                        "sun", "transport"}
    for pkg in packages:
        assert any(m.startswith(pkg + ".") for m in MODULES), pkg


def test_every_module_imports_without_bpy():
    assert {"steerable.basis", "sphere.hemisphere", "steerable.sampled_basis", "io.atomic",
            "transport.cpca", "checks.ashikhmin2002"} <= set(MODULES)
    code = ("import importlib, sys\n"
            f"for mod in {MODULES!r}:\n"
            "    importlib.import_module('relightable_textures.lt_addon.' + mod)\n"
            "bad = [m for m in ('bpy', 'mathutils') if m in sys.modules]\n"
            "assert not bad, bad\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
