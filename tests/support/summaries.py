"""Summaries from a real simulation of scripted robots, written by the search's own summary writer."""

from __future__ import annotations

import dataclasses

import numpy as np

from search.crowd.agents.policies import load_policy
from search.crowd.sim.coupled import replay
from search.crowd.sim.scenarios import Scenario
from search.crowd.summary import build_summary, frozen_scenario
from search.solvers.reward import RewardConfig


def summary_from_simulation(
    agents: list[str], scenario: Scenario, seed: int = 0, names: list[str] | None = None
) -> dict:
    """The summary.json object `foil search` would write for scripted robots under seeded random environment
    actions, cut where the trajectory ends; with visible robots it records every agent's crowd."""
    scenario = frozen_scenario(scenario, {})
    config, reward = scenario.config(), RewardConfig()
    policies = [load_policy(a) for a in agents]
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-config.env_action_bound, config.env_action_bound, (reward.horizon, config.human_num, 2))
    length = len(replay(policies, scenario, actions).time)
    summary = build_summary(agents, policies, scenario, reward, actions[:length], {"name": "random", "seed": seed})
    for entry, name in zip(summary["agents"], names or agents, strict=True):
        entry["name"] = name
    return summary


def visible(scenario: Scenario) -> Scenario:
    return dataclasses.replace(scenario, world=scenario.world | {"robot_visible": True})
