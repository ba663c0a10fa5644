"""The coupled highway problem on the kernel against GymCoupledProblem over highway-env: the same rewards,
events, positions and path lengths at every step, through snapshots, and the same search results."""

from dataclasses import replace

import numpy as np
import pytest

from search.core.rollout import Tracker
from search.gym.agents import load_agent
from search.gym.problem import GymCoupledProblem
from search.highway.adapter import HighwayAdapter
from search.highway.coupled import KernelCoupledProblem, coupled_problem
from search.highway.scenarios import SCENARIOS
from search.solvers.mcts import MCTSConfig, mcts
from search.solvers.reward import RewardConfig


def _drivers(*names):
    """Scripted drivers (tests/highway/drivers.py): the shipped agents' exactness is bench_highway_exact's."""
    return [load_agent(f"tests.highway.drivers:{name}", HighwayAdapter()) for name in names]


@pytest.fixture(scope="module")
def agents():
    return _drivers("idle", "slower")


def _same(reference: GymCoupledProblem, kernel: KernelCoupledProblem) -> None:
    assert np.array_equal(reference.t, kernel.t)
    for b, row in enumerate(reference.rows):
        for k, instance in enumerate(row):
            assert np.array_equal(instance.observation, kernel._rows.observations[b, k])
            assert (instance.outcome, instance.event_step) == (
                kernel._rows.outcome[b, k],
                kernel._rows.event_step[b, k],
            )
            assert instance.path_length == kernel._rows.path_length[b, k]
            row_index = b * len(row) + k
            position = [kernel.kernel.state.x[row_index, 0], kernel.kernel.state.y[row_index, 0]]
            assert np.array_equal(reference.adapter.position(instance.env), position)
        assert reference.measured(b) == kernel.measured(b)  # the visible score, step by step


@pytest.mark.parametrize("discrete", [False, True], ids=["continuous", "meta-actions"])
def test_steps_and_snapshots_as_the_highway_env_problem(agents, discrete):
    scenario = SCENARIOS["highway-dense"]
    scenario = replace(scenario, settings=scenario.settings | {"discrete": discrete})
    agents = _drivers("idle", "faster") if discrete else _drivers("cruise", "cautious")
    reference, kernel = GymCoupledProblem(agents, scenario), KernelCoupledProblem(agents, scenario)
    rng = np.random.default_rng(0)
    for problem in (reference, kernel):
        problem.reset(3)
    saved = None
    for step in range(8):
        actions = rng.uniform(-1, 1, (reference.batch, 8, 2))
        expected, got = reference.step(actions), kernel.step(actions)
        assert np.array_equal(expected[0], got[0]) and np.array_equal(expected[1], got[1])
        assert all(np.array_equal(a, b) for a, b in zip(reference.last_events, kernel.last_events, strict=True))
        _same(reference, kernel)
        if step == 2:
            saved = reference.snapshot([2, 0, 0]), kernel.snapshot([2, 0, 0])
        if step == 4:
            reference.restore(saved[0])
            kernel.restore(saved[1])
            _same(reference, kernel)
        if step == 6:
            reference.assign([1], reference.concat([reference.snapshot([0])]))
            kernel.assign([1], kernel.concat([kernel.snapshot([0])]))
            _same(reference, kernel)


def test_a_search_finds_the_same_scenarios(agents):
    scenario, found = SCENARIOS["highway-light"], []
    for problem in (GymCoupledProblem(agents, scenario), coupled_problem(agents, scenario, RewardConfig())):
        tracker = Tracker(2 * problem.horizon, 2)  # two whole trajectories, one per row
        mcts(problem, tracker, np.random.default_rng(0), MCTSConfig(batch=2))
        found.append([(f.reward, f.actions.tobytes()) for f in tracker.queue.ranked()])
    assert isinstance(problem, KernelCoupledProblem)
    assert found[0] == found[1] and len(found[0]) == 2
