"""Summaries in a Gymnasium domain, and rebuilding them for `foil verify`.

A summary (``foil.summary/2``, as in every world) is built from a replay of its environment actions at batch size
1; its scenario holds the adapter, its settings and the seed, so ``verify`` needs nothing else. Per step it
records each agent's ``position`` (as ``agent_positions``), its action (``agent_actions``) and what else the
adapter shows of its instance's world (``other_positions``: one list per agent); where the adapter shows nothing
else (no ``others``), a digest of each instance's observation and state instead (``world_digests``,
`search.gym.world_state`), so ``verify`` sees every change of the world. ``min_other_distance`` is null: a generic
environment has no other movers to measure against. Where the adapter declares a visible score, each step also
records each agent's value of it (``scores``), which the clip shows and its viewers judge by (`app.visible.Score`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from app.formats import SUMMARY_FORMAT
from search.core.outcomes import OUTCOME_NAMES
from search.gym.agents import GymAgent, load_agent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.gym.world_state import describes_others, world_digest
from search.solvers.follow import Follow, recorded
from search.solvers.reward import TERMS, RewardConfig, sequential_sum


def _floats(value) -> list:
    return np.asarray(value, dtype=np.float64).tolist()


def replay(problem: GymCoupledProblem, env_actions: np.ndarray, on_state=None, digests: bool = False) -> dict:
    """Step a batch-1 problem through ``env_actions``; per step the record a summary holds, and the reward terms.
    ``on_state(problem)`` sees the problem after the reset and after each step (the clips render it there); with
    ``digests`` each step records each instance's ``world_digests`` too (a clip's rendering replay needs none)."""
    problem.reset(1)
    if on_state is not None:
        on_state(problem)
    c = problem.reward_config
    steps, rewards, terms = [], [], {name: [] for name in TERMS}
    terminal_at = None
    for i, action in enumerate(np.asarray(env_actions, dtype=np.float64)):
        reward, terminal = problem.step(action[None])
        goal, end = problem.last_events
        plausibility = c.plausibility * float(problem.prior.log_prob(action)) if c.plausibility else 0.0
        divergence = float(reward[0]) - plausibility if c.plausibility else float(reward[0])
        for name, value in zip(
            TERMS,
            (
                0.0 if goal[0] or end[0] else divergence,
                divergence if goal[0] else 0.0,
                divergence if end[0] else 0.0,
                plausibility,
            ),
            strict=True,
        ):
            terms[name].append(value)
        rewards.append(float(reward[0]))
        row = problem.rows[0]
        steps.append(
            {
                "t": float((i + 1) * problem.adapter.dt),
                "other_positions": [_floats(problem.adapter.others(instance.env)) for instance in row],
                "agent_positions": [_floats(problem.adapter.position(instance.env)) for instance in row],
                "agent_actions": [_floats(np.asarray(a).reshape(-1)) for a in problem.last_agent_actions[0]],
            }
        )
        if problem.adapter.score is not None:
            steps[-1]["scores"] = [instance.measured[-1] for instance in row]
        if digests:
            steps[-1]["world_digests"] = [world_digest(problem.adapter, each.env, each.observation) for each in row]
        if on_state is not None:
            on_state(problem)
        if terminal[0]:
            terminal_at = i
            break
    if terminal_at is None or terminal_at != len(env_actions) - 1:
        where = "never ends" if terminal_at is None else f"ends at step {terminal_at + 1} of {len(env_actions)}"
        raise ValueError(f"the trajectory {where}: a summary holds exactly one complete trajectory")
    return {
        "steps": steps,
        "reward": sequential_sum(rewards),
        "reward_terms": {name: sequential_sum(values) for name, values in terms.items()},
    }


def build_gym_summary(
    agents: list[GymAgent],
    scenario: GymScenario,
    reward_config: RewardConfig,
    env_actions: np.ndarray,
    solver: dict,
    follow: Follow | None = None,
    window: tuple[int, int] | None = None,
) -> dict:
    """The summary of ``env_actions`` replayed from the scenario's seed; with ``follow`` the agents follow a leader
    (`search.solvers.follow`); ``window`` is the part a clip shows."""
    problem = GymCoupledProblem(agents, scenario, reward_config)
    problem.override = follow
    record = replay(problem, env_actions, digests=not describes_others(problem.adapter))
    dt = problem.adapter.dt
    summary = {
        "format": SUMMARY_FORMAT,
        "agents": [{"name": agent.name, "source": agent.source} for agent in agents],
        "scenario": scenario.to_dict(),
        "solver": solver,
        "reward_parameters": reward_config.to_dict(),
        "env_actions": [_floats(np.asarray(a).reshape(-1)) for a in env_actions],
        "steps": record["steps"],
        "outcomes": [
            {
                "event": OUTCOME_NAMES[instance.outcome],
                "time": float(instance.event_step * dt) if instance.event_step else None,
                "path_length": instance.path_length,
                "min_other_distance": None,
            }
            for instance in problem.rows[0]
        ],
        "reward": record["reward"],
        "reward_terms": record["reward_terms"],
    }
    return recorded(summary, follow, window)


def rebuild(data: Mapping[str, Any]) -> dict:
    """The summary that the file's own inputs produce now."""
    scenario = GymScenario.from_dict(data["scenario"])
    adapter = scenario.load_adapter()
    agents = [load_agent(entry["name"], adapter) for entry in data["agents"]]
    env_actions = np.array(data["env_actions"], dtype=np.float64).reshape(-1, *adapter.env_action_shape)
    reward_config = RewardConfig.from_dict(data["reward_parameters"])
    follow, window = Follow.of_summary(data), data.get("window")
    return build_gym_summary(agents, scenario, reward_config, env_actions, data["solver"], follow, window)
