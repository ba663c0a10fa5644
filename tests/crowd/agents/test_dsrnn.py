"""The DS-RNN network and policy: shapes, masking across crowd sizes, determinism, recurrent state."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from search.crowd.agents.dsrnn import DSRNN, DSRNNPolicy, export_torchscript, load_torchscript
from search.crowd.sim.coupled import CoupledSimulator
from search.crowd.sim.observation import ROBOT_NODE_SIZE
from search.crowd.sim.scenarios import Scenario
from tests.support.agents import SMALL, make_net, random_observation


@pytest.mark.parametrize("humans", [0, 1, 4, 6])
def test_act_shapes_for_every_crowd_size_up_to_the_maximum(net, humans):
    policy = DSRNNPolicy(net)
    state = policy.initial_state(5)
    assert {k: v.shape for k, v in state.items()} == {"h0": (5, 16), "h1": (5, 6, 16), "h2": (5, 12)}
    action, new_state = policy.act(random_observation(5, humans), state)
    assert action.shape == (5, 2) and action.dtype == np.float64 and np.isfinite(action).all()
    assert {k: v.shape for k, v in new_state.items()} == {k: v.shape for k, v in state.items()}
    assert all(isinstance(v, np.ndarray) for v in new_state.values())


def test_more_humans_than_the_maximum_is_a_clear_error(net):
    policy = DSRNNPolicy(net)
    with pytest.raises(ValueError, match="at most 6 humans"):
        policy.act(random_observation(2, 7), policy.initial_state(2))


def test_absent_humans_do_not_change_the_action(net):
    """A crowd of 3 acts the same whether given alone or padded with masked humans at arbitrary places."""
    policy = DSRNNPolicy(net)
    small = random_observation(4, 3)
    padded = random_observation(4, 6, seed=1)
    padded = dataclasses.replace(
        padded,
        robot_node=small.robot_node,
        temporal_edges=small.temporal_edges,
        spatial_edges=np.concatenate([small.spatial_edges, padded.spatial_edges[:, 3:]], axis=1),
        human_mask=np.array([[True] * 3 + [False] * 3] * 4),
    )
    state_a, state_b = policy.initial_state(4), policy.initial_state(4)
    for _ in range(3):
        action_a, state_a = policy.act(small, state_a)
        action_b, state_b = policy.act(padded, state_b)
        np.testing.assert_allclose(action_a, action_b, atol=1e-6)
    full = dataclasses.replace(padded, human_mask=np.ones((4, 6), dtype=bool))
    assert not np.allclose(
        policy.act(full, policy.initial_state(4))[0], policy.act(small, policy.initial_state(4))[0], atol=1e-4
    )


def test_same_observation_and_state_give_the_same_action(net):
    policy = DSRNNPolicy(net)
    obs = random_observation(3, 5)
    state = policy.act(obs, policy.initial_state(3))[1]
    first, _ = policy.act(obs, state)
    second, _ = policy.act(obs, state)
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(first, DSRNNPolicy(make_net()).act(obs, state)[0])  # a rebuilt twin


def test_the_recurrent_state_matters_and_is_not_mutated(net):
    policy = DSRNNPolicy(net)
    obs = random_observation(3, 5)
    zero = policy.initial_state(3)
    _, later = policy.act(obs, zero)
    before = {k: v.copy() for k, v in later.items()}
    policy.act(obs, later)
    assert all(np.array_equal(before[k], later[k]) for k in later)
    assert not np.allclose(policy.act(obs, zero)[0], policy.act(obs, later)[0])


def test_sequence_forward_matches_stepping_with_resets(net):
    """PPO's sequence pass and the acting step agree, including hidden states zeroed at episode starts."""
    t, b, n = 5, 3, SMALL.max_humans
    torch.manual_seed(1)
    inputs = (torch.randn(t, b, ROBOT_NODE_SIZE), torch.randn(t, b, 2), torch.randn(t, b, n, 2), torch.ones(t, b, n))
    starts = torch.zeros(t, b)
    starts[2, 1] = 1.0
    hidden = [torch.randn_like(h) for h in net.initial_state(b)]
    with torch.no_grad():
        means, values, last = net(*inputs, starts, hidden)
        h = hidden
        for i in range(t):
            h = [x * (1 - starts[i]).reshape((-1,) + (1,) * (x.dim() - 1)) for x in h]
            mean, h = net.act_mean(*(x[i] for x in inputs), h)
            torch.testing.assert_close(mean, means[i])
    assert values.shape == (t, b)
    for a, b_ in zip(last, h, strict=True):
        torch.testing.assert_close(a, b_)


def sequence_with_absent_humans_and_resets(net: DSRNN, t: int = 6, b: int = 3):
    n = net.max_humans
    torch.manual_seed(2)
    mask = (torch.rand(t, b, n) > 0.3).float()
    inputs = (torch.randn(t, b, ROBOT_NODE_SIZE), torch.randn(t, b, 2), torch.randn(t, b, n, 2), mask)
    starts = torch.zeros(t, b)
    starts[3, 0] = starts[1, 2] = 1.0
    hidden = [torch.randn_like(h) for h in net.initial_state(b)]
    hidden[1] = hidden[1] * mask[0, :, :, None]
    return inputs, starts, hidden


def test_sequence_gradients_match_stepping(net):
    """PPO's gradients through the sequence pass equal autograd's through the acting step, with absent humans
    and episode starts in the sequence."""
    inputs, starts, hidden = sequence_with_absent_humans_and_resets(net)
    params = [p for name, p in net.named_parameters() if name != "action_logstd"]
    weights = torch.randn(inputs[0].shape[0], inputs[0].shape[1], 2)

    means, values, _ = net(*inputs, starts, hidden)
    sequence_grads = torch.autograd.grad((means * weights).sum() + values.square().sum(), params)

    h, loss = hidden, 0.0
    for i in range(inputs[0].shape[0]):
        h = [x * (1 - starts[i]).reshape((-1,) + (1,) * (x.dim() - 1)) for x in h]
        features, h = net.step(*(x[i] for x in inputs), h)
        loss = loss + (net.action_mean(net.actor(features)) * weights[i]).sum()
        loss = loss + net.critic_linear(net.critic(features)).square().sum()
    step_grads = torch.autograd.grad(loss, params)
    for name, a, b in zip(
        [n for n, _ in net.named_parameters() if n != "action_logstd"], sequence_grads, step_grads, strict=True
    ):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5, msg=name)


def test_bfloat16_products_keep_float32_state_and_outputs(net):
    inputs, starts, hidden = sequence_with_absent_humans_and_resets(net)
    exact = net(*inputs, starts, hidden)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        low = net(*inputs, starts, hidden)
    assert all(x.dtype == torch.float32 for x in (low[0], low[1], *low[2]))
    torch.testing.assert_close(low[0], exact[0], rtol=0.05, atol=0.05)
    torch.testing.assert_close(low[1], exact[1], rtol=0.05, atol=0.05)
    assert not torch.equal(low[0], exact[0])  # the products did run in bfloat16


def test_snapshot_and_restore_in_the_coupled_simulator():
    scenario = Scenario(
        name="six",
        robot_start=(-5.0, 4.0),
        robot_goal=(7.0, -2.0),
        human_positions=((0, 0), (1, 1), (-1, 2), (2, -1), (3, 3), (-2, -2)),
        human_goals=((0, 1), (-1, -1), (1, -2), (-2, 1), (-3, -3), (2, 2)),
    )
    policies = [DSRNNPolicy(make_net(0), "a"), DSRNNPolicy(make_net(1), "b")]
    sim = CoupledSimulator(policies, scenario, batch=2)
    zero = np.zeros((2, 6, 2))
    for _ in range(4):
        sim.step(zero)
    snapshot = sim.snapshot()
    first = [sim.step(zero).agent_actions for _ in range(5)]
    sim.restore(snapshot)
    second = [sim.step(zero).agent_actions for _ in range(5)]
    np.testing.assert_array_equal(np.array(first), np.array(second))
    assert not np.allclose(first[-1][:, 0], first[-1][:, 1])  # two different networks really act differently


def test_torchscript_export_acts_like_the_network(net, tmp_path):
    path = tmp_path / "agent.ts"
    export_torchscript(net, path)
    scripted = load_torchscript(path, "scripted")
    policy = DSRNNPolicy(net)
    obs = random_observation(4, 3)
    a_state, b_state = policy.initial_state(4), scripted.initial_state(4)
    for _ in range(2):
        a, a_state = policy.act(obs, a_state)
        b, b_state = scripted.act(obs, b_state)
        np.testing.assert_allclose(a, b, atol=1e-6)
