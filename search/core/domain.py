"""The one way between Foil and a world: everything the command line, the solvers, the bundle builder and the
clips need from a world goes through a `Domain`, so none of them names a world.

A domain is a world's small interfaces together (`search.core.world`): its scenarios and settings, its agents, its
clips and the coupled problems a search steps (`Problems`, here); a world that trains agents of its own is a
`search.core.world.Trainer` too. Every world, Foil's own included, is installed through the entry point group
``foil.domains`` (name = "module:Class", pyproject.toml), and is found for a command by the names it ships, a file's
``world = "<name>"`` key and what each world claims (docs/worlds.md), never by the order worlds were installed in.
"""

from __future__ import annotations

import tomllib
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.visible import World
from search.core.evaluation import evaluation
from search.core.world import Agents, Claim, Clips, Scenarios, Shipped, Trainer

if TYPE_CHECKING:
    from search.core.contrast import Played, Seen

ENTRY_POINTS = "foil.domains"


@dataclass(frozen=True)
class Coupled:
    """A search's problem with what turns a kept trajectory into a summary, ``summarize(env_actions, solver)``,
    and the world its clips show. ``summarize`` also takes ``follow`` (a `search.solvers.follow.Follow`: the
    agents followed a leader), ``window`` (the steps a clip shows) and ``horizon`` (the reward's horizon, where
    the summary ends before the search's)."""

    problem: Any  # a search.core.problem.Problem
    scenario_name: str
    summarize: Callable[..., dict[str, Any]]
    world: World = World()


class Problems(ABC):
    """A world's coupled problems: the agents stepped side by side from one state, their summaries, the rollouts
    the representative solver scores, and the re-simulation ``foil verify`` compares a summary with."""

    # whether the coupled problems step all their rows at once (the crowd's simulator, the highway kernel): then the
    # summary methods play every group of episodes in this process; False: over worker processes (search.core.workers)
    batched = True

    @abstractmethod
    def takes_summary(self, summary: Mapping[str, Any]) -> Claim | None:
        """Whether a summary is this world's, by its scenario."""

    @abstractmethod
    def coupled(self, agents: Sequence[str], state: Any, reward: dict[str, Any]) -> Coupled:
        """The agents in one coupled problem from ``state``, scored by the divergence reward (its settings)."""

    def play_states(
        self, agents: Sequence[str], states: list[Any], reward: dict[str, Any], pushes: int, rng: np.random.Generator
    ) -> Played:
        """Every agent's rollouts for the representative solver and the representativeness check (see
        `search.solvers.representative`): from each state one without pushes and ``pushes`` under uniform
        pushes, all ``agents`` (two or more) in one coupled problem whose reward ends as ``finish = "last"``, each
        agent's clip read as it ended (`search.core.contrast.Played`). Default: through the coupled problem, each
        rollout's clip built as its summary (exact, at twice the steps)."""
        from search.core.contrast import play_problem

        return play_problem([self.coupled(agents, s, reward) for s in states], pushes, rng)

    def shown(
        self, coupled: Coupled, row: int, steps: int, since: int, summary: Callable[[], Mapping[str, Any]]
    ) -> float:
        """The visible contrast (`search.solvers.representative.visible_contrast`) of the clip of row ``row`` of a
        coupled problem that has taken ``steps`` steps, shown from the state after step ``since`` on: how the
        summary methods that fork (Agent Disagreements) score a fork. ``summary()`` builds the row's summary.
        Default: that summary's contrast (exact, at the cost of a replay); a world that can read it from its
        problem says so faster."""
        from search.core.contrast import summary_contrast

        return summary_contrast(dict(summary()), coupled.world)

    @abstractmethod
    def rebuild(self, summary: Mapping[str, Any]) -> Any:
        """The summary that the file's own inputs produce now (``foil verify`` compares it with the file)."""


class Domain(Scenarios, Agents, Problems, Clips):
    """A world Foil compares agents in. ``name`` goes into the manifest and is what a ``world = "..."`` key names;
    ``shipped()`` the agents', scenarios' and distributions' names it ships.

    A world writes its abstract methods (``Domain.__abstractmethods__``: its scenarios' states and step, its
    coupled problem, a summary's claim and rebuild, its clip, its test episodes); Foil gives every other method a
    default (docs/worlds.md)."""

    name: str = ""

    def shipped(self) -> Shipped:
        """The names this world ships. Default: none."""
        return Shipped()

    def shipped_scenarios(self) -> list[str]:
        """The names of the scenarios and distributions of starting states this world ships, which `foil worlds`
        lists. Default: none."""
        return []

    def describe_agents(self) -> str:
        """What agents and scenarios this world takes, for an error that refuses a mix. Default: the names it
        ships."""
        shipped = self.shipped()
        names = [*sorted(shipped.names), *(f"{prefix}..." for prefix in shipped.prefixes)]
        return f"the {self.name} world takes {', '.join(names) if names else 'the files it claims'}"

    def evaluate(
        self, agent: str, episodes: int, seed: int, world: dict[str, Any], scenario: str | None = None
    ) -> dict[str, Any]:
        """Default: `evaluate_episodes`' object without each episode's reward."""
        result = self.evaluate_episodes(agent, episodes, seed, world, scenario)
        return {key: value for key, value in result.items() if key != "episode_rewards"}

    def evaluate_episodes(
        self, agent: str, episodes: int, seed: int, world: dict[str, Any], scenario: str | None = None
    ) -> dict[str, Any]:
        """Default: computed by Foil from `play`'s episodes (`search.core.evaluation.evaluation`), with the visible
        score of the world's `World` where it declares one."""
        played = self.play(agent, episodes, seed, world, scenario)
        return evaluation(agent, seed, played, self.world(scenario).score, per_episode=True)

    def replay(
        self, agents: Sequence[str], state: Any, reward: dict[str, Any], actions: np.ndarray, entry: dict[str, Any]
    ) -> tuple[float, dict[str, Any]]:
        """A candidate trajectory's exact replay as a summary (solver entry ``entry``), and its clip's visible
        contrast."""
        from search.core.contrast import summary_contrast

        coupled = self.coupled(agents, state, reward)
        summary = coupled.summarize(actions, entry)
        return summary_contrast(summary, coupled.world), summary

    def replays(
        self,
        agents: Sequence[str],
        candidates: list[tuple[Any, np.ndarray]],
        reward: dict[str, Any],
        entry: dict[str, Any],
    ) -> list[tuple[float, dict[str, Any]]]:
        """Exact replays of candidate trajectories ``(state, env_actions)`` as summaries (solver entry ``entry``),
        each with its clip's visible contrast, in order: the representative solver's candidate clips. Over the
        worker processes where the world has no batched fast path (``batched``)."""
        if self.batched:
            return [self.replay(agents, state, reward, actions, entry) for state, actions in candidates]
        from search.core.workers import in_order

        return in_order(_replay_candidate, [(self.name, agents, s, reward, a, entry) for s, a in candidates])


@cache
def domains() -> tuple[Domain, ...]:
    """Every installed world, by name: one per ``foil.domains`` entry point (a package installed twice counts
    once)."""
    found: dict[str, Domain] = {}
    for entry in {entry.value: entry for entry in entry_points(group=ENTRY_POINTS)}.values():
        value, world_class = entry.value, entry.load()
        try:
            domain = world_class()
        except TypeError as error:  # a Domain without every method a world writes
            raise ValueError(
                f"the {ENTRY_POINTS} entry point {value!r} cannot be made: {error}: write the methods docs/worlds.md "
                'lists ("The methods a world writes")'
            ) from None
        if not isinstance(domain, Domain):
            raise ValueError(f"the {ENTRY_POINTS} entry point {value!r} is no search.core.domain.Domain")
        if domain.name in found:
            raise ValueError(f"two installed worlds are named {domain.name!r}: rename one ({value})")
        found[domain.name] = domain
    if not found:
        raise ValueError(f"no world is installed: reinstall Foil (pip install -e .), whose worlds are {ENTRY_POINTS}")
    return tuple(found[name] for name in sorted(found))


def domain_named(name: str) -> Domain:
    for domain in domains():
        if domain.name == name:
            return domain
    raise ValueError(f"no world {name!r}: the installed ones are {[d.name for d in domains()]}")


def named_world(path: str | Path) -> str | None:
    """The world a TOML file names itself with a ``world = "<name>"`` key, if it does."""
    path = Path(path)
    if path.suffix != ".toml" or not path.is_file():
        return None
    try:
        world = tomllib.loads(path.read_text(encoding="utf-8")).get("world")
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        return None  # its world's loader says what is wrong with it
    return world if isinstance(world, str) else None


def domain_for(agents: Sequence[str], scenario: str | None = None, world: str | None = None) -> Domain:
    """The one world the agents and the scenario belong to (the one ``world`` names, where given), or a clear error.
    Each is looked up among the names the worlds ship, then by a scenario file's ``world`` key, then by each
    world's claim on it; the world every one of them can be in wins, the one that owns one of them where several
    can."""
    found = {spec: _claims(spec, "agent") for spec in agents}
    if scenario is not None:
        found[f"scenario {scenario}"] = _claims(scenario, "scenario")
    if world is not None:
        named = domain_named(world)
        found["the study's world"] = {named: Claim.OWN}
    return _choose(found, "to the scenario file or to the study's [build] table")


def domain_of_summary(summary: Mapping[str, Any]) -> Domain:
    """The world that re-simulates and renders a summary."""
    claims = {d: c for d in domains() if (c := d.takes_summary(summary)) is not None}
    if not claims:
        raise ValueError("no installed world can re-simulate this summary: its scenario names no known world")
    return _choose({"the summary": claims}, "to its scenario file")


def trainer_for(path: Path) -> Trainer:
    """The world that trains from a config file or releases a run folder, by the config's ``world`` key or its
    content."""
    if not path.exists():
        raise FileNotFoundError(f"no training config or run folder at {str(path)!r}")
    trainers = [d for d in domains() if isinstance(d, Trainer)]
    named = named_world(path)
    if named is not None:
        domain = domain_named(named)
        if not isinstance(domain, Trainer):
            raise ValueError(
                f"the {named} world has no trainer of its own: train its agents with your own tools (the worlds "
                f"with one are {[d.name for d in trainers]})"
            )
        return domain
    claims: dict[Domain, Claim] = {d: c for d in trainers if (c := d.takes_training(path)) is not None}
    if not claims:
        raise ValueError(
            f'no installed world trains from {str(path)!r}: name its world with world = "<name>" (those with a '
            f"trainer are {[d.name for d in trainers]}; a world without one takes agents trained elsewhere)"
        )
    chosen = _choose({str(path): claims}, "to the config")
    assert isinstance(chosen, Trainer)
    return chosen


def _claims(name: str, kind: str) -> dict[Domain, Claim]:
    """The worlds that take an agent or a scenario, and how: the world that ships the name, else the one a file's
    ``world`` key names, else each world's claim on it."""
    installed = domains()
    shipping = [d for d in installed if name in d.shipped()]
    if len(shipping) > 1:
        raise ValueError(f"the worlds {[d.name for d in shipping]} all ship the name {name!r}: uninstall one")
    if shipping:
        return {shipping[0]: Claim.OWN}
    if kind == "scenario" and (named := named_world(name)) is not None:
        return {domain_named(named): Claim.OWN}
    claims = ((d, d.takes_agent(name) if kind == "agent" else d.takes_scenario(name)) for d in installed)
    return {d: claim for d, claim in claims if claim is not None}


def _choose(found: dict[str, dict[Domain, Claim]], where: str) -> Domain:
    """The one world all of ``found`` (what each item's worlds claim) can be in; an item no world claims goes with
    the others, whose world's loader says what is wrong with it. Where several worlds could take them, the error
    says which ``world`` key to add ``where``."""
    known = {item: claims for item, claims in found.items() if claims}
    if not known:
        worlds = "; ".join(d.describe_agents() for d in domains())
        raise ValueError(f"no installed world takes {', '.join(found)}: {worlds}")
    common = [d for d in domains() if all(d in claims for claims in known.values())]
    if not common:
        listing = ", ".join(f"{item} ({' or '.join(d.name for d in claims)})" for item, claims in known.items())
        worlds = "; ".join(d.describe_agents() for d in dict.fromkeys(d for c in known.values() for d in c))
        raise ValueError(f"cannot mix worlds: {listing}. {worlds}")
    owning = [d for d in common if any(claims[d] is Claim.OWN for claims in known.values())]
    if len(common) == 1 or len(owning) == 1:
        return common[0] if len(common) == 1 else owning[0]
    names = [d.name for d in owning or common]
    keys = " or ".join(f'world = "{name}"' for name in names)
    raise ValueError(f"{', '.join(known)} could be in the worlds {names}: say which, add {keys} {where}")


def play_spread(
    domain: str,
    agents: Sequence[str],
    states: list[Any],
    reward: dict[str, Any],
    pushes: int,
    rng: np.random.Generator,
    seen: Seen | None = None,
) -> Played:
    """`play_problem` of the world named ``domain``, the states over worker processes (search.core.workers):
    every state's pushes are drawn here, in order, as `play_problem` draws them, and each worker builds the
    coupled problem of its states from the world's name, so the rollouts are the same whatever the number of
    workers. ``seen`` must pickle (a module-level function)."""
    from search.core.contrast import Played, draw_pushes, play_problem
    from search.core.workers import in_order, workers

    coupled = [domain_named(domain).coupled(agents, state, reward) for state in states]
    if workers() <= 1 or len(states) < 2:
        return play_problem(coupled, pushes, rng, seen)
    envs = [draw_pushes(found.problem, pushes, rng) for found in coupled]
    done = in_order(
        _play_state, [(domain, agents, state, reward, env, seen) for state, env in zip(states, envs, strict=True)]
    )
    return Played.join([Played.of_state(index, *found) for index, found in enumerate(done)])


def _play_state(
    domain: str, agents: Sequence[str], state: Any, reward: dict[str, Any], env: np.ndarray, seen: Seen | None
) -> tuple[list[np.ndarray], np.ndarray, list[Any]]:
    from search.core.contrast import play_rows

    return play_rows(domain_named(domain).coupled(agents, state, reward), env, seen)


def _replay_candidate(world: str, *task: Any) -> tuple[float, dict[str, Any]]:
    """`Domain.replays`'s task in a worker: the world by its name."""
    return domain_named(world).replay(*task)
