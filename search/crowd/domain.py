"""The crowd world as a domain: DS-RNN and scripted robots among ORCA or social-force humans (search/crowd/sim,
search/crowd/agents), its scenarios and the ``training`` distribution, its summaries, batched rollouts and clips, and
its trainer."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from app.visible import CROWD, World
from search.core.domain import Coupled, Domain
from search.core.world import Claim, Shipped, Trainer, is_module_attribute

CHECKPOINT_SUFFIXES = (".pt", ".pth", ".ts")  # PyTorch checkpoints and TorchScript files


def _toml(path: Path) -> dict:
    """A TOML file's table, or an empty one for anything else (its loader says what is wrong with a bad file)."""
    import tomllib

    if path.suffix != ".toml" or not path.is_file():
        return {}
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        return {}


class CrowdDomain(Domain, Trainer):
    name = "crowd"
    default_distribution = "training"
    episode_seconds_setting = "time_limit"

    def __init__(self) -> None:
        self._loaded: dict[tuple[str, int], Any] = {}

    def _policies(self, agents: Sequence[str]) -> list:
        """The agents' policies, each loaded once while its file is unchanged (a representative search asks for
        them once per batch of states and once per replay)."""
        from search.crowd.agents.policies import load_policy

        def key(spec: str) -> tuple[str, int]:
            path = Path(spec)
            return spec, path.stat().st_mtime_ns if path.suffix and path.is_file() else 0

        for spec in agents:
            if key(spec) not in self._loaded:
                self._loaded[key(spec)] = load_policy(spec)
        return [self._loaded[key(spec)] for spec in agents]

    def shipped(self) -> Shipped:
        """The shipped and scripted agents, and the shipped scenarios and distribution (``training``)."""
        from search.crowd.agents.policies import SCRIPTED, SHIPPED_AGENTS
        from search.crowd.sim.scenarios import shipped_scenarios

        return Shipped(frozenset(SCRIPTED) | frozenset(SHIPPED_AGENTS) | frozenset(shipped_scenarios()))

    def shipped_scenarios(self) -> list[str]:
        from search.crowd.sim.scenarios import shipped_scenarios

        return shipped_scenarios()

    def takes_agent(self, spec: str) -> Claim | None:
        """A checkpoint or TorchScript file; ``module:attribute`` read as a crowd policy where nothing else names
        a world."""
        if Path(spec).suffix in CHECKPOINT_SUFFIXES:
            return Claim.OWN
        return Claim.OWN if is_module_attribute(spec) else None

    def takes_scenario(self, name: str) -> Claim | None:
        """A TOML file with a ``[robot]`` table (a scenario) or a ``[distribution]`` kind (a distribution)."""
        data = _toml(Path(name))
        distribution = data.get("distribution")
        own = "robot" in data or isinstance(distribution, dict) and "kind" in distribution
        return Claim.OWN if own else None

    def takes_summary(self, summary: Mapping[str, Any]) -> Claim | None:
        scenario = summary.get("scenario")
        return Claim.OWN if isinstance(scenario, dict) and "robot" in scenario else None

    def describe_agents(self) -> str:
        return "crowd agents (lo, med, hi, scripted policies, checkpoints) go on crowd scenarios"

    def parse_world(self, items: list[str]) -> dict:
        from search.crowd.sim.world import WorldConfig
        from search.solvers.runner import parse_settings

        return parse_settings(WorldConfig, items, "world")

    def check_world(self, settings: dict, what: str) -> dict:
        from search.core.settings import check_values
        from search.crowd.sim.world import WorldConfig

        return check_values(WorldConfig, settings, what)

    def agents_settings(self, agents: Sequence[str]) -> dict:
        """The world an imported CrowdNav_DSRNN checkpoint was trained in (its config)."""
        from search.crowd.agents.policies import comparison_world

        return comparison_world(list(agents), {})

    def scenario_settings(self, scenario: str) -> dict:
        from search.crowd.sim.scenarios import load_scenario_or_distribution

        return dict(load_scenario_or_distribution(scenario).world)

    def search_settings(self, agents: Sequence[str], settings: dict, scenario: str) -> dict:
        from search.crowd.agents.policies import comparison_world

        return comparison_world(list(agents), settings, self.scenario_settings(scenario))

    def episode_seconds(self, name: str, world: dict) -> float | None:
        """The world's time limit (``world`` holds the search's settings, `search_settings`)."""
        from search.crowd.sim.world import WorldConfig

        return float(WorldConfig.from_dict(world).time_limit)

    def is_distribution(self, name: str) -> bool:
        from search.crowd.sim.scenarios import ScenarioDistribution, load_scenario_or_distribution

        return isinstance(load_scenario_or_distribution(name), ScenarioDistribution)

    def scenario_dict(self, name: str, world: dict) -> dict:
        from dataclasses import asdict

        from search.crowd.sim.scenarios import ScenarioDistribution, load_scenario_or_distribution
        from search.crowd.summary import frozen_scenario

        scenario = load_scenario_or_distribution(name)
        if isinstance(scenario, ScenarioDistribution):
            return asdict(replace(scenario, world=scenario.world | world))
        return frozen_scenario(scenario, world).to_dict()

    def step_seconds(self, name: str, world: dict) -> float:
        from search.crowd.sim.world import WorldConfig

        return float(self.scenario_dict(name, world).get("world", {}).get("dt", WorldConfig().dt))

    def state(self, name: str, world: dict) -> Any:
        from search.crowd.sim.scenarios import load_scenario
        from search.crowd.summary import frozen_scenario

        return frozen_scenario(load_scenario(name), world)

    def draw_states(self, name: str, world: dict, rng: np.random.Generator, count: int) -> list:
        from search.crowd.sim.scenarios import ScenarioDistribution, load_scenario_or_distribution
        from search.crowd.summary import frozen_scenario

        loaded = load_scenario_or_distribution(name)
        if not isinstance(loaded, ScenarioDistribution):
            raise ValueError(f"{name!r} is one scenario, not a distribution of starting states")
        drawn = replace(loaded, world=loaded.world | world).sample(rng, count)
        return [frozen_scenario(s, s.world | world) for s in drawn]

    def coupled(self, agents: Sequence[str], state: Any, reward: dict) -> Coupled:
        from search.crowd.problem import CoupledProblem
        from search.crowd.summary import build_summary
        from search.solvers.reward import RewardConfig

        policies, reward_config = self._policies(agents), RewardConfig.from_dict(reward)
        return Coupled(
            CoupledProblem(policies, state, reward=reward_config),
            state.name,
            lambda actions, solver, follow=None, window=None, horizon=None: build_summary(
                list(agents), policies, state, reward_config.with_horizon(horizon), actions, solver, follow, window
            ),
            self.world(),
        )

    def play_states(self, agents, states, reward, pushes, rng):
        """The crowd's fast path: every state's rollouts in one batched simulator, no replays."""
        from search.crowd.rollouts import play
        from search.solvers.reward import RewardConfig

        return play(self._policies(agents), states, RewardConfig.from_dict(reward), pushes, rng)

    def shown(self, coupled: Coupled, row: int, steps: int, since: int, summary=None) -> float:
        """Read from the simulator's final state (no replay)."""
        from search.crowd.rollouts import shown

        return shown(coupled.problem.sim, row, since * coupled.problem.sim.config.dt)

    def rebuild(self, summary: Mapping[str, Any]) -> Any:
        from search.crowd.summary import rebuild

        return rebuild(summary)

    def evaluate(
        self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None, per_episode: bool = False
    ) -> dict:
        """In the world the agent brings (an imported checkpoint's), under the ``world`` settings given."""
        from search.crowd.agents.evaluate import evaluate
        from search.crowd.agents.policies import comparison_world, load_policy
        from search.crowd.sim.world import WorldConfig

        config = WorldConfig.from_dict(comparison_world([agent], world))
        return evaluate(load_policy(agent), episodes=episodes, seed=seed, config=config, per_episode=per_episode)

    def play(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> list:
        """The test episodes `evaluate` summarises, one `Episode` each (the crowd shows no visible score)."""
        from search.core.evaluation import Episode
        from search.core.outcomes import OUTCOME_NAMES
        from search.crowd.agents.evaluate import play
        from search.crowd.agents.policies import comparison_world, load_policy
        from search.crowd.sim.world import WorldConfig

        config = WorldConfig.from_dict(comparison_world([agent], world))
        returns, outcome, event_time, _ = play(load_policy(agent), episodes, seed, config)
        return [
            Episode(float(r), float(t), OUTCOME_NAMES[int(code)])
            for r, code, t in zip(returns, outcome, event_time, strict=True)
        ]

    def evaluate_episodes(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> dict:
        return self.evaluate(agent, episodes, seed, world, scenario, per_episode=True)

    def describe_evaluation(self, result: dict) -> str:
        from search.crowd.agents.evaluate import format_result

        return format_result(result)

    def agent_file(self, agent: str) -> Path | None:
        from search.crowd.agents.policies import AGENTS_DIR, SCRIPTED, SHIPPED_AGENTS

        if agent in SCRIPTED:
            return None
        return AGENTS_DIR / f"{agent}.pt" if agent in SHIPPED_AGENTS else Path(agent)

    def agent_source(self, agent: str, world: dict) -> dict:
        """Its kind, its checkpoint file and checksum, a CrowdNav_DSRNN model's config and trained world, and the
        full world of its evaluation."""
        from app.formats import sha256_file
        from search.crowd.agents.crowdnav import config_path, is_crowdnav_file
        from search.crowd.agents.policies import SCRIPTED, SHIPPED_AGENTS, trained_world
        from search.crowd.sim.world import WorldConfig

        source: dict[str, Any] = {
            "kind": "scripted" if agent in SCRIPTED else "shipped" if agent in SHIPPED_AGENTS else "python"
        }
        path = self.agent_file(agent)
        if path is not None and path.is_file():
            source |= {
                "kind": source["kind"] if agent in SHIPPED_AGENTS else "checkpoint",
                "checkpoint": str(path),
                "sha256": sha256_file(path),
            }
            if is_crowdnav_file(path):
                source |= {
                    "kind": "crowdnav_dsrnn",
                    "config": str(config_path(path)),
                    "trained_world": trained_world(agent),
                }
        return source | {"world": WorldConfig.from_dict(world).to_dict()}

    def takes_training(self, path: Path) -> Claim | None:
        """A run folder with the trainer's progress.csv, or a TOML config of `TrainConfig` fields."""
        from dataclasses import fields

        from search.crowd.agents.train import TrainConfig

        if path.is_dir():
            return Claim.OWN if (path / "progress.csv").is_file() and any(path.glob("checkpoints/*.pt")) else None
        data = _toml(path)
        return Claim.OWN if data and set(data) <= {f.name for f in fields(TrainConfig)} else None

    def train(self, config: Path, out: Path) -> Path:
        from search.crowd.agents.train import load_train_config, train

        return train(load_train_config(config), out)

    def release(self, run_dir: Path, out: Path | None, episodes: int, every: int, jobs: int) -> dict:
        from search.crowd.agents.policies import AGENTS_DIR
        from search.crowd.agents.release import release

        return release(run_dir, out or AGENTS_DIR, episodes, every)

    def validate_run(self, run_dir: Path, episodes: int, every: int) -> None:
        from search.crowd.agents.release import validate_run

        validate_run(run_dir, episodes, every)

    def render(self, summary: Path, out: Path, numbers: list[int], options: Any) -> Any:
        from search.crowd.render import render_file

        return render_file(summary, out, numbers, options)

    def renderer_files(self, summary: Path) -> list[Path]:
        import search.clips.render as toolkit
        import search.clips.windows as windows
        import search.crowd.render as renderer
        import search.crowd.scene as scene

        return [Path(renderer.__file__), Path(scene.__file__), Path(toolkit.__file__), Path(windows.__file__)]

    def world(self, scenario: str | None = None) -> World:
        """The crowd's world: robots among people, reaching a goal, in the crowd's words (its manifests leave the
        `world` object out)."""
        return CROWD
