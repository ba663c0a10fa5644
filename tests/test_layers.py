"""The offline side's layers import only downwards, and no module imports itself back through others: a
newcomer can read the layers bottom-up, and a change in a lower layer never needs an upper one. The worlds are
siblings on one layer: each imports the core, the solvers and the clip toolkit, and another world only where it
declares that world its parent (highway driving is a Gymnasium world)."""

from pathlib import Path

import search
from tests.support.imports import import_circles, imported, package_modules, upward_imports

LAYERS = ("core", "solvers", "clips", "worlds", "api", "bundle", "cli")
WORLDS = {"crowd": (), "gym": (), "highway": ("gym",)}  # each world and the parent worlds it may import
ROOT = Path(search.__file__).parent


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if len(parts) < 2:
        return None
    return LAYERS.index("worlds") if parts[1] in WORLDS else LAYERS.index(parts[1]) if parts[1] in LAYERS else None


def _world(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in WORLDS else None


def test_every_module_belongs_to_a_layer():
    assert [m for m in package_modules(ROOT) if m != "search" and _layer(m) is None] == []


def test_imports_point_down_the_layers():
    assert upward_imports(ROOT, _layer) == []


def test_a_world_imports_no_other_world_but_its_declared_parent():
    leaks = [
        f"{module} imports {name}"
        for module, path in package_modules(ROOT).items()
        if (own := _world(module))
        for name in imported(path, "search")
        if _world(name) not in (None, own, *WORLDS[own])
    ]
    assert leaks == []


def test_no_import_circles():
    assert import_circles(ROOT) == []


def test_the_architecture_page_names_every_module():
    """docs/architecture.md is where a reader finds what each module is for: every module of both sides is named
    there (as its file name, under its folder's entry)."""
    page = (ROOT.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    modules = [path for side in ("search", "app") for path in (ROOT.parent / side).rglob("*.py")]
    unnamed = [str(p.relative_to(ROOT.parent)) for p in modules if p.name != "__init__.py" and p.name not in page]
    assert modules and unnamed == []
