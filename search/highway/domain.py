"""Highway driving as a domain: the Gymnasium domain with highway-env's highway, shipped agents (highway-lo,
highway-med, highway-hi), scenarios and a distribution of starting states, its clip style (the adapter's
rendering hooks) and its words: cars in traffic, judged by how long they last."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from search.core.world import Claim, Shipped, Trainer
from search.gym.adapter import Adapter
from search.gym.domain import GymDomain
from search.gym.problem import GymScenario
from search.gym.scenarios import GymDistribution, gym_file
from search.highway.adapter import AGENT_PREFIX, HighwayAdapter
from search.highway.scenarios import ADAPTER, DISTRIBUTIONS, SCENARIOS, load_highway_scenario


class HighwayDomain(GymDomain, Trainer):
    name = "highway"
    default_distribution = "highway-traffic"
    batched = True  # the kernel steps every row of a search at once

    def shipped(self) -> Shipped:
        """Every name with the highway's prefix: its agents, scenarios and distribution (an unknown one is refused
        with the list of those it ships)."""
        return Shipped(prefixes=(AGENT_PREFIX,))

    def takes_agent(self, spec: str) -> Claim | None:
        """Any Gymnasium agent, as the Gymnasium world takes it."""
        return Claim.ALSO if super().takes_agent(spec) else None

    def takes_scenario(self, name: str) -> Claim | None:
        """A file that names the highway's adapter."""
        found = gym_file(name)
        return Claim.OWN if found is not None and found["adapter"] == ADAPTER else None

    def takes_summary(self, summary: Mapping[str, Any]) -> Claim | None:
        own = super().takes_summary(summary) and summary["scenario"].get("adapter") == ADAPTER
        return Claim.OWN if own else None

    def shipped_scenarios(self) -> list[str]:
        return sorted([*SCENARIOS, *DISTRIBUTIONS])

    def describe_agents(self) -> str:
        return "highway agents (highway-lo, highway-med, highway-hi, .zip files) go on highway scenarios"

    def load(self, name: str) -> GymScenario | GymDistribution:
        return load_highway_scenario(name) if name in self.shipped() else super().load(name)

    def episode_seconds(self, name: str, world: dict) -> float | None:
        """highway-env's ``duration``, the decisions an episode lasts (its environment has no step limit of its own)."""
        from search.highway.env import DURATION_S

        adapter = self.adapter(name)
        return float((adapter.settings | world).get("duration", DURATION_S)) * adapter.dt

    def adapter(self, scenario: str | None) -> Adapter:
        """The scenario's adapter; the highway's own default world when no scenario is given."""
        return HighwayAdapter() if scenario is None else super().adapter(scenario)

    def takes_training(self, path: Path) -> Claim | None:
        """A config or run marked ``domain = "highway"``."""
        from search.highway.release import is_highway_run
        from search.highway.train import is_highway_config

        return Claim.OWN if (is_highway_run(path) if path.is_dir() else is_highway_config(path)) else None

    def train(self, config: Path, out: Path) -> Path:
        from search.highway.train import load_config, train

        return train(load_config(config), out)

    def release(self, run_dir: Path, out: Path | None, episodes: int, every: int, jobs: int) -> dict:
        from search.highway.release import release

        return release(run_dir, out, episodes, every, jobs=jobs)

    def validate_run(self, run_dir: Path, episodes: int, every: int) -> None:
        from search.highway.release import validate_run

        validate_run(run_dir, every)

    def evaluation(self, agent, episodes: int, seed: int, adapter: Adapter, per_episode: bool = False) -> dict:
        """On the batched kernel: the same test episodes and result, many episodes at a time."""
        from search.highway.evaluate import evaluate

        return evaluate(agent, episodes, seed, adapter, per_episode=per_episode)

    def problem(self, agents, state, reward, adapter):
        """On the batched kernel where it covers the scenario (else highway-env, with a one-line notice)."""
        from search.core.workers import workers
        from search.highway.coupled import coupled_problem

        return coupled_problem(agents, state, reward, adapter, workers())

    def eval_scenario(self, scenarios):
        """None: the shipped agents are judged in their training traffic, as their model cards report."""
        return None

    def agent_file(self, agent: str) -> Path | None:
        return HighwayAdapter().agent_file(agent) or super().agent_file(agent)
