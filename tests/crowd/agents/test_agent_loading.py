"""Loading agents by shipped name, checkpoint, TorchScript file and module:attribute, and the errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from search.crowd.agents.dsrnn import DSRNNPolicy, NetworkConfig, export_torchscript, read_checkpoint, save_checkpoint
from search.crowd.agents.policies import SHIPPED_AGENTS, load_policy
from search.crowd.sim.observation import ROBOT_NODE_FIELDS
from tests.support.agents import make_net, random_observation


def act_once(policy, humans: int = 3) -> np.ndarray:
    return policy.act(random_observation(2, humans), policy.initial_state(2))[0]


def test_checkpoint_and_torchscript_files_load_the_same_agent(tmp_path):
    net = make_net()
    save_checkpoint(tmp_path / "agent.pt", net, env_steps=123)
    export_torchscript(net, tmp_path / "agent.ts")
    from_checkpoint = load_policy(str(tmp_path / "agent.pt"))
    from_script = load_policy(str(tmp_path / "agent.ts"))
    assert from_checkpoint.name == str(tmp_path / "agent.pt")
    np.testing.assert_allclose(act_once(from_checkpoint), act_once(DSRNNPolicy(net)), atol=1e-6)
    np.testing.assert_allclose(act_once(from_script), act_once(DSRNNPolicy(net)), atol=1e-6)
    assert read_checkpoint(tmp_path / "agent.pt")["env_steps"] == 123


def test_module_attribute_loads_your_own_policy(tmp_path, monkeypatch):
    (tmp_path / "my_robot.py").write_text(
        "from search.crowd.agents.policies import GoalPolicy\n"
        "class Cautious(GoalPolicy):\n"
        "    name = 'cautious'\n"
        "    def act(self, observation, state):\n"
        "        action, state = super().act(observation, state)\n"
        "        return 0.5 * action, state\n"
        "robot = Cautious()\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    for spec in ("my_robot:Cautious", "my_robot:robot"):
        assert load_policy(spec).name == "cautious"
    with pytest.raises(ValueError, match="cannot load policy"):
        load_policy("my_robot:nothing")


@pytest.mark.parametrize("name", SHIPPED_AGENTS)
def test_shipped_agents_load_by_name_and_act(name):
    """A shipped name loads its network, whose first move in a shipped scenario heads for the goal (the world
    clips its speed), the same move every time, in crowds as large as trained on or smaller."""
    from search.crowd.agents.policies import AGENTS_DIR
    from search.crowd.sim.observation import observe
    from search.crowd.sim.scenarios import load_scenario

    policy = load_policy(name)
    assert policy.name == name
    scenario = load_scenario("paper-bl-tr")
    config = scenario.config()
    observation = observe(scenario.initial_state(config), config, robot=0)
    action, _ = policy.act(observation, policy.initial_state(1))
    goal = np.subtract(scenario.robot_goal, scenario.robot_start)
    assert action.shape == (1, 2)
    assert action[0] @ goal / (np.linalg.norm(action[0]) * np.linalg.norm(goal)) > 0.5  # within 60 degrees
    np.testing.assert_array_equal(policy.act(observation, policy.initial_state(1))[0], action)
    from_file = load_policy(str(AGENTS_DIR / f"{name}.pt"))  # the shipped name is that file's network
    np.testing.assert_array_equal(from_file.act(observation, from_file.initial_state(1))[0], action)
    assert np.isfinite(act_once(policy, humans=4)).all()  # smaller crowds than trained on


@pytest.mark.parametrize("scenario", ["paper-bl-tr", "paper-tl-br", "paper-code"])
def test_the_better_shipped_agents_reach_the_goal_in_the_clips_horizon(scenario):
    """med and hi drive into the goal within the clips' 25 s on every shipped scenario when nobody disturbs the
    crowd (the agents before the relative goal circled it and timed out)."""
    from search.core.outcomes import SUCCESS
    from search.crowd.sim.coupled import replay
    from search.crowd.sim.scenarios import load_scenario

    trajectory = replay([load_policy("med"), load_policy("hi")], load_scenario(scenario), np.zeros((100, 10, 2)))
    assert trajectory.outcome.tolist() == [SUCCESS, SUCCESS]
    assert (trajectory.event_time <= 25.0).all()


def test_missing_files_and_unknown_names_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no agent file"):
        load_policy(str(tmp_path / "nope.pt"))
    with pytest.raises(ValueError, match="unknown agent 'nope'"):
        load_policy("nope")


def test_files_that_are_not_checkpoints_are_clear_errors(tmp_path):
    text = tmp_path / "notes.pt"
    text.write_text("not a checkpoint")
    with pytest.raises(ValueError, match="not a readable torch checkpoint"):
        load_policy(str(text))
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ValueError, match="not a Foil DS-RNN checkpoint"):
        load_policy(str(other))


def test_weights_that_do_not_fit_their_sizes_are_a_clear_error(tmp_path):
    net = make_net()
    path = tmp_path / "agent.pt"
    save_checkpoint(path, net)
    data = torch.load(path, weights_only=False)
    data["network"] = dataclasses.asdict(dataclasses.replace(NetworkConfig(**data["network"]), edge_hidden=32))
    torch.save(data, path)
    with pytest.raises(ValueError, match="do not fit the network sizes"):
        load_policy(str(path))


def test_old_observation_checkpoints_are_refused_with_what_to_do(tmp_path):
    """A format-1 checkpoint's network reads the robot node without the relative goal: loading it would act on
    the wrong inputs, so it is refused and the message says to retrain."""
    path = tmp_path / "old.pt"
    save_checkpoint(path, make_net())
    data = torch.load(path, weights_only=False)
    data["format"] = "foil.dsrnn/1"
    del data["observation"]
    torch.save(data, path)
    with pytest.raises(ValueError, match=r"older observation.*Retrain it with `foil train`"):
        load_policy(str(path))
    data["format"], data["observation"] = "foil.dsrnn/2", {"robot_node": ["px", "py"]}
    torch.save(data, path)
    with pytest.raises(ValueError, match="older observation"):
        load_policy(str(path))


def test_checkpoints_record_the_observation_layout(tmp_path):
    save_checkpoint(tmp_path / "agent.pt", make_net())
    data = read_checkpoint(tmp_path / "agent.pt")
    assert data["format"] == "foil.dsrnn/2"
    assert data["observation"] == {"robot_node": list(ROBOT_NODE_FIELDS)}
    assert data["model"]["robot_linear.weight"].shape[1] == len(ROBOT_NODE_FIELDS) == 12
