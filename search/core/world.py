"""What a world offers Foil, one small interface per concept, so nothing outside a world needs to know which world
it is: its `Scenarios` (and settings), its `Agents`, its `Clips` and, where it trains agents of its own, a
`Trainer`. The coupled problems a search steps are the fourth concept, `search.core.domain.Problems`: their
default rollouts are the solvers' own. A world is all of them together (`search.core.domain.Domain`).

Each interface says whether a world takes a name, a file or a folder as a `Claim`: Foil finds a world by the names
it ships, a file's ``world = "<name>"`` key and these claims, never by the order worlds were installed in."""

from __future__ import annotations

import inspect
import re
import tomllib
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from app.formats import sha256_file
from app.visible import World
from search.core.evaluation import Episode, describe
from search.core.settings import check_keys


class Claim(Enum):
    """How a world takes something (no claim: ``None``)."""

    OWN = "own"  # its own kind: a file type only it reads, content only it writes
    ALSO = "also"  # it can take it as other worlds can (a ``module:attribute`` agent, any Gymnasium file)


@dataclass(frozen=True)
class Shipped:
    """The names a world ships (agents, scenarios, distributions): exact names and name prefixes. No two installed
    worlds may ship the same name."""

    names: frozenset[str] = frozenset()
    prefixes: tuple[str, ...] = ()

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and (name in self.names or name.startswith(self.prefixes))


def is_module_attribute(spec: str) -> bool:
    """Whether an agent is given as ``module:attribute`` (an object in an importable module), not as a file."""
    return re.fullmatch(r"[A-Za-z_][\w.]*:[A-Za-z_][\w.]*", spec) is not None


class Scenarios(ABC):
    """A world's scenarios (fixed starting states), distributions of starting states and world settings."""

    default_distribution: str | None = None  # what a study's fixed scenarios are checked against by default
    episode_seconds_setting: str | None = None  # the setting `foil eval --time-limit` sets, where one sets it
    # the world settings it takes (``--world key=value``, a study's [build.world]), each with its default, whose
    # type a given value must have (a whole number is taken for a float)
    settings: ClassVar[Mapping[str, Any]] = {}

    def takes_scenario(self, name: str) -> Claim | None:
        """Whether a scenario or distribution file is this world's, by its content (shipped names and a file's
        ``world`` key are looked up before). Default: none is."""
        return None

    def parse_world(self, items: list[str]) -> dict[str, Any]:
        """``--world key=value`` settings, each converted to its type. Default: each value read as a TOML value
        (a bare word as text), then checked by `check_world`."""
        parsed = {}
        for item in items:
            key, equals, value = item.partition("=")
            if not equals:
                raise ValueError(f"--world {item!r}: give key=value")
            try:
                parsed[key.strip()] = tomllib.loads(f"v = {value}")["v"]
            except tomllib.TOMLDecodeError:
                parsed[key.strip()] = value
        return self.check_world(parsed, "--world")

    def check_world(self, settings: dict[str, Any], what: str) -> dict[str, Any]:
        """A study's world settings checked (a clear error for an unknown key or a bad value). Default: the keys
        of `settings` (the class's), each given in its default's type."""
        check_keys(settings, type(self).settings, f"{what} setting")
        checked = dict(settings)
        for key, value in settings.items():
            default = type(self).settings[key]
            if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
                checked[key] = float(value)
            elif type(value) is not type(default):
                raise ValueError(
                    f"{what} setting {key} = {value!r}: give a {type(default).__name__}, such as {default!r}"
                )
        return checked

    def agents_settings(self, agents: Sequence[str]) -> dict[str, Any]:
        """The world settings the agents bring (those they were trained in), shared by a whole study. Default:
        none."""
        return {}

    def scenario_settings(self, scenario: str) -> dict[str, Any]:
        """The world settings a scenario file sets itself (they win over a study's). Default: none."""
        return {}

    def search_settings(self, agents: Sequence[str], settings: dict[str, Any], scenario: str) -> dict[str, Any]:
        """The world settings a search runs in, from the agents', the scenario's and the given ``settings``.
        Default: those given."""
        return dict(settings)

    def is_distribution(self, name: str) -> bool:
        """Whether ``name`` is a distribution of starting states (for the representative solver). Default: a
        world without distributions."""
        return False

    def scenario_dict(self, name: str, world: dict[str, Any]) -> dict[str, Any]:
        """The scenario or distribution ``name`` under ``world``, complete (every default written in). Default:
        its state's ``to_dict()``."""
        found: dict[str, Any] = self.state(name, world).to_dict()
        return found

    @abstractmethod
    def step_seconds(self, name: str, world: dict[str, Any]) -> float:
        """Simulated seconds per step in scenario or distribution ``name`` under ``world``: how a study's seconds of
        clip become steps."""

    def episode_seconds(self, name: str, world: dict[str, Any]) -> float | None:
        """The longest an episode of scenario or distribution ``name`` lasts under ``world``, in seconds: no
        searched clip is longer. Default: None, no limit known."""
        return None

    @abstractmethod
    def state(self, name: str, world: dict[str, Any]) -> Any:
        """The fixed scenario ``name`` under ``world``, complete: a state with a ``name`` and a ``to_dict()``."""

    def draw_states(self, name: str, world: dict[str, Any], rng: np.random.Generator, count: int) -> list[Any]:
        """``count`` starting states drawn from distribution ``name`` under ``world``, each named ``name#i``.
        Default: a world without distributions refuses."""
        raise ValueError(
            f"{name!r} is no distribution of starting states here: this world has none (a world with them writes "
            "is_distribution and draw_states)"
        )


class Agents(ABC):
    """A world's agents: which it takes, how they do, and where they came from. A world plays test episodes
    (`play`) and Foil computes the evaluation from them; a world with an evaluation of its own (more keys, a
    faster path) overrides `evaluate_episodes` and `evaluate` too."""

    def takes_agent(self, spec: str) -> Claim | None:
        """Whether an agent file or ``module:attribute`` is this world's, by its kind (shipped names are looked up
        before). Default: none is (only the agents it ships)."""
        return None

    @abstractmethod
    def play(
        self, agent: str, episodes: int, seed: int, world: dict[str, Any], scenario: str | None = None
    ) -> list[Episode]:
        """``episodes`` test episodes of the agent alone, in ``scenario``'s world when given: episode i starts
        alike for every agent at one seed, so two agents are compared episode by episode."""

    @abstractmethod
    def evaluate(
        self, agent: str, episodes: int, seed: int, world: dict[str, Any], scenario: str | None = None
    ) -> dict[str, Any]:
        """The agent's ``foil eval --json`` object (docs/formats.md): outcome rates where the world has
        outcomes, mean reward, the visible score where the world declares one, each with its 95% interval
        (`search.core.domain.Domain` computes it from `play`)."""

    @abstractmethod
    def evaluate_episodes(
        self, agent: str, episodes: int, seed: int, world: dict[str, Any], scenario: str | None = None
    ) -> dict[str, Any]:
        """``evaluate``'s object with each episode's reward (``episode_rewards``), so the bundle compares two
        agents episode by episode (search/bundle/truth.py)."""

    def describe_evaluation(self, result: dict[str, Any]) -> str:
        """``foil eval``'s lines for a person (``--json`` prints the object itself). Default: Foil's
        (`search.core.evaluation.describe`)."""
        return describe(result)

    def eval_scenario(self, scenarios: Sequence[str]) -> str | None:
        """Which of a study's scenarios an agent is evaluated in (None: the world's own test episodes)."""
        return None

    def agent_file(self, agent: str) -> Path | None:
        """The file an agent is loaded from (its checksum identifies it), or None for a scripted one. Default:
        None."""
        return None

    def agent_source(self, agent: str, world: dict[str, Any]) -> dict[str, Any]:
        """Where an agent came from, for the manifest. Default: its file and the file's checksum, or "scripted"."""
        path = self.agent_file(agent)
        if path is None or not path.is_file():
            return {"kind": "scripted"}
        return {"kind": "file", "checkpoint": str(path), "sha256": sha256_file(path)}


class Clips(ABC):
    """How a world's summaries become clips, and what a clip visibly shows in which words."""

    @abstractmethod
    def render(self, summary: Path, out: Path, numbers: list[int], options: Any) -> Any:
        """``foil render``: the clip, its poster and its contact sheet (a `search.clips.render.RenderResult`)."""

    def renderer_files(self, summary: Path) -> list[Path]:
        """The source files a clip of ``summary`` is drawn by (part of a rendered clip's cache key). Default: the
        file the world's class is defined in; a world that draws in other files lists them."""
        return [Path(inspect.getfile(type(self)))]

    def world(self, scenario: str | None = None) -> World:
        """What a clip visibly shows here and in which words. Default: `app.visible.World`'s."""
        return World()


class Trainer(ABC):
    """A world that trains and ships agents of its own (`foil train`, `foil release`); a world without one takes
    agents trained elsewhere."""

    @abstractmethod
    def takes_training(self, path: Path) -> Claim | None:
        """Whether a training config file or a training run's folder is this world's, by its content (a config's
        ``world`` key is looked up before)."""

    @abstractmethod
    def train(self, config: Path, out: Path) -> Path:
        """``foil train``: train from a config file into ``out``; the last checkpoint."""

    @abstractmethod
    def release(self, run_dir: Path, out: Path | None, episodes: int, every: int, jobs: int) -> dict[str, Any]:
        """``foil release``: choose the shipped agents from a run and write them with their model cards."""

    @abstractmethod
    def validate_run(self, run_dir: Path, episodes: int, every: int) -> None:
        """``foil release --validate-only``: print the run's validation curve."""
