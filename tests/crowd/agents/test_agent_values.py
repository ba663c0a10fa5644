"""Agents' own values of a state, which Agent Disagreements' last_state importance reads: a DS-RNN's value head
(the critic training uses), and a Stable-Baselines3 DQN agent's action values (highway)."""

from __future__ import annotations

import numpy as np
import torch

from search.core.domain import domain_for
from search.crowd.agents.dsrnn import observation_tensors


def test_a_dsrnn_value_is_its_critic_of_the_state_after_its_memory():
    domain = domain_for(["lo", "hi"], "paper-code")
    coupled = domain.coupled(["lo", "hi"], domain.state("paper-code", {}), {})
    problem = coupled.problem
    problem.reset(2)
    rng = np.random.default_rng(0)
    for _ in range(6):
        problem.step(rng.uniform(-0.25, 0.25, (2, *problem.action_shape)))
    sim, policy = problem.sim, problem.sim.policies[0]
    state = {key: value.copy() for key, value in sim.policy_states[0].items()}
    own, other = problem.values(0), problem.values(0, of=1)
    assert own.shape == (2,) and np.all(np.isfinite(own)) and not np.allclose(own, other)
    # the critic of the training network's forward pass (one step, no episode start) on the same inputs
    inputs = [t[None] for t in observation_tensors(sim.observations()[0], policy.max_humans)]
    hidden = [torch.from_numpy(state[f"h{i}"]) for i in range(len(state))]
    with torch.no_grad():
        _, values, _ = policy.net(*inputs, torch.zeros(1, 2), hidden)
    assert np.allclose(own, values[0].numpy(), atol=1e-5)
    assert all(np.array_equal(sim.policy_states[0][k], state[k]) for k in state)  # the memory is left as it was


def test_a_highway_dqn_agent_has_action_values_and_its_value_is_the_best():
    domain = domain_for(["highway-lo", "highway-hi"], "highway-dense")
    problem = domain.coupled(["highway-lo", "highway-hi"], domain.state("highway-dense", {}), {}).problem
    problem.reset(3)
    values, action_values = problem.values(1), problem.action_values(1)
    assert action_values.shape == (3, 5) and np.all(np.isfinite(action_values))  # one Q a meta-action
    assert np.array_equal(values, action_values.max(axis=1))
