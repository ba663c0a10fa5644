"""The offline side's layers import only downwards, and no module imports itself back through others: a
newcomer can read the layers bottom-up, and a change in a lower layer never needs an upper one."""

import ast
from pathlib import Path

import search

LAYERS = ("sim", "agents", "solvers", "gym", "clips", "highway", "bundle", "cli")
ROOT = Path(search.__file__).parent


def _modules() -> dict[str, Path]:
    return {
        ".".join(path.relative_to(ROOT.parent).with_suffix("").parts).removesuffix(".__init__"): path
        for path in ROOT.rglob("*.py")
    }


def _imports(path: Path, top_level_only: bool) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = tree.body if top_level_only else ast.walk(tree)
    found = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return {name for name in found if name.split(".")[0] == "search"}


def _layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def test_every_module_belongs_to_a_layer():
    assert [m for m in _modules() if m != "search" and _layer(m) is None] == []


def test_imports_point_down_the_layers():
    upward = []
    for module, path in _modules().items():
        own = _layer(module)
        for imported in _imports(path, top_level_only=False):
            layer = _layer(imported)
            if own is not None and layer is not None and layer > own:
                upward.append(f"{module} imports {imported}")
    assert upward == []


def test_no_import_circles():
    modules = _modules()
    graph = {m: {i for i in _imports(p, top_level_only=True) if i in modules and i != m} for m, p in modules.items()}
    state: dict[str, int] = {}
    circles = []

    def visit(module: str, trail: list[str]) -> None:
        state[module] = 1
        for nxt in sorted(graph[module]):
            if state.get(nxt) == 1:
                circles.append(
                    " -> ".join(trail[trail.index(nxt) :] + [module, nxt]) if nxt in trail else f"{module} -> {nxt}"
                )
            elif nxt not in state:
                visit(nxt, trail + [module])
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [])
    assert circles == []
