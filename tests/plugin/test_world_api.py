"""`search.api` is the one import a world's author needs: every name it lists resolves, each is one that the code
showing how to write a world or an adapter uses (so it gathers no more than they need), and the plugin world
imports nothing else of Foil's, so its code does not follow Foil's internal layout."""

import re
from pathlib import Path

import search.api
from tests.support.imports import imported

ROOT = Path(__file__).parents[2]
LINEWORLD = tuple((Path(__file__).parent / "lineworld" / "lineworld").glob("*.py"))
ADAPTERS = (
    ROOT / "tests" / "gym" / "corridor.py",
    ROOT / "tests" / "gym" / "test_gym_clips.py",
    ROOT / "tests" / "gym" / "test_visible_score.py",
    ROOT / "docs" / "examples" / "cartpole" / "cartpole_push.py",
)


GROUPS = ("ADAPTER_AUTHORS", "WORLD_AUTHORS", "METHOD_AUTHORS")


def test_every_listed_name_resolves_and_every_public_name_is_listed_in_a_group():
    assert [name for name in search.api.__all__ if not hasattr(search.api, name)] == []
    public = {name for name in vars(search.api) if not name.startswith("_")} - set(GROUPS)
    assert public == set(search.api.__all__)
    assert set().union(*(getattr(search.api, group) for group in GROUPS)) == public


def documented_imports(path: Path) -> set[str]:
    """The names a doc's code blocks import from search.api (``from search.api import A, B``)."""
    found = re.findall(r"^from search\.api import (.+)$", path.read_text(encoding="utf-8"), re.MULTILINE)
    return {f"search.api.{name.strip()}" for line in found for name in line.split(",")}


def test_every_name_is_used_by_a_world_an_adapter_or_the_world_authors_docs():
    used = set().union(*(imported(path, "search") for path in (*LINEWORLD, *ADAPTERS)))
    used |= documented_imports(ROOT / "docs" / "worlds.md")
    assert [name for name in search.api.__all__ if f"search.api.{name}" not in used] == []


def test_the_plugin_world_imports_nothing_of_foils_but_the_api():
    foil = set().union(*(imported(path, "search") | imported(path, "app") for path in LINEWORLD))
    assert sorted(name for name in foil if name.split(".")[:2] != ["search", "api"]) == []
