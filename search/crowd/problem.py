"""The paper's problem: the agents under comparison in one coupled simulator, scored by the divergence reward."""

from __future__ import annotations

import numpy as np

from search.sim.coupled import CoupledSimulator, Snapshot
from search.sim.observation import Policy
from search.sim.scenarios import Scenario
from search.sim.world import WorldConfig, WorldState
from search.solvers.prior import ActionPrior
from search.solvers.reward import DivergenceReward, RewardConfig


class CoupledProblem:
    """The agents under comparison in one coupled simulator, scored by the divergence reward."""

    def __init__(
        self,
        policies: list[Policy],
        scenario: Scenario,
        world: WorldConfig | None = None,
        reward: RewardConfig | None = None,
    ):
        self.sim = CoupledSimulator(policies, scenario, world, batch=1)
        self.reward_config = reward or RewardConfig()
        config = self.sim.config
        self.action_shape = (config.human_num, 2)
        self.horizon = self.reward_config.horizon
        self.prior = ActionPrior(
            self.action_shape, config.env_action_bound, self.reward_config.prior, self.reward_config.prior_sigma
        )
        self.reward = DivergenceReward(self.reward_config, self.prior)

    @property
    def batch(self) -> int:
        return self.sim.batch

    def reset(self, batch: int) -> None:
        self.sim.reset(batch)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sim = self.sim
        robot_actions, _, newly_done = sim.advance(actions)
        state, batch = sim.state, sim.batch
        t = np.rint(state.time[:batch] / sim.config.dt).astype(np.int64)
        goal, end = self.reward.events(newly_done, sim.gather(state.outcome), sim.gather(state.done).all(axis=1), t)
        reward = self.reward.step(
            robot_actions, sim.gather(state.robot_pos), state.human_pos[:batch], actions, goal, end
        )
        return reward, goal | end

    def snapshot(self, index=None) -> Snapshot:
        return self.sim.snapshot(index)

    def restore(self, snapshot: Snapshot) -> None:
        self.sim.restore(snapshot)

    def assign(self, index, snapshot: Snapshot) -> None:
        self.sim.assign(index, snapshot)

    def concat(self, snapshots: list[Snapshot]) -> Snapshot:
        return concat_snapshots(snapshots)


def concat_snapshots(snapshots: list[Snapshot]) -> Snapshot:
    """Rows of several coupled snapshots as one. A snapshot of B rows holds ``copies * B`` worlds, copy-major
    (one world copy per agent when robots are visible), so worlds are joined copy by copy."""
    if len(snapshots) == 1:
        return snapshots[0]
    copies = snapshots[0].state.n_worlds // snapshots[0].batch

    def join(arrays: list[np.ndarray], batches: list[int]) -> np.ndarray:
        if copies == 1:  # the shared crowd: rows are worlds
            return np.concatenate(arrays)
        parts = [a.reshape(copies, b, *a.shape[1:]) for a, b in zip(arrays, batches, strict=True)]
        joined = np.concatenate(parts, axis=1)
        return joined.reshape(-1, *joined.shape[2:])

    batches = [s.batch for s in snapshots]
    state = WorldState.of_rows(join([s.state.rows for s in snapshots], batches), snapshots[0].state.layout)
    policy_states = [
        {key: np.concatenate([s.policy_states[k][key] for s in snapshots]) for key in snapshots[0].policy_states[k]}
        for k in range(len(snapshots[0].policy_states))
    ]
    return Snapshot(state, policy_states, sum(batches))
