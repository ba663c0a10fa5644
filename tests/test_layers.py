"""The offline side's layers import only downwards, and no module imports itself back through others: a
newcomer can read the layers bottom-up, and a change in a lower layer never needs an upper one."""

from pathlib import Path

import search
from tests.support.imports import import_circles, package_modules, upward_imports

LAYERS = ("core", "sim", "agents", "solvers", "clips", "crowd", "gym", "highway", "bundle", "cli")
ROOT = Path(search.__file__).parent


def _layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def test_every_module_belongs_to_a_layer():
    assert [m for m in package_modules(ROOT) if m != "search" and _layer(m) is None] == []


def test_imports_point_down_the_layers():
    assert upward_imports(ROOT, _layer) == []


def test_no_import_circles():
    assert import_circles(ROOT) == []
