"""operators/ (the bpy layer) is arranged by role, and its imports run one way.

The rooms, lowest first (docs/architecture.md says what each holds):

    base < farm < preview < bakes < ui < cli      (registration.py, at the top, registers ui + cli)

A module may import from its own folder and from the folders before it, never from a folder
after it, and the module graph has no cycle (inside a folder either). Every import is read,
the ones inside functions too: a lazy import is still a dependency. The farm runs a bake's
chunks without importing the bake: each bake hands it its own chunk function.

Like test_no_bpy_in_core.py for the core, this reads the source (ast), so it needs no bpy."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
OPERATORS = ROOT / "operators"
#: The rooms of operators/, lowest first.
ORDER = ("base", "farm", "preview", "bakes", "ui", "cli")
#: Modules that live at operators/ itself: they sit above every room.
TOP = {"operators", "operators.registration"}


def _module(path: pathlib.Path, top: pathlib.Path) -> tuple:
    parts = path.relative_to(top).with_suffix("").parts
    return parts[:-1] if parts[-1] == "__init__" else parts


def _exists(top: pathlib.Path, parts) -> bool:
    return (top.joinpath(*parts).with_suffix(".py").is_file()
            or (top.joinpath(*parts) / "__init__.py").is_file())


def import_graph(root: pathlib.Path = OPERATORS) -> dict:
    """{module: {(imported module, line)}} over operators/, relative imports resolved (the
    extension imports itself relatively only). ``from . import x`` names the module x when it
    is one, else the package."""
    graph, top = {}, root.parent
    for path in sorted(root.rglob("*.py")):
        mod = _module(path, top)
        package = mod if path.name == "__init__.py" else mod[:-1]
        edges = graph.setdefault(".".join(mod), set())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or not node.level:
                continue
            base = package[:len(package) - (node.level - 1)]
            target = base + tuple(node.module.split(".") if node.module else ())
            for alias in node.names:
                sub = target + (alias.name,)
                edges.add((".".join(sub if _exists(top, sub) else target), node.lineno))
    return graph


def room(module: str):
    """The room of ``operators.<room>.<module>``; None outside operators/ or at its top."""
    parts = module.split(".")
    if module in TOP or parts[0] != "operators":
        return None
    return parts[1]


def upward_imports(graph: dict) -> list:
    """Imports from a room to a later one (or to the top), as 'a:line -> b'."""
    bad = []
    for a, edges in graph.items():
        ra = room(a)
        for b, line in sorted(edges):
            if not b.startswith("operators") or ra is None:
                continue
            rb = room(b)
            if rb is None or ORDER.index(rb) > ORDER.index(ra):
                bad.append(f"{a}:{line} -> {b}")
    return bad


def cycles(graph: dict) -> list:
    """The module graph's strongly connected components with more than one module (Tarjan)."""
    succ = {a: {b for b, _ in edges if b in graph and b != a} for a, edges in graph.items()}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in succ[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(succ):
        if v not in index:
            visit(v)
    return out


GRAPH = import_graph()


def test_every_module_lives_in_a_room():
    loose = [m for m in GRAPH if m not in TOP and room(m) not in ORDER]
    assert not loose, f"modules outside the rooms {ORDER}: {loose}"
    for name in ORDER:
        assert (OPERATORS / name / "__init__.py").is_file(), f"operators/{name}/ is missing"


def test_imports_run_one_way():
    assert not upward_imports(GRAPH), (
        f"imports against the order {' < '.join(ORDER)}:\n" + "\n".join(upward_imports(GRAPH)))


def test_no_import_cycles():
    assert not cycles(GRAPH), f"import cycles: {cycles(GRAPH)}"


def test_the_guard_sees_an_upward_import_and_a_cycle(tmp_path):
    """The checks can fail: a base module importing a bake, and two bakes importing each other
    (the cycle the texture and lobes bakes had before the layout change), are both caught."""
    fake = tmp_path / "operators"
    for room_name in ("base", "bakes"):
        (fake / room_name).mkdir(parents=True)
        (fake / room_name / "__init__.py").write_text("")
    (fake / "__init__.py").write_text("")
    (fake / "base" / "meshes.py").write_text("from ..bakes import lobes\n")
    (fake / "bakes" / "lobes.py").write_text("def f():\n    from .texture import KIND\n")
    (fake / "bakes" / "texture.py").write_text("from .lobes import f\n")
    graph = import_graph(fake)
    assert upward_imports(graph) == ["operators.base.meshes:1 -> operators.bakes.lobes"]
    assert cycles(graph) == [["operators.bakes.lobes", "operators.bakes.texture"]]


@pytest.mark.parametrize("name", ORDER)
def test_each_room_says_what_it_holds(name):
    """docs/architecture.md has a paragraph per room (the newcomer's map)."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    assert f"`operators/{name}/`" in text, f"docs/architecture.md does not describe {name}/"


def test_the_product_never_imports_the_development_tools():
    """devtools/ adds `relight bench` and the analysis charts through entry points
    (lt_addon/plugins.py); the product does not import it, not even under a try."""
    graph = {**GRAPH, **{k: v for k, v in import_graph(ROOT / "lt_addon").items()}}
    found = [f"{a}:{line}" for a, edges in graph.items() for b, line in edges
             if b.split(".")[0] == "devtools"]
    assert not found, f"imports of devtools/ in the product: {found}"


def test_a_dask_task_names_only_chunk_functions_of_this_package_s_bakes():
    """A worker imports the chunk function a task names (distributed._resolve): only one of
    this package's ``operators.bakes`` modules, never another module (issue 56)."""
    pytest.importorskip("bpy")
    from relightable_textures.operators.farm import distributed as d
    from relightable_textures.operators.bakes import texture_transport

    for bad in ("os:system", "subprocess:run", "relightable_textures.operators.bakes.x:a.b",
                "relightable_textures.operators.farm.distributed:_resolve"):
        with pytest.raises(ValueError, match="not a chunk function"):
            d._resolve(bad)
    stage = texture_transport.direct_chunk_cache
    assert d._resolve(d.stage_name(stage)) is stage
