"""`foil eval`: the JSON contract, determinism and disjoint test seeds."""

from __future__ import annotations

import json

import numpy as np

from search.cli import main
from search.crowd.agents.evaluate import TEST_STREAM, evaluate
from search.crowd.agents.policies import load_policy
from search.crowd.agents.train import TRAIN_STREAM
from search.crowd.sim.scenarios import sample_training_states
from search.crowd.sim.world import WorldConfig

KEYS = [
    "agent",
    "episodes",
    "success_rate",
    "collision_rate",
    "timeout_rate",
    "reward_mean",
    "reward_ci95",
    "nav_time_mean",
    "time_limit",
]


def test_eval_json_has_exactly_the_contract_keys(capsys):
    assert main(["eval", "goal", "--episodes", "30", "--seed", "3", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert list(result) == KEYS
    assert result["agent"] == "goal" and result["episodes"] == 30 and result["time_limit"] == 50.0
    assert abs(result["success_rate"] + result["collision_rate"] + result["timeout_rate"] - 1) < 1e-9
    low, high = result["reward_ci95"]
    assert low < result["reward_mean"] < high


def test_same_seed_same_numbers_and_other_seeds_differ():
    policy = load_policy("orca")
    first, again = evaluate(policy, 20, seed=1), evaluate(policy, 20, seed=1)
    assert first == again
    assert evaluate(policy, 20, seed=2)["reward_mean"] != first["reward_mean"]


def test_test_episodes_are_not_training_episodes():
    config = WorldConfig()
    for seed in range(3):
        test = sample_training_states(config, np.random.default_rng([TEST_STREAM, seed]), 4)
        for train_seed in range(3):
            train = sample_training_states(config, np.random.default_rng([TRAIN_STREAM, train_seed]), 4)
            assert not np.isclose(test.robot_pos[:, None], train.robot_pos[None]).all(-1).any()


def test_human_readable_output_and_bad_input(capsys):
    assert main(["eval", "goal", "--episodes", "5"]) == 0
    assert "success rate" in capsys.readouterr().out
    assert main(["eval", "goal", "--episodes", "1"]) == 2
    assert "at least 2 episodes" in capsys.readouterr().err
    assert main(["eval", "missing.pt"]) == 2


def test_time_limit_judges_agents_at_a_shorter_horizon(capsys):
    """An ORCA robot that needs longer than 8 s in some episodes times out there at --time-limit 8, and no
    successful episode lasts longer than the limit; the default is the training time limit."""
    full = evaluate(load_policy("orca"), 40, seed=0)
    assert main(["eval", "orca", "--episodes", "40", "--time-limit", "8", "--json"]) == 0
    short = json.loads(capsys.readouterr().out)
    assert short["time_limit"] == 8.0 and full["time_limit"] == 50.0
    assert short["timeout_rate"] > full["timeout_rate"]
    assert short["success_rate"] < full["success_rate"]
    assert short["nav_time_mean"] <= 8.0
    assert main(["eval", "orca", "--episodes", "5", "--time-limit", "8"]) == 0
    assert "8 s each at most" in capsys.readouterr().out
    for bad in ("0", "-3", "nan", "inf"):
        assert main(["eval", "orca", "--episodes", "5", "--time-limit", bad]) == 2
        assert "--time-limit must be a positive, finite number of seconds" in capsys.readouterr().err
