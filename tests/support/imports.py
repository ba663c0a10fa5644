"""A package's import graph read from its source (no module is imported): what the layer tests check."""

import ast
from pathlib import Path


def package_modules(root: Path) -> dict[str, Path]:
    """Every module under the package folder `root`, by dotted name."""
    return {
        ".".join(path.relative_to(root.parent).with_suffix("").parts).removesuffix(".__init__"): path
        for path in root.rglob("*.py")
    }


def imported(path: Path, package: str) -> set[str]:
    """The names from `package` that a module imports anywhere in it, inside functions and `if TYPE_CHECKING:` too
    (`from a.b import c` counts as `a.b` and `a.b.c`): an import deferred to a function still ties the modules
    together, only later."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return {name for name in found if name.split(".")[0] == package}


def upward_imports(root: Path, layer_of) -> list[str]:
    """`module imports name` for every import from a layer above the importing module's own."""
    upward = []
    for module, path in package_modules(root).items():
        own = layer_of(module)
        for name in imported(path, root.name):
            layer = layer_of(name)
            if own is not None and layer is not None and layer > own:
                upward.append(f"{module} imports {name}")
    return upward


def import_circles(root: Path) -> list[str]:
    """Circles among the modules' imports, those inside functions included, each as `a -> b -> a`."""
    modules = package_modules(root)
    graph = {m: {i for i in imported(p, root.name) if i in modules and i != m} for m, p in modules.items()}
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
    return circles
