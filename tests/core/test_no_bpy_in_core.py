"""lt_addon is the bpy-free core: no bpy/mathutils imports, relative imports of the package."""

import ast
import pathlib
import subprocess
import sys

import pytest

CORE = pathlib.Path(__file__).resolve().parents[2] / "lt_addon"
FORBIDDEN = {"bpy", "mathutils", "bmesh", "gpu", "bgl", "blf", "aud", "addon_utils"}
MODULES = sorted(p.stem for p in CORE.glob("*.py") if p.stem != "__init__")


def _imports(path):
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, 0
        elif isinstance(node, ast.ImportFrom):
            yield node.lineno, node.module or "", node.level


@pytest.mark.parametrize("path", sorted(CORE.glob("*.py")), ids=lambda p: p.name)
def test_no_blender_imports_in_source(path):
    for lineno, name, level in _imports(path):
        top = name.split(".")[0]
        assert level > 0 or top not in FORBIDDEN, f"{path.name}:{lineno} imports {name}"
        # inside the extension, the package itself is imported relatively only
        assert level > 0 or top != "relightable_textures", (
            f"{path.name}:{lineno}: absolute import of the package; use a relative import")
        if level > 0:  # relative imports must stay inside the core (never ..operators)
            assert level == 1, f"{path.name}:{lineno}: lt_addon must not import outside itself"


def test_every_module_imports_without_bpy():
    assert {"steerable", "hemisphere", "sampled_basis", "calibration", "storage", "clamp",
            "interp_baseline", "paper_checks"} <= set(MODULES)
    for mod in MODULES:
        code = (f"import relightable_textures.lt_addon.{mod}; import sys; "
                "bad = [m for m in ('bpy', 'mathutils') if m in sys.modules]; "
                "assert not bad, bad")
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=60)
        assert proc.returncode == 0, f"{mod}: {proc.stderr[-2000:]}"
