"""Every world is reached through its domain (`search.solvers.domain`): the solvers, the bundle builder and the
command line import no world's own modules, so a world can be added without editing them."""

from pathlib import Path

import search
from search.solvers.domain import BUILTIN, domain_for, domain_named, domains
from tests.support.imports import imported, package_modules

ROOT = Path(search.__file__).parent
WORLDS = ("search.crowd", "search.gym", "search.highway", "search.sim", "search.agents")
CALLERS = ("search.solvers.", "search.bundle.", "search.cli.")


def test_the_domain_interface_is_the_only_way_into_a_world():
    found = [
        f"{module} imports {name}"
        for module, path in package_modules(ROOT).items()
        if f"{module}.".startswith(CALLERS)
        for name in imported(path, "search", top_level_only=False)
        if name.startswith(WORLDS)
    ]
    assert found == []


def test_every_builtin_domain_is_installed_by_name_and_claims_its_own():
    assert [type(d).__name__ for d in domains()][: len(BUILTIN)] == [spec.partition(":")[2] for spec in BUILTIN]
    assert domain_named("highway") is domain_for(["highway-lo"]) and domain_for(["lo"]) is domain_named("crowd")
