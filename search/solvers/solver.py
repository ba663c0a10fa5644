"""The solvers of `foil search` behind one interface, found by name in one registry, so the runner, the study
file's parsing and the bundle builder ask a solver what it is instead of comparing names.

A solver runs in one of two ways: a `ProblemSearch` searches the coupled problem of one fixed scenario (MCTS,
N-first, random, cross-entropy) and its kept trajectories become the summaries, best first; an `OwnSummaries`
solver chooses its own summaries (the representative solver, the summary methods that watch agents play) and
writes a record of how under its own key of run.json. A new solver is one module that defines it and calls
`register`, named under the ``foil.solvers`` entry point group (name = "module"): Foil's own are registered there
in its pyproject.toml as a package's are in its own, and every one is imported when the registry is first read.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    import numpy as np

    from app.formats import ClipVote
    from search.core.domain import Domain
    from search.core.problem import Problem
    from search.core.rollout import Tracker
    from search.solvers.reward import RewardConfig

DEFAULT_SOLVER = "mcts"
ENTRY_POINTS = "foil.solvers"
Starts = Literal["fixed", "distribution", "either"]  # the scenarios a solver starts from


class Solver(ABC):
    """What the runner, the study file and the bundle builder need to know of a solver."""

    name: str
    config_class: type  # its settings, one frozen dataclass from the study file (or --set) to the search
    starts: Starts = "fixed"  # a fixed scenario, a distribution of starting states it draws from, or either
    reels: bool = False  # its clips are a reel of moments per agent, not one clip of the pair
    needs: tuple[type, ...] = ()  # the capabilities of the problem it uses (search.core.problem)
    rules: int = 1  # raised when the same settings choose differently, so a bundle's cached searches are redone
    # its votes read rollouts shared with a study's other searches of the same draws (a search.solvers.pool.Pool,
    # through `Comparison.pool`), and its settings have ``states``, ``pushes``, ``batch_states``, ``longest`` and
    # ``earlier`` (a clip from other states than the earlier ones of the same vote)
    pooled: bool = False

    def warnings(self, record: dict[str, Any]) -> list[str]:
        """What a search's run.json record warns of, in words: the runner, `foil search` and the bundle print
        these and read no solver's record themselves. Default: nothing."""
        return []

    def clip_vote(self, entry: dict[str, Any]) -> ClipVote | None:
        """The vote over starting states that a summary's solver entry records for its clip, each agent's count
        in the search's order (the bundle's audit holds it to the ground truth). Default: none."""
        return None

    def longest_clip(self, config: Any, horizon: int) -> int | None:
        """The most steps a clip of its search may last, for a reward of ``horizon`` steps (None: its clips are
        moments of episodes, never longer than one). Default: the horizon."""
        return horizon

    def clip_warnings(self, entry: dict[str, Any]) -> list[str]:
        """What a summary's solver entry warns of for its clip, in words, where the bundle logs each clip (a clip
        longer than the study's, say). Default: nothing."""
        return []

    def takes(self, distribution: bool) -> bool:
        """Whether it starts from a scenario of this kind (a distribution of starting states, or a fixed one)."""
        return self.starts == "either" or (self.starts == "distribution") == distribution

    def held_to_clip(
        self, config: Any, reward: RewardConfig, steps: int, given: dict[str, Any]
    ) -> tuple[Any, RewardConfig]:
        """Its settings and reward with each clip held to ``steps`` steps of video per question (a study's
        clip_seconds); ``given`` holds the settings the study gave ("settings", "reward"), refused where they say
        otherwise. By default a searched clip plays on to the reward's horizon."""
        return config, reward.with_horizon(held(given, "reward", "horizon", steps))


def held(given: dict[str, Any], table: str, key: str, value: int) -> int:
    """``value`` for the setting ``table.key`` that a clip length fixes, refusing a study that gave another."""
    if key in given[table] and given[table][key] != value:
        raise ValueError(f"[build.budget] clip_seconds makes {key} {value} steps here; leave {table}.{key} out")
    return value


@dataclass(frozen=True)
class ProblemSearch(Solver):
    """A search of the coupled problem of one fixed scenario: ``search(problem, tracker, rng, config)`` spends the
    tracker's budget and the tracker keeps the best trajectories."""

    name: str
    config_class: type
    search: Callable[[Problem, Tracker, np.random.Generator, Any], object]
    needs: tuple[type, ...] = ()

    def run(self, problem: Problem, tracker: Tracker, rng: np.random.Generator, config: Any) -> None:
        from search.core.problem import require

        require(problem, self.needs, self.name)
        self.search(problem, tracker, rng, config)


@dataclass(frozen=True)
class Comparison:
    """What a solver that chooses its own summaries starts from: the agents in their world (``domain``, a
    `search.core.domain.Domain`, which imports the solvers, so none of them imports it), the scenario, the
    settings, and the solver entry every summary carries."""

    agents: tuple[str, ...]
    scenario: str
    domain: Domain
    world_settings: dict[str, Any]
    reward_settings: dict[str, Any]
    entry: dict[str, Any] = field(default_factory=dict)
    pool: Any = None  # rollouts it shares with a study's other searches (a search.solvers.pool.Pool); None: its own

    def pair(self, solver: str, what: str) -> list[str]:
        """The two agents compared, refusing any other number."""
        if len(self.agents) != 2:
            raise ValueError(f"the {solver} {what}; got {len(self.agents)}")
        return list(self.agents)


class OwnSummaries(Solver):
    """A solver that chooses its own summaries, in its own order, and records how under ``record_key`` in
    run.json."""

    record_key: str

    @abstractmethod
    def choose(
        self, comparison: Comparison, tracker: Tracker, rng: np.random.Generator, config: Any
    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """The summaries, shown first first, and the record of how they were chosen."""


SOLVERS: dict[str, Solver] = {}  # by name; read it through `solvers`, which imports Foil's own first


def register(solver: Solver) -> Solver:
    """Add a solver to the registry under its name."""
    if SOLVERS.get(solver.name, solver) is not solver:
        raise ValueError(f"a solver named {solver.name!r} is registered already: give the new one another name")
    SOLVERS[solver.name] = solver
    return solver


def solvers() -> dict[str, Solver]:
    """Every registered solver by name: those of every installed ``foil.solvers`` entry point (Foil's own among
    them) and any registered since."""
    for entry in entry_points(group=ENTRY_POINTS):
        entry.load()
    return SOLVERS


def solver_named(name: str) -> Solver:
    found = solvers()
    if name not in found:
        raise ValueError(f"unknown solver {name!r}: use one of {sorted(found)}")
    return found[name]
