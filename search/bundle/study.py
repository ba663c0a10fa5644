"""A study as every step of its build takes it, resolved once: the parsed `[build]` table, the one world its agents
are compared in (its Domain) and the world settings they bring. Before it, each step found the world again from the
agents and a scenario, and merged the settings its own way; here the world is found once, and one function
(`Study.world_settings`) says which settings win.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from app.visible import World
from search.bundle.spec import BuildError, BuildSpec, load_build
from search.core.domain import Domain, domain_for


@dataclass(frozen=True)
class Study:
    """A study file's build: its spec and text (copied into the bundle), its world, and ``world``: the settings
    its agents were trained in (a CrowdNav_DSRNN model's config), the world every agent is compared in, in the
    evaluation and in every search alike (`Domain.agents_settings`; none where the world has no such settings)."""

    spec: BuildSpec
    text: str
    domain: Domain
    world: dict[str, Any]

    @classmethod
    def of(cls, spec: BuildSpec, text: str = "") -> Study:
        """The study of a parsed spec: its world, found from its agents and its first scenario (an agent given as
        module:attribute may act in any world) and the world the study names, if it does; every scenario is in it
        (`search.bundle.spec` refuses a study whose scenarios are in different worlds)."""
        domain = domain_for(spec.agents, spec.sets[0].scenarios[0], spec.world)
        return cls(spec, text, domain, domain.agents_settings(spec.agents))

    @property
    def shows(self) -> World:
        """What the study's clips visibly show, and in which words: its world's, at its first scenario."""
        return self.domain.world(self.spec.sets[0].scenarios[0])

    @property
    def named(self) -> str | None:
        """The world the study names (``world = "..."`` in `[build]`), if it does: what its searches are told."""
        return self.spec.world

    def world_settings(self, scenario: str, scheme: dict[str, Any] | None = None) -> dict[str, Any]:
        """The world settings to run ``scenario`` (a fixed scenario or a distribution) under, the one precedence
        of the whole build, lowest first:

        1. the agents' settings (``world``: those they were trained in),
        2. the scenario file's own (`Domain.scenario_settings`: the world applies them when it loads the file, so
           the agents' settings it sets are left out here),
        3. the scheme's `[build.schemes.NAME.world]` table (``scheme``), for a search.

        The evaluation is the one step that takes ``world`` whole, not through this function: each agent is
        evaluated in the settings it was trained in."""
        own = self.domain.scenario_settings(scenario) if self.world else {}
        return {key: value for key, value in self.world.items() if key not in own} | (scheme or {})


def load_study(path: str | os.PathLike[str]) -> Study:
    """A study file's build (`search.bundle.spec.load_build`) with its world resolved; a study whose world cannot
    be found is refused as its `[build]` table."""
    spec, text = load_build(path)
    try:
        return Study.of(spec, text)
    except (ValueError, FileNotFoundError) as error:
        raise BuildError(f"{path}: [build]: {error}") from None
