"""The survey server's wings import only downwards: the shared files at the package's root, then storage, the
study, the analysis, the web side and the command line. No module imports itself back through others, not even
through an import deferred to a function, and the root stays small enough to read at a glance."""

from pathlib import Path

import app
from tests.support.imports import import_circles, upward_imports

WINGS = ("store", "survey", "analysis", "web", "cli")
ROOT = Path(app.__file__).parent


def _wing(module: str) -> int | None:
    """0 for the root's shared modules, then one level per wing, bottom-up."""
    parts = module.split(".")
    if len(parts) < 2:
        return None
    return WINGS.index(parts[1]) + 1 if parts[1] in WINGS else 0


def test_the_root_holds_at_most_six_modules():
    assert len(list(ROOT.glob("*.py"))) <= 6


def test_imports_point_down_the_wings():
    assert upward_imports(ROOT, _wing) == []


def test_no_import_circles():
    assert import_circles(ROOT) == []


def test_a_circle_closed_inside_a_function_is_a_circle(tmp_path):
    """A function-level import only delays the circle to the first call: the check must see it, as it did not
    when the analysis's power, preregistration and report imported each other that way."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "low.py").write_text("def pilot():\n    from pkg.high import tally\n\n    return tally()\n")
    (package / "high.py").write_text("from pkg.low import pilot\n\n\ndef tally():\n    return pilot\n")
    assert import_circles(package) == ["pkg.high -> pkg.low -> pkg.high"]
