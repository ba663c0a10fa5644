"""The main job's first form: two scripted robots through a shipped scenario under random environment actions."""

from __future__ import annotations

import time

import numpy as np

from search.policies import load_policy
from search.sim.coupled import replay
from search.sim.scenarios import load_scenario
from search.sim.world import OUTCOME_NAMES


def run_demo(scenario: str = "paper-bl-tr", seed: int = 0, steps: int = 100) -> int:
    loaded = load_scenario(scenario)
    config = loaded.config()
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-config.env_action_bound, config.env_action_bound, (steps, config.human_num, 2))
    names = ["goal", "orca"]
    start = time.perf_counter()
    trajectory = replay([load_policy(n) for n in names], loaded, actions)
    elapsed = time.perf_counter() - start
    print(f"scenario {loaded.name}: {loaded.description}")
    print(f"{len(trajectory.time)} coupled steps of {trajectory.time[1] - trajectory.time[0]:.2f} s "
          f"under random environment actions (seed {seed}) in {elapsed:.2f} s")
    for k, name in enumerate(names):
        event = OUTCOME_NAMES[trajectory.outcome[k]]
        when = trajectory.event_time[k]
        print(f"  robot '{name}': {event}" + (f" at {when:.2f} s" if np.isfinite(when) else "")
              + f", path {trajectory.path_length[k]:.2f} m, closest human {trajectory.min_clearance[k]:.2f} m, "
              f"return {trajectory.rewards[:, k].sum():.2f}")
    gap = np.linalg.norm(trajectory.robot_pos[:, 0] - trajectory.robot_pos[:, 1], axis=-1)
    print(f"  largest distance between the two robots: {gap.max():.2f} m")
    return 0
