"""Any Gymnasium environment as a domain: its scenario files name the adapter (docs/gym.md), its agents are
Stable-Baselines3 files or ``module:attribute`` callables, and what a clip shows and in which words is the
adapter's."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from app.visible import VisibleClip, World
from search.core.domain import Coupled, Domain
from search.core.world import Claim, is_module_attribute
from search.gym.adapter import Adapter, load_adapter
from search.gym.agents import GymAgent, load_agent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.gym.scenarios import GymDistribution, gym_file, load_gym_file


class GymDomain(Domain):
    name = "gym"
    # whether the world's coupled problems step their rows in one batched fast path (the highway kernel): then
    # independent work stays in one process; a Python environment's is spread over worker processes
    batched = False

    def __init__(self) -> None:
        self._agents: dict[tuple[str, str], GymAgent] = {}

    def takes_agent(self, spec: str) -> Claim | None:
        """A Stable-Baselines3 file; ``module:attribute`` too, as other worlds take it."""
        if spec.endswith(".zip"):
            return Claim.OWN
        return Claim.ALSO if is_module_attribute(spec) else None

    def takes_scenario(self, name: str) -> Claim | None:
        """A file that names an adapter: any Gymnasium environment's, unless a world of its own owns it."""
        return Claim.ALSO if gym_file(name) is not None else None

    def takes_summary(self, summary: Mapping[str, Any]) -> Claim | None:
        scenario = summary.get("scenario")
        return Claim.ALSO if isinstance(scenario, dict) and scenario.get("domain") == "gym" else None

    def describe_agents(self) -> str:
        return (
            "Gymnasium agents (Stable-Baselines3 .zip files, module:attribute) go on a scenario file that names "
            "their environment's adapter"
        )

    def parse_world(self, items: list[str]) -> dict:
        """``key=value`` settings of the adapter, each value read as JSON where it is (else text)."""
        settings = {}
        for item in items:
            key, sep, text = item.partition("=")
            if not sep or not key.strip():
                raise ValueError(f"bad world setting {item!r}: use key=value, e.g. vehicles_density=2")
            try:
                settings[key.strip()] = json.loads(text)
            except json.JSONDecodeError:
                settings[key.strip()] = text
        return settings

    def check_world(self, settings: dict, what: str) -> dict:
        return dict(settings)  # an adapter's settings are its own

    def load(self, name: str) -> GymScenario | GymDistribution:
        """A scenario or distribution by name: a file (highway driving adds its shipped names)."""
        return load_gym_file(name)

    def is_distribution(self, name: str) -> bool:
        return isinstance(self.load(name), GymDistribution)

    def scenario_dict(self, name: str, world: dict) -> dict:
        found = self.load(name).to_dict()
        return found | {"settings": found["settings"] | world}

    def step_seconds(self, name: str, world: dict) -> float:
        return float(self.adapter(name).dt)

    def episode_seconds(self, name: str, world: dict) -> float | None:
        """The environment's step limit (its spec's ``max_episode_steps``) in seconds; None where it has none."""
        adapter = self.adapter(name)
        env = type(adapter)(adapter.settings | world).make()
        steps = getattr(env.spec, "max_episode_steps", None)
        env.close()
        return float(steps * adapter.dt) if steps else None

    def state(self, name: str, world: dict) -> GymScenario:
        found = self.load(name)
        if isinstance(found, GymDistribution):
            raise ValueError(
                f"{name!r} is a distribution of starting states: only the representative solver draws from one; "
                "give a scenario file with one seed"
            )
        return GymScenario(found.name, found.adapter, found.seed, found.settings | world, found.description)

    def draw_states(self, name: str, world: dict, rng: np.random.Generator, count: int) -> list:
        found = self.load(name)
        if not isinstance(found, GymDistribution):
            raise ValueError(f"{name!r} is one scenario, not a distribution of starting states")
        return found.with_settings(world).sample(rng, count)

    def agent(self, spec: str, adapter: Adapter) -> GymAgent:
        """An agent, loaded once per adapter class (a model file is read once per process)."""
        key = (spec, type(adapter).__qualname__)
        if key not in self._agents:
            self._agents[key] = load_agent(spec, adapter)
        return self._agents[key]

    def coupled(self, agents: Sequence[str], state: Any, reward: dict) -> Coupled:
        from search.gym.summary import build_gym_summary
        from search.solvers.reward import RewardConfig

        adapter = state.load_adapter()
        loaded = [self.agent(spec, adapter) for spec in agents]
        reward_config = RewardConfig.from_dict(reward)
        problem = self.problem(loaded, state, reward_config, adapter)
        shape = problem.action_shape
        return Coupled(
            problem,
            state.name,
            lambda actions, solver, follow=None, window=None, horizon=None: build_gym_summary(
                loaded,
                state,
                reward_config.with_horizon(horizon),
                np.asarray(actions).reshape(-1, *shape),
                solver,
                follow,
                window,
            ),
            adapter.world(),
        )

    def play_states(self, agents, states, reward, pushes, rng):
        """Rollouts read from the problem's own record of each agent's ending, as its summary would say it (no
        replay; `tests/gym/test_any_world.py` checks it against the summaries); the states over worker processes
        unless the world steps them in one batch (``batched``)."""
        from search.core.contrast import play_problem
        from search.core.domain import play_spread

        if self.batched:
            return play_problem([self.coupled(agents, s, reward) for s in states], pushes, rng, seen)
        return play_spread(self.name, agents, states, reward, pushes, rng, seen)

    def shown(self, coupled: Coupled, row: int, steps: int, since: int, summary=None) -> float:
        """Read from the problem's record of each agent's ending (no replay)."""
        return shown(coupled, row, steps, since)

    def problem(self, agents: list[GymAgent], state: GymScenario, reward, adapter: Adapter) -> GymCoupledProblem:
        """The coupled problem a search steps, its rows over the command's worker processes (its summaries replay
        in the environment itself, in this process)."""
        from search.core.workers import workers

        return GymCoupledProblem(agents, state, reward, adapter, workers=workers())

    def rebuild(self, summary: Mapping[str, Any]) -> Any:
        from search.gym.summary import rebuild

        return rebuild(summary)

    def adapter(self, scenario: str | None) -> Adapter:
        """The adapter of a scenario or distribution file, with its settings."""
        if scenario is None:
            raise ValueError(
                "a Gymnasium agent acts in the world its scenario file names: give --scenario FILE (a .toml file "
                "with adapter = 'module:Class', read relative to the working directory)"
            )
        found = self.load(scenario)
        return load_adapter(found.adapter, found.settings)

    def evaluate(
        self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None, per_episode: bool = False
    ) -> dict:
        adapter = self.adapter(scenario)
        adapter = type(adapter)(adapter.settings | world)
        return self.evaluation(self.agent(agent, adapter), episodes, seed, adapter, per_episode)

    def play(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> list:
        """The test episodes `evaluate` summarises, in the adapter's environment."""
        from search.gym.evaluate import test_episodes

        adapter = self.adapter(scenario)
        adapter = type(adapter)(adapter.settings | world)
        return test_episodes(self.agent(agent, adapter), episodes, seed, adapter)

    def evaluate_episodes(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> dict:
        return self.evaluate(agent, episodes, seed, world, scenario, per_episode=True)

    def evaluation(
        self, agent: GymAgent, episodes: int, seed: int, adapter: Adapter, per_episode: bool = False
    ) -> dict:
        """The test episodes, one at a time in the adapter's environment."""
        from search.gym.evaluate import evaluate

        return evaluate(agent, episodes, seed, adapter, per_episode)

    def describe_evaluation(self, result: dict) -> str:
        from search.core.evaluation import describe

        return describe(result)

    def eval_scenario(self, scenarios):
        """The first scenario the agent is shown in: a Gymnasium agent acts in the world its scenario names."""
        return scenarios[0] if scenarios else None

    def agent_file(self, agent: str) -> Path | None:
        return Path(agent) if agent.endswith(".zip") else None

    def agent_source(self, agent: str, world: dict) -> dict:
        from app.formats import sha256_file

        path = self.agent_file(agent)
        return {"kind": "gymnasium"} | (
            {"checkpoint": str(path), "sha256": sha256_file(path)} if path is not None and path.is_file() else {}
        )

    def render(self, summary: Path, out: Path, numbers: list[int], options: Any) -> Any:
        from search.gym.clips import render_gym

        return render_gym(summary, out, numbers, options)

    def renderer_files(self, summary: Path) -> list[Path]:
        import inspect

        import search.clips.render as toolkit
        import search.clips.windows as windows
        import search.gym.clips as renderer
        from app.formats import load_summary

        adapter = GymScenario.from_dict(load_summary(summary)["scenario"]).load_adapter()
        files = [renderer.__file__, toolkit.__file__, windows.__file__, inspect.getfile(type(adapter))]
        return [Path(file) for file in files]

    def world(self, scenario: str | None = None) -> World:
        return self.adapter(scenario).world()


def shown(coupled: Coupled, row: int, steps: int, since: int = 0) -> float:
    """The visible contrast of a row of a Gymnasium problem of two agents that just ended, its clip shown from the
    state after step ``since`` (`clip_of_row`)."""
    from search.core.contrast import visible_contrast

    return visible_contrast(clip_of_row(coupled, row, steps, since))


def seen(coupled: Coupled, row: int, steps: int) -> tuple[VisibleClip, list[int]]:
    """A row's clip of every agent and the step each one's episode ended on (0: it ran on), as
    `search.core.contrast.play_rows` reads a row the moment it ends."""
    return clip_of_row(coupled, row, steps), [step for _, step in coupled.problem.endings(row)]


def clip_of_row(coupled: Coupled, row: int, steps: int, since: int = 0) -> VisibleClip:
    """The clip of every agent of a row of a Gymnasium problem that has taken ``steps`` steps, shown from the state
    after step ``since``: each agent's event and its time, and its visible score's sum where the world shows one,
    as `search.gym.summary.build_gym_summary` records them."""
    from search.core.outcomes import OUTCOME_NAMES

    dt = coupled.problem.adapter.dt
    endings = coupled.problem.endings(row)
    outcomes = tuple(
        {
            "event": OUTCOME_NAMES[outcome],
            "time": float(max(step - since, 0) * dt) if step else None,
            "min_other_distance": None,
        }
        for outcome, step in endings
    )
    end_s = max((steps - since) * dt, 1e-6)
    score = coupled.world.score
    ends = [step for _, step in endings]  # a view and its readout stop where its run ended
    summed = (
        ()
        if score is None
        else tuple(
            score.of(m[since : max(end, since + 1) if end else steps], dt)
            for m, end in zip(coupled.problem.measured(row), ends, strict=True)
        )
    )
    labels = tuple(str(k) for k in range(len(endings)))
    return VisibleClip(labels, outcomes, (0.0,) * len(endings), end_s, world=coupled.world, summed=summed)
