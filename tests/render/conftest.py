"""Summaries for the renderer's tests, made by stepping scripted robots through the coupled simulator."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from search.coupled import CoupledSimulator
from search.policies import load_policy
from search.scenarios import Scenario, load_scenario
from search.world import OUTCOME_NAMES


def summary_from_simulation(agents: list[str], scenario: Scenario, seed: int = 0, steps: int = 40,
                            names: list[str] | None = None) -> dict:
    """A foil.summary/1 object of scripted robots under seeded random environment actions; with a visible
    robot each step records every agent's own crowd."""
    sim = CoupledSimulator([load_policy(a) for a in agents], scenario)
    config = sim.config
    rng = np.random.default_rng(seed)
    records, actions = [], []
    for _ in range(steps):
        action = rng.uniform(-config.env_action_bound, config.env_action_bound, (1, config.human_num * 2))
        step = sim.step(action)
        crowd = sim.state.human_pos[0] if sim.shared_crowd else sim.state.human_pos
        records.append({"t": float(step.time[0]), "humans": crowd.tolist(), "robots": step.robot_pos[0].tolist(),
                        "robot_actions": step.robot_actions[0].tolist()})
        actions.append(action[0].tolist())
        if sim.all_done[0]:
            break
    state = sim.state
    outcome, when = sim._gather(state.outcome)[0], sim._gather(state.event_time)[0]
    return {
        "format": "foil.summary/1",
        "agents": [{"name": n, "source": a} for n, a in zip(names or agents, agents, strict=True)],
        "scenario": scenario.to_dict() | {"world": config.to_dict()},
        "solver": {"name": "random", "parameters": {}, "seed": seed, "budget": len(records)},
        "env_actions": actions,
        "steps": records,
        "outcomes": [{"event": OUTCOME_NAMES[outcome[k]], "time": float(when[k]) if np.isfinite(when[k]) else None,
                      "path_length": float(sim._gather(state.path_length)[0, k]),
                      "min_human_distance": float(sim._gather(state.min_clearance)[0, k])}
                     for k in range(len(agents))],
        "reward": 0.0,
        "reward_terms": {},
    }


def visible(scenario: Scenario) -> Scenario:
    return dataclasses.replace(scenario, world=scenario.world | {"robot_visible": True})


@pytest.fixture(scope="session")
def shared_summary() -> dict:
    return summary_from_simulation(["goal", "orca"], load_scenario("paper-bl-tr"), steps=60,
                                   names=["SECRET-ALPHA", "SECRET-BETA"])


@pytest.fixture
def summary_file(tmp_path, shared_summary):
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(shared_summary))
    return path
