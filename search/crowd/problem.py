"""The paper's problem: the agents under comparison in one coupled simulator, scored by the divergence reward."""

from __future__ import annotations

import numpy as np

from search.core.prior import ActionPrior
from search.core.problem import box_alternatives
from search.crowd.sim.coupled import CoupledSimulator, Snapshot
from search.crowd.sim.observation import Policy
from search.crowd.sim.scenarios import Scenario
from search.crowd.sim.world import WorldConfig, WorldState
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
        self.agent_rewards = np.zeros((1, len(policies)))  # each agent's own reward on the last step

    @property
    def batch(self) -> int:
        return self.sim.batch

    def reset(self, batch: int) -> None:
        self.sim.reset(batch)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sim = self.sim
        agent_actions, agent_rewards, newly_done = sim.advance(actions)
        self.agent_rewards = sim.gather(agent_rewards)
        state, batch = sim.state, sim.batch
        t = np.rint(state.time[:batch] / sim.config.dt).astype(np.int64)
        goal, end = self.reward.events(newly_done, sim.gather(state.outcome), sim.gather(state.done).all(axis=1), t)
        reward = self.reward.step(
            agent_actions, sim.gather(state.robot_pos), state.human_pos[:batch], actions, goal, end
        )
        return reward, goal | end

    # what the summary methods of the literature need (search.solvers.follow, disagreements, highlights)
    @property
    def override(self):
        return self.sim.override

    @override.setter
    def override(self, override) -> None:
        self.sim.override = override

    @property
    def proposed(self) -> list[np.ndarray]:
        """Each agent's own choice on the last step, (B, 2) per agent."""
        return list(self.sim.proposed.transpose(1, 0, 2))

    def action_gap(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(B,) how far apart two agents' velocities are, in units of the robot's preferred speed."""
        return np.linalg.norm(a - b, axis=-1) / self.sim.config.robot_v_pref

    def alternatives(self, action: np.ndarray) -> list[np.ndarray]:
        """Actions a robot might have taken instead of ``action`` (B, 2): itself, then each velocity coordinate
        at either end of the preferred speed."""
        speed = self.sim.config.robot_v_pref
        return box_alternatives(action, np.full(2, -speed), np.full(2, speed))

    def features(self) -> np.ndarray:
        """(B, F) what a clip shows of each row: the first robot's position and velocity and every human's."""
        sim, batch = self.sim, self.sim.batch
        robot = np.concatenate([sim.gather(sim.state.robot_pos)[:, 0], sim.gather(sim.state.robot_vel)[:, 0]], axis=1)
        humans = sim.state.human_pos[:batch].reshape(batch, -1)
        return np.concatenate([robot, humans], axis=1)

    def values(self, agent: int, of: int | None = None) -> np.ndarray | None:
        """(B,) agent ``agent``'s estimate of the value of robot ``of``'s state (its own by default), with its own
        memory, where its policy has a value."""
        policy, sim = self.sim.policies[agent], self.sim
        if not hasattr(policy, "value"):
            return None
        seen = sim.observations()[agent if of is None else of]
        return np.asarray(policy.value(seen, sim.policy_states[agent]), dtype=np.float64)

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
