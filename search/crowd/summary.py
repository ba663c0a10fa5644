"""Crowd summaries (summary.json, defined in `app.formats`): one kept trajectory, replayable and checkable.

A summary is built from a replay of its environment actions at batch size 1, never from a search's batched
numbers (neural policies may differ in the last bits between batch sizes). ``rebuild`` builds it again from the
file's own inputs, which ``foil verify`` compares with the file exactly.

``steps`` holds the state after each step (the initial state is ``scenario``): the humans as ``other_positions``,
the robots as ``agent_positions``; ``min_other_distance`` is the smallest surface-to-surface distance between the
robot and any human (negative after a collision).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from app.formats import SUMMARY_FORMAT
from search.core.outcomes import OUTCOME_NAMES
from search.core.prior import ActionPrior
from search.crowd.agents.policies import SCRIPTED, load_policy
from search.crowd.sim.coupled import replay
from search.crowd.sim.scenarios import Scenario
from search.solvers.follow import Follow, recorded
from search.solvers.reward import DivergenceReward, RewardConfig


def agent_entry(spec: str, policy) -> dict:
    return {"name": spec, "source": "scripted" if spec in SCRIPTED else str(getattr(policy, "source", spec))}


def frozen_scenario(scenario: Scenario, world: dict) -> Scenario:
    """The scenario with its complete world config (plus ``world`` overrides) written in, so a summary does not
    depend on defaults."""
    return replace(scenario, world=scenario.config().to_dict() | world)


def _number(value: float) -> float | None:
    """JSON has no NaN or infinity: an event that has not happened has no time (null)."""
    return float(value) if math.isfinite(value) else None


def _pairs(array: np.ndarray) -> list[list[float]]:
    return np.asarray(array, dtype=np.float64).tolist()


def _humans(crowds: np.ndarray) -> list:
    """One crowd as [[x, y], ...]; with visible robots, one such list per agent's crowd."""
    return _pairs(crowds[0]) if len(crowds) == 1 else _pairs(crowds)


def build_summary(
    agents: list[str],
    policies: list,
    scenario: Scenario,
    reward_config: RewardConfig,
    env_actions: np.ndarray,
    solver: dict,
    follow: Follow | None = None,
    window: tuple[int, int] | None = None,
) -> dict:
    """Replay ``env_actions`` from the scenario's initial state and record everything a clip or a check needs.
    With ``follow`` the robots follow a leader (`search.solvers.follow`); ``window`` is the part a clip shows.

    The reward is the search's, over the searched steps. What the clip shows goes on after them: where the
    trajectory ended before every robot's episode did (a robot reached its goal first, or ``finish = "first"``),
    the robots go on without pushes until each has ended or the horizon is reached (the coda: ``steps`` beyond
    ``env_actions``), and ``outcomes`` are those at the clip's end."""
    config = scenario.config()
    searched = len(env_actions)
    trajectory = replay(
        policies, scenario, env_actions, stop_when_done=False, coda_to=reward_config.horizon, override=follow
    )
    prior = ActionPrior((config.human_num, 2), config.env_action_bound, reward_config.prior, reward_config.prior_sigma)
    total, terms, terminal = DivergenceReward(reward_config, prior).trajectory(trajectory.head(searched), config.dt)
    ends = np.flatnonzero(terminal)
    if ends.size == 0 or ends[0] != len(terminal) - 1:
        where = "never ends" if ends.size == 0 else f"ends at step {ends[0] + 1} of {len(terminal)}"
        raise ValueError(f"the trajectory {where}: a summary holds exactly one complete trajectory")
    summary = {
        "format": SUMMARY_FORMAT,
        "agents": [agent_entry(spec, policy) for spec, policy in zip(agents, policies, strict=True)],
        "scenario": scenario.to_dict(),
        "solver": solver,
        "reward_parameters": reward_config.to_dict(),
        "env_actions": [
            np.asarray(a, dtype=np.float64).reshape(-1).tolist() for a in trajectory.env_actions[:searched]
        ],
        "steps": [
            {
                "t": float(trajectory.time[i]),
                "other_positions": _humans(trajectory.crowds[i]),
                "agent_positions": _pairs(trajectory.agent_pos[i]),
                "agent_actions": _pairs(trajectory.agent_actions[i]),
            }
            for i in range(len(trajectory.time))
        ],
        "outcomes": [
            {
                "event": OUTCOME_NAMES[int(trajectory.outcome[k])],
                "time": _number(trajectory.event_time[k]),
                "path_length": float(trajectory.path_length[k]),
                "min_other_distance": _number(trajectory.min_clearance[k]),
            }
            for k in range(len(agents))
        ],
        "reward": total,
        "reward_terms": terms,
    }
    return recorded(summary, follow, window)


def rebuild(data: Mapping[str, Any]) -> dict:
    """The summary that the file's own inputs produce now."""
    agents = [entry["name"] for entry in data["agents"]]
    scenario = Scenario.from_dict(data["scenario"], source="summary scenario")
    reward_config = RewardConfig.from_dict(data["reward_parameters"])
    env_actions = np.array(data["env_actions"], dtype=np.float64)
    policies = [load_policy(a) for a in agents]
    window = data.get("window")
    return build_summary(
        agents, policies, scenario, reward_config, env_actions, data["solver"], Follow.of_summary(data), window
    )
