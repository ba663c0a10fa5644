"""CrowdNav_DSRNN agents: the checkpoint as its training saves it, its config, and the forward pass against a
reference written here from the published architecture."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from search.cli import main
from search.crowd.agents.crowdnav import CrowdNavPolicy, read_config
from search.crowd.agents.policies import comparison_world, load_policy, trained_world
from search.crowd.sim.observation import Observation
from search.crowd.sim.world import WorldConfig
from tests.support.crowdnav import CONFIG, HUMANS, SIZES, config_text, random_state_dict, write_model


def _sigmoid(x):
    return 1 / (1 + np.exp(-x))


def _gru(p: dict, prefix: str, x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """PyTorch's GRU equations (gates r, z, n), in float64."""
    gi = x @ p[prefix + "weight_ih_l0"].T + p[prefix + "bias_ih_l0"]
    gh = h @ p[prefix + "weight_hh_l0"].T + p[prefix + "bias_hh_l0"]
    size = h.shape[-1]
    r = _sigmoid(gi[..., :size] + gh[..., :size])
    z = _sigmoid(gi[..., size : 2 * size] + gh[..., size : 2 * size])
    n = np.tanh(gi[..., 2 * size :] + r * gh[..., 2 * size :])
    return (1 - z) * n + z * h


def _linear(p: dict, prefix: str, x: np.ndarray) -> np.ndarray:
    return x @ p[prefix + "weight"].T + p[prefix + "bias"]


def reference_step(p: dict, robot_node, temporal, spatial, edge_h, node_h):
    """One acting step of CrowdNav_DSRNN's SRNN + DiagGaussian mean (srnn_model.py, model.py), in float64:
    edge RNNs (ReLU(linear) then GRU) for the temporal edge and each spatial edge, attention scores
    (temporal_embed . spatial_embed) * human_num / sqrt(attention_size) softmaxed over humans, node RNN on
    [ReLU(encoder(robot_linear(node))), ReLU(edge_attention_embed([h_temporal, attended]))], output linear,
    actor MLP, fc_mean."""
    relu = lambda x: np.maximum(x, 0)  # noqa: E731
    ht = _gru(
        p,
        "base.humanhumanEdgeRNN_temporal.gru.",
        relu(_linear(p, "base.humanhumanEdgeRNN_temporal.encoder_linear.", temporal)),
        edge_h[:, 0],
    )
    hs = _gru(
        p,
        "base.humanhumanEdgeRNN_spatial.gru.",
        relu(_linear(p, "base.humanhumanEdgeRNN_spatial.encoder_linear.", spatial)),
        edge_h[:, 1:],
    )
    query = _linear(p, "base.attn.temporal_edge_layer.0.", ht)
    keys = _linear(p, "base.attn.spatial_edge_layer.0.", hs)
    scores = np.einsum("ba,bna->bn", query, keys) * spatial.shape[1] / np.sqrt(SIZES["attention_size"])
    weights = np.exp(scores - scores.max(1, keepdims=True))
    weights /= weights.sum(1, keepdims=True)
    attended = np.einsum("bn,bnh->bh", weights, hs)
    encoded = relu(_linear(p, "base.humanNodeRNN.encoder_linear.", _linear(p, "base.robot_linear.", robot_node)))
    edges = relu(_linear(p, "base.humanNodeRNN.edge_attention_embed.", np.concatenate([ht, attended], -1)))
    hn = _gru(p, "base.humanNodeRNN.gru.", np.concatenate([encoded, edges], -1), node_h)
    x = _linear(p, "base.humanNodeRNN.output_linear.", hn)
    x = np.tanh(_linear(p, "base.actor.2.", np.tanh(_linear(p, "base.actor.0.", x))))
    return _linear(p, "dist.fc_mean.", x), np.concatenate([ht[:, None], hs], 1), hn


def observation(rng, batch: int, seen: np.ndarray) -> Observation:
    node = np.concatenate(
        [
            rng.uniform(-5, 5, (batch, 2)),
            np.full((batch, 1), 0.3),
            rng.uniform(-5, 5, (batch, 2)),
            np.ones((batch, 1)),
            rng.uniform(0, 6, (batch, 1)),
            np.zeros((batch, 5)),
        ],
        axis=1,
    )
    return Observation(
        robot_node=node,
        temporal_edges=rng.uniform(-1, 1, (batch, 2)),
        spatial_edges=rng.uniform(-4, 4, (batch, HUMANS, 2)),
        human_velocities=rng.uniform(-1, 1, (batch, HUMANS, 2)),
        human_radii=np.full((batch, HUMANS), 0.3),
        human_mask=seen,
        done=np.zeros(batch, bool),
    )


@pytest.mark.parametrize("legacy", [True, False], ids=["legacy-serialisation", "zip-serialisation"])
def test_forward_pass_equals_the_reference_on_a_checkpoint_in_the_original_format(tmp_path, legacy):
    checkpoint = write_model(tmp_path / "model", seed=3, legacy=legacy)
    policy = load_policy(str(checkpoint))
    assert isinstance(policy, CrowdNavPolicy)
    p = {name: value.double().numpy() for name, value in random_state_dict(3).items()}
    rng = np.random.default_rng(0)
    batch, dt = 4, CONFIG["env"]["time_step"]
    state = policy.initial_state(batch)
    edge_h, node_h = (
        np.zeros((batch, 1 + HUMANS, SIZES["human_human_edge_rnn_size"])),
        np.zeros((batch, SIZES["human_node_rnn_size"])),
    )
    believed = None
    for step in range(4):
        seen = rng.random((batch, HUMANS)) < 0.6
        obs = observation(rng, batch, seen)
        robot = obs.robot_node[:, :2]
        # what CrowdNav's robot believes: seen humans where they are, unseen ones at (15, 15) before the first
        # sighting, afterwards moved on at their last velocity
        humans = np.concatenate([robot[:, None] + obs.spatial_edges, obs.human_velocities], -1)
        if believed is None:
            unseen = np.broadcast_to([15.0, 15.0, 0.0, 0.0], humans.shape)
        else:
            unseen = np.concatenate([believed[..., :2] + dt * believed[..., 2:], believed[..., 2:]], -1)
        believed = np.where(seen[..., None], humans, unseen)
        node = obs.robot_node[:, :7].copy()
        node[:, 6] = math.pi / 2  # a holonomic CrowdNav robot never updates theta
        expected, edge_h, node_h = reference_step(
            p, node, obs.temporal_edges, believed[..., :2] - robot[:, None], edge_h, node_h
        )
        action, state = policy.act(obs, state)
        np.testing.assert_allclose(action, expected, atol=2e-5, err_msg=f"step {step}")
    assert action.shape == (batch, 2) and np.abs(action).max() > 0.05  # outputs that depend on the inputs


def test_policy_state_is_returned_not_kept(tmp_path):
    policy = load_policy(str(write_model(tmp_path / "model")))
    obs = observation(np.random.default_rng(1), 2, np.ones((2, HUMANS), bool))
    state = policy.initial_state(2)
    first, after = policy.act(obs, state)
    again, _ = policy.act(obs, state)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(after["edges"], state["edges"])


def test_config_parser_reads_every_key_and_maps_the_world(tmp_path):
    path = tmp_path / "config.py"
    path.write_text(config_text())
    config = read_config(path)
    assert set(config.values) == {(s, k) for s, values in CONFIG.items() for k in values}
    text_lines = path.read_text().splitlines()
    assert all(f"{s}.{k} =" in text_lines[line - 1] for (s, k), (_, line) in config.values.items())
    assert config.world == {
        "dt": 0.25,
        "randomize_attributes": True,
        "success_reward": 10.0,
        "collision_penalty": -20.0,
        "discomfort_dist": 0.25,
        "discomfort_factor": 10.0,
        "circle_radius": 6.0,
        "human_num": HUMANS,
        "human_policy": "orca",
        "human_radius": 0.3,
        "human_v_pref": 1.0,
        "robot_visible": False,
        "robot_radius": 0.3,
        "robot_v_pref": 1.0,
        "kinematics": "holonomic",
        "neighbor_dist": 10.0,
        "safety_space": 0.15,
        "time_horizon": 5.0,
        "sf_a": 2.0,
        "sf_b": 1.0,
        "sf_ki": 1.0,
        "time_limit": 49.0,
        "human_fov": 360.0,
        "robot_fov": 360.0,
        "goal_change_chance": 0.25,
        "end_goal_change_chance": 1.0,
    }
    assert config.sizes == SIZES
    WorldConfig.from_dict(config.world)


def test_config_with_switches_off_and_a_unicycle(tmp_path):
    changed = {
        **CONFIG,
        "humans": {**CONFIG["humans"], "random_goal_changing": False, "FOV": 1.0},
        "robot": {**CONFIG["robot"], "FOV": 0.5},
        "action_space": {"kinematics": "unicycle"},
    }
    path = tmp_path / "config.py"
    path.write_text(config_text(changed))
    world = read_config(path).world
    assert world["goal_change_chance"] == 0.0 and world["end_goal_change_chance"] == 1.0
    assert (world["human_fov"], world["robot_fov"]) == (180.0, 90.0)
    assert (world["kinematics"], world["unicycle_motion"], world["robot_start"]) == ("unicycle", "arc", "circle")


@pytest.mark.parametrize(
    ("section", "key", "value", "says"),
    [
        ("sim", "group_human", True, "Foil reproduces only False"),
        ("noise", "add_noise", True, "Foil reproduces only False"),
        ("humans", "random_unobservability", True, "Foil reproduces only False"),
        ("env", "env_name", "CrowdSimPred-v0", "Foil reproduces only 'CrowdSimDict-v0'"),
        ("humans", "policy", "srnn", "human_policy must be 'orca' or 'social_force'"),
        ("reward", "discomfort_dist_front", 0.5, "one discomfort distance"),
        ("robot", "FOV", 3, "multiples of pi"),
        ("sim", "lidar_range", 5, "does not know this setting"),
        ("sim", "human_num", 2.5, "expected a whole number"),
        ("action_space", "kinematics", "diff_drive", "kinematics must be 'holonomic' or 'unicycle'"),
        ("env", "time_limit", 1, "more than 1 s"),
        ("SRNN", "human_node_lstm_size", 16, "does not know this setting"),
    ],
)
def test_config_parser_refuses_what_foil_cannot_reproduce_naming_its_line(tmp_path, section, key, value, says):
    config = {s: dict(values) for s, values in CONFIG.items()}
    config[section][key] = value
    path = tmp_path / "config.py"
    path.write_text(config_text(config))
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if f"{section}.{key} =" in text)
    with pytest.raises(ValueError, match=says) as error:
        read_config(path)
    assert f"config.py:{line}: {section}.{key}" in str(error.value)


def test_config_parser_never_runs_the_file(tmp_path):
    path = tmp_path / "config.py"
    marker = tmp_path / "ran"
    path.write_text(config_text().replace("    sim.render = False", f"    sim.render = open({str(marker)!r}, 'w')"))
    with pytest.raises(ValueError, match=r"config.py:\d+: sim.render is not a plain value"):
        read_config(path)
    assert not marker.exists()


def test_clear_errors_for_another_network_and_a_missing_config(tmp_path):
    other = tmp_path / "other.pt"
    torch.save(torch.nn.Linear(3, 2).state_dict(), other)
    with pytest.raises(ValueError, match="state_dict of another network .*weight, bias"):
        load_policy(str(other))
    checkpoint = write_model(tmp_path / "model")
    (tmp_path / "model" / "configs" / "config.py").unlink()
    with pytest.raises(FileNotFoundError, match="no configs/config.py"):
        load_policy(str(checkpoint))
    broken = random_state_dict()
    broken["base.attn.spatial_edge_layer.0.weight"] = torch.zeros(5, 3)
    with pytest.raises(ValueError, match="weights do not fit"):
        load_policy(str(write_model(tmp_path / "broken", state_dict=broken)))


def test_config_sizes_must_be_the_checkpoints(tmp_path):
    config = {**CONFIG, "SRNN": {**SIZES, "attention_size": 64}}
    with pytest.raises(
        ValueError,
        match=r"config.py:\d+: SRNN.attention_size = 64, but the checkpoint's weights "
        "have 5",
    ):
        load_policy(str(write_model(tmp_path / "model", config=config)))


def test_the_agent_brings_its_world_and_explicit_settings_win(tmp_path):
    checkpoint = str(write_model(tmp_path / "model"))
    assert trained_world(checkpoint)["human_num"] == HUMANS
    assert trained_world("hi") == {} and trained_world("orca") == {}
    world = comparison_world(["hi", checkpoint], {"time_limit": 25.0})
    assert world["time_limit"] == 25.0 and world["goal_change_chance"] == 0.25
    # a scenario file's own [world] settings come between the trained world and the explicit ones
    assert "circle_radius" not in comparison_world([checkpoint], {}, {"circle_radius": 3.0})
    other = {**CONFIG, "sim": {**CONFIG["sim"], "circle_radius": 4}}
    second = str(write_model(tmp_path / "second", config=other))
    with pytest.raises(ValueError, match="trained in different worlds .*circle_radius"):
        comparison_world([checkpoint, second], {})
    assert comparison_world([checkpoint, second], {"circle_radius": 5.0})["circle_radius"] == 5.0


def test_foil_eval_runs_the_agent_in_its_own_world(tmp_path, capsys):
    checkpoint = str(write_model(tmp_path / "model"))
    assert main(["eval", checkpoint, "--episodes", "3", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["time_limit"] == 49.0  # CrowdNav ends episodes once its clock reaches time_limit - 1
    assert result["episodes"] == 3
    assert main(["eval", checkpoint, "--episodes", "3", "--json", "--time-limit", "5"]) == 0
    assert json.loads(capsys.readouterr().out)["time_limit"] == 5.0
    assert main(["eval", checkpoint, "--episodes", "3", "--world", "human_num=2"]) == 2  # the command line wins
    assert f"exactly {HUMANS} humans" in capsys.readouterr().err


def test_a_crowd_of_another_size_is_refused(tmp_path):
    policy = load_policy(str(write_model(tmp_path / "model")))
    obs = observation(np.random.default_rng(0), 1, np.ones((1, HUMANS), bool))
    obs.spatial_edges, obs.human_mask = obs.spatial_edges[:, :2], obs.human_mask[:, :2]
    with pytest.raises(ValueError, match=f"exactly {HUMANS} humans .*this world has 2"):
        policy.act(obs, policy.initial_state(1))


def test_a_unicycle_agent_observes_its_heading_and_turns_in_an_arc_world(tmp_path, capsys):
    unicycle = {**CONFIG, "action_space": {"kinematics": "unicycle"}}
    checkpoint = str(write_model(tmp_path / "model", config=unicycle))
    policy = load_policy(checkpoint)
    assert policy.world["kinematics"] == "unicycle" and policy.world["unicycle_motion"] == "arc"
    rng = np.random.default_rng(2)
    obs = observation(rng, 2, np.ones((2, HUMANS), bool))
    p = {name: value.double().numpy() for name, value in random_state_dict(0).items()}
    state = np.zeros((2, 1 + HUMANS, SIZES["human_human_edge_rnn_size"])), np.zeros((2, SIZES["human_node_rnn_size"]))
    expected, _, _ = reference_step(p, obs.robot_node[:, :7], obs.temporal_edges, obs.spatial_edges, *state)
    action, _ = policy.act(obs, policy.initial_state(2))  # the unicycle's own heading, not pi/2
    np.testing.assert_allclose(action, expected, atol=2e-5)
    assert main(["eval", checkpoint, "--episodes", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 2


def test_a_visible_robot_among_social_force_humans(tmp_path, capsys):
    changed = {
        **CONFIG,
        "robot": {**CONFIG["robot"], "visible": True},
        "humans": {**CONFIG["humans"], "policy": "social_force"},
    }
    checkpoint = str(write_model(tmp_path / "model", config=changed))
    assert trained_world(checkpoint)["robot_visible"] and trained_world(checkpoint)["human_policy"] == "social_force"
    assert main(["eval", checkpoint, "--episodes", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 2
