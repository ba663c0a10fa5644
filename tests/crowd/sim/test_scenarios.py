"""Scenario files, the training distribution, the Gymnasium wrapper and the demo command."""

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from search.cli import main
from search.crowd.sim.as_gymnasium import CrowdNavEnv
from search.crowd.sim.scenarios import (
    Scenario,
    ScenarioDistribution,
    load_scenario,
    load_scenario_or_distribution,
    sample_training_states,
    shipped_scenarios,
)
from search.crowd.sim.world import WorldConfig


def test_shipped_scenarios_load_with_ten_humans():
    assert shipped_scenarios() == ["paper-bl-tr", "paper-code", "paper-tl-br", "training"]
    code = load_scenario("paper-code")
    assert code.robot_start == (-5.0, 4.0) and code.robot_goal == (7.0, -2.0)
    assert code.human_goals[0] == tuple(-np.array(code.human_positions[0]))  # antipode by default
    for name in ("paper-bl-tr", "paper-code", "paper-tl-br"):
        scenario = load_scenario(name)
        assert len(scenario.human_positions) == 10 and scenario.config().human_num == 10
        humans = np.array(scenario.human_positions)
        gaps = np.linalg.norm(humans[:, None] - humans[None], axis=-1) + np.eye(10) * 10
        assert gaps.min() > 0.6  # nobody starts overlapping


def test_scenario_round_trips_through_its_dict():
    scenario = load_scenario("paper-bl-tr")
    assert Scenario.from_dict(scenario.to_dict()) == scenario


@pytest.mark.parametrize(
    "text, message",
    [
        ('name = "x"\n', "missing \\[robot\\]"),
        ("[robot]\nstart = [0, 0]\n", "needs 'goal'"),
        ('[robot]\nstart = [0, "a"]\ngoal = [1, 1]\n', "start must be a pair of numbers"),
        ("[robot]\nstart = [0, 0]\ngoal = [1, 1]\n[[humans]]\ngoal = [1, 1]\n", "human 0 needs 'position'"),
        ("[robot]\nstart = [0, 0]\ngoal = [1, 1]\n[world]\nspeed = 2\n", "unknown world setting"),
        ("[robot]\nstart = [0, 0]\ngoal = [1, 1]\ncolour = 3\n", "unknown key\\(s\\) \\['colour'\\]"),
        ("robots = 2\n[robot]\nstart = [0, 0]\ngoal = [1, 1]\n", "unknown key"),
        ("[robot\nstart = [0, 0]\n", "not valid TOML"),
        ("[robot]\nstart = [0, nan]\ngoal = [1, 1]\n", "must be finite"),
    ],
)
def test_bad_scenario_files_are_explained(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_scenario(path)


def test_missing_scenario_lists_the_shipped_ones():
    with pytest.raises(FileNotFoundError, match="paper-bl-tr"):
        load_scenario("nowhere")


def test_training_distribution_is_seeded_and_follows_crowdnav():
    config = WorldConfig()
    a = sample_training_states(config, np.random.default_rng(7), 20)
    b = sample_training_states(config, np.random.default_rng(7), 20)
    assert a.equals(b)
    assert np.all(np.linalg.norm(a.robot_pos - a.robot_goal, axis=-1) >= 6.0)
    assert np.all(np.abs(a.robot_pos) <= 6.0)
    radius = np.linalg.norm(a.human_pos, axis=-1)
    assert np.all(np.abs(radius - 6.0) < 0.2)
    np.testing.assert_array_equal(a.human_goal, -a.human_pos)


@pytest.mark.parametrize(
    "config",
    [WorldConfig(), WorldConfig(kinematics="unicycle"), WorldConfig(human_policy="social_force", robot_visible=True)],
)
def test_gymnasium_wrapper_passes_the_env_checker(config):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the checker's note that the env has no registered spec
        check_env(CrowdNavEnv(config))


def test_gymnasium_episode_ends_with_terminated_or_truncated():
    env = CrowdNavEnv(scenario=load_scenario("paper-bl-tr"))
    obs, _ = env.reset(seed=0)
    assert obs["spatial_edges"].shape == (10, 2)
    for _ in range(400):
        obs, reward, terminated, truncated, info = env.step(np.array([0.7, 0.7]))
        if terminated or truncated:
            break
    assert terminated and info["outcome"] in ("success", "collision")


def test_cli_reports_bad_scenarios_without_a_traceback(capsys, tmp_path):
    assert main(["search", "--agents", "goal,orca", "--scenario", "nowhere.toml", "--out", str(tmp_path)]) == 2
    assert "no scenario" in capsys.readouterr().err


def test_training_distribution_draws_seeded_fixed_scenarios_from_the_training_states():
    training = load_scenario_or_distribution("training")
    assert isinstance(training, ScenarioDistribution)
    drawn = training.sample(np.random.default_rng(3), 5)
    assert drawn == training.sample(np.random.default_rng(3), 5)  # the seed fixes the draw
    assert [s.name for s in drawn] == [f"training#{i}" for i in range(5)]
    states = sample_training_states(WorldConfig(), np.random.default_rng(3), 5)
    for i, scenario in enumerate(drawn):
        assert np.array_equal(scenario.human_positions, states.human_pos[i])
        assert np.array_equal(scenario.robot_start, states.robot_pos[i, 0])
        assert np.array_equal(scenario.robot_goal, states.robot_goal[i, 0])
        assert Scenario.from_dict(scenario.to_dict()) == scenario  # a summary can record it
        state = scenario.initial_state(scenario.config())
        assert np.array_equal(state.human_goal[0], states.human_goal[i])


def test_a_distribution_is_refused_where_one_scenario_is_needed_and_bad_files_are_named(tmp_path):
    with pytest.raises(ValueError, match="distribution of starting states.*representative"):
        load_scenario("training")
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[distribution]\nkind = "grid"\n')
    with pytest.raises(ValueError, match=r"bad.toml: \[distribution\] takes one key, kind"):
        load_scenario_or_distribution(bad)
    bad.write_text('name = "x"\n[distribution]\nkind = "circle-crossing"\n[world]\nhuman_num = -1\n')
    with pytest.raises(ValueError, match=r"bad.toml: \[world\]: .*human_num"):
        load_scenario_or_distribution(bad)
    dense = tmp_path / "dense.toml"
    dense.write_text('name = "dense"\n[distribution]\nkind = "circle-crossing"\n[world]\nhuman_num = 4\n')
    assert [
        len(s.human_positions) for s in load_scenario_or_distribution(dense).sample(np.random.default_rng(0), 2)
    ] == [4, 4]
