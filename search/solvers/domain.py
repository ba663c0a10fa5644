"""The one interface between Foil and a world: everything the command line, the solvers, the bundle builder and
the clips need from a world goes through a `Domain`, so none of them names a world.

A domain recognises its agents and scenarios, loads scenarios and distributions of starting states, builds the
coupled problem and its summaries (and re-simulates them for ``foil verify``), evaluates an agent, says where an
agent came from, renders a clip, and says what a clip visibly shows and in which words (``app.visible.World``).

Foil's own domains are listed in ``BUILTIN``; a package adds one without editing Foil through the entry point
group ``foil.domains`` (name = "module:Class"). A Gymnasium environment needs no domain of its own: its scenario
file names an adapter, and the Gymnasium domain takes it from there (docs/gym.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from importlib import import_module
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.visible import World

if TYPE_CHECKING:
    from search.solvers.representative import Rollouts
    from search.solvers.rollout import Tracker

ENTRY_POINTS = "foil.domains"
# Foil's own domains, most specific first: the first that claims an agent or scenario owns it.
BUILTIN = (
    "search.highway.domain:HighwayDomain",
    "search.gym.domain:GymDomain",
    "search.crowd.domain:CrowdDomain",
)


@dataclass(frozen=True)
class Coupled:
    """A search's problem with what turns a kept trajectory into a summary, ``summarize(env_actions, solver)``,
    and the world its clips show. ``summarize`` also takes ``follow`` (a `search.solvers.follow.Follow`: the
    agents followed a leader), ``window`` (the steps a clip shows) and ``horizon`` (the reward's horizon, where
    the summary ends before the search's)."""

    problem: Any  # a search.solvers.problem.Problem
    scenario_name: str
    summarize: Callable[..., dict]
    world: World = World()


class Domain(ABC):
    """A world Foil compares agents in. ``name`` goes into the manifest; a state is whatever the domain uses as
    one concrete starting state (it has a ``name`` and a ``to_dict()``)."""

    name: str = ""
    default_distribution: str | None = None  # what a study's fixed scenarios are checked against by default
    time_limit_setting: str | None = None  # the world setting `foil eval --time-limit` sets, where there is one

    # recognising agents, scenarios and summaries
    @abstractmethod
    def claims_agent(self, spec: str) -> bool | None:
        """True for an agent of this world, False for another's, None for one that may act in any world."""

    @abstractmethod
    def claims_scenario(self, name: str) -> bool: ...

    @abstractmethod
    def claims_summary(self, summary: Mapping[str, Any]) -> bool: ...

    @abstractmethod
    def describe_agents(self) -> str:
        """What agents and scenarios this world takes, for an error that refuses a mix."""

    # settings and scenarios
    @abstractmethod
    def parse_world(self, items: list[str]) -> dict:
        """``--world key=value`` settings, each converted to its type."""

    @abstractmethod
    def check_world(self, settings: dict, what: str) -> dict:
        """A study's world settings checked (a clear error for an unknown key or a bad value)."""

    def study_world(self, agents: Sequence[str]) -> dict:
        """The world settings the agents bring (a trained world), shared by a whole study. Default: none."""
        return {}

    def own_world(self, scenario: str) -> dict:
        """The world settings a scenario file sets itself (they win over a study's). Default: none."""
        return {}

    def comparison_world(self, agents: Sequence[str], world: dict, scenario: str) -> dict:
        """The world settings a search runs in, from the agents' trained world, the scenario's and ``world``."""
        return dict(world)

    @abstractmethod
    def is_distribution(self, name: str) -> bool:
        """Whether ``name`` is a distribution of starting states (for the representative solver)."""

    @abstractmethod
    def scenario_dict(self, name: str, world: dict) -> dict:
        """The scenario or distribution ``name`` under ``world``, complete (every default written in)."""

    @abstractmethod
    def step_seconds(self, name: str, world: dict) -> float:
        """Simulated seconds per step in scenario or distribution ``name`` under ``world``: how a study's seconds of
        clip become steps."""

    @abstractmethod
    def state(self, name: str, world: dict) -> Any:
        """The fixed scenario ``name`` under ``world``, complete."""

    @abstractmethod
    def draw_states(self, name: str, world: dict, rng: np.random.Generator, count: int) -> list:
        """``count`` starting states drawn from distribution ``name`` under ``world``, each named ``name#i``."""

    # searching and summaries
    @abstractmethod
    def coupled(self, agents: Sequence[str], state: Any, reward: dict) -> Coupled:
        """The agents in one coupled problem from ``state``, scored by the divergence reward (its settings)."""

    def roll_out(
        self,
        agents: Sequence[str],
        states: list,
        reward: dict,
        pushes: int,
        rng: np.random.Generator,
        tracker: Tracker,
    ) -> Rollouts:
        """The representative solver's rollouts (see `search.solvers.representative`): from each state one
        without pushes and ``pushes`` under uniform pushes, each scored by what its clip visibly shows. Default:
        through the coupled problem, each rollout's clip built as its summary (exact, at twice the steps)."""
        from search.solvers.representative import roll_out_problem

        return roll_out_problem([self.coupled(agents, s, reward) for s in states], pushes, rng, tracker)

    def shown(
        self, coupled: Coupled, row: int, steps: int, since: int, summary: Callable[[], Mapping[str, Any]]
    ) -> float:
        """The visible contrast (`search.solvers.representative.visible_contrast`) of the clip of row ``row`` of a
        coupled problem that has taken ``steps`` steps, shown from the state after step ``since`` on: how the
        summary methods that fork (Agent Disagreements) score a fork. ``summary()`` builds the row's summary.
        Default: that summary's contrast (exact, at the cost of a replay); a domain that can read it from its
        problem says so faster."""
        from search.solvers.representative import summary_contrast

        return summary_contrast(dict(summary()), coupled.world)

    @abstractmethod
    def rebuild(self, summary: Mapping[str, Any]) -> Any:
        """The summary that the file's own inputs produce now (``foil verify`` compares it with the file)."""

    # agents
    @abstractmethod
    def evaluate(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> dict:
        """The agent's ``foil eval --json`` object (success, collision, timeout rates, mean reward and its 95%
        interval), in ``scenario``'s world when given."""

    def evaluate_episodes(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> dict:
        """``evaluate``'s object with each episode's reward (``episode_rewards``; episode i starts alike for every
        agent at one seed), so the bundle compares two agents episode by episode (search/bundle/truth.py). Default:
        without them, and the bundle compares mean rewards alone."""
        return self.evaluate(agent, episodes, seed, world, scenario)

    @abstractmethod
    def describe_evaluation(self, result: dict) -> str:
        """``foil eval``'s lines for a person (``--json`` prints the object itself)."""

    def eval_scenario(self, scenarios: Sequence[str]) -> str | None:
        """Which of a study's scenarios an agent is evaluated in (None: the domain's own test episodes)."""
        return None

    @abstractmethod
    def agent_file(self, agent: str) -> Path | None:
        """The file an agent is loaded from (its checksum identifies it), or None for a scripted one."""

    @abstractmethod
    def agent_source(self, agent: str, world: dict) -> dict:
        """Where an agent came from, for the manifest."""

    # training and releasing the world's own agents
    def claims_training(self, path: Path) -> bool:
        """Whether a training config file or a training run's folder is this world's."""
        return False

    def train(self, config: Path, out: Path) -> Path:
        """``foil train``: train from a config file into ``out``; the last checkpoint."""
        raise ValueError(f"the {self.name} world has no trainer of its own: train agents with your own tools")

    def release(self, run_dir: Path, out: Path | None, episodes: int, every: int, jobs: int) -> dict:
        """``foil release``: choose the shipped agents from a run and write them with their model cards."""
        raise ValueError(f"the {self.name} world ships no agents of its own")

    def validate_run(self, run_dir: Path, episodes: int, every: int) -> None:
        """``foil release --validate-only``: print the run's validation curve."""
        raise ValueError(f"the {self.name} world ships no agents of its own")

    # clips
    @abstractmethod
    def render(self, summary: Path, out: Path, numbers: list[int], options: Any) -> Any:
        """``foil render``: the clip, its poster and its contact sheet (a `search.clips.render.RenderResult`)."""

    @abstractmethod
    def renderer_files(self, summary: Path) -> list[Path]:
        """The source files a clip of ``summary`` is drawn by (part of a rendered clip's cache key)."""

    def world(self, scenario: str | None = None) -> World:
        """What a clip visibly shows here and in which words; default the crowd's."""
        return World()


@cache
def domains() -> tuple[Domain, ...]:
    """Every installed domain: Foil's own, then those of the ``foil.domains`` entry points."""
    specs = list(BUILTIN) + [entry.value for entry in entry_points(group=ENTRY_POINTS)]
    found = []
    for spec in dict.fromkeys(specs):
        module, _, name = spec.partition(":")
        found.append(getattr(import_module(module), name)())
    return tuple(found)


def domain_named(name: str) -> Domain:
    for domain in domains():
        if domain.name == name:
            return domain
    raise ValueError(f"no domain {name!r}: the installed ones are {[d.name for d in domains()]}")


def domain_for(agents: Sequence[str], scenario: str | None = None) -> Domain:
    """The one world the agents (and the scenario) belong to, or a clear error; agents that may act anywhere
    (``module:attribute``) go with the others, or with the last domain (the crowd) when alone."""
    installed = domains()
    found: dict[str, Domain | None] = {}
    for spec in agents:
        claims = [d.claims_agent(spec) for d in installed]
        found[spec] = next((d for d, c in zip(installed, claims, strict=True) if c), None)
    if scenario is not None:
        found[f"scenario {scenario}"] = next((d for d in installed if d.claims_scenario(scenario)), installed[-1])
    kinds = list(dict.fromkeys(d for d in found.values() if d is not None))
    if len(kinds) > 1:
        kinds = _narrowest(kinds, found)
    if len(kinds) > 1:
        listing = ", ".join(f"{name} ({d.name if d else 'any'})" for name, d in found.items())
        worlds = "; ".join(d.describe_agents() for d in kinds)
        raise ValueError(f"cannot mix worlds: {listing}. {worlds}")
    return kinds[0] if kinds else installed[-1]


def _narrowest(kinds: list[Domain], found: dict[str, Domain | None]) -> list[Domain]:
    """Where one domain is a kind of another (highway driving is a Gymnasium world), the narrower one takes
    everything the wider one claimed that the narrower accepts too."""
    narrow = [d for d in kinds if any(isinstance(d, type(o)) and d is not o for o in kinds)]
    if len(narrow) != 1:
        return kinds
    keep = narrow[0]
    return [keep] + [d for d in kinds if not isinstance(keep, type(d)) and d is not keep]


def domain_of_training(path: Path) -> Domain:
    """The world a training config or run folder belongs to (the last domain, the crowd, by default)."""
    installed = domains()
    return next((d for d in installed if d.claims_training(Path(path))), installed[-1])


def domain_of_summary(summary: Mapping[str, Any]) -> Domain:
    for domain in domains():
        if domain.claims_summary(summary):
            return domain
    raise ValueError("no installed domain can re-simulate this summary: its scenario names no known world")
