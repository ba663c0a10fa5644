"""A Gymnasium wrapper around one world with one robot, for use with the RL ecosystem.

Observations are DS-RNN's dict (robot_node, temporal_edges, spatial_edges) as float32; the action is the
robot's velocity (holonomic) or (dv, dtheta) (unicycle). Episodes start from the random training distribution,
or from a fixed scenario when one is given. An optional ``env_action_fn(rng, n_humans)`` perturbs the crowd.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike

from search.core.outcomes import COLLISION, OUTCOME_NAMES, SUCCESS, TIMEOUT
from search.crowd.sim import world
from search.crowd.sim.observation import ROBOT_NODE_SIZE, observe
from search.crowd.sim.scenarios import Scenario, sample_training_states
from search.crowd.sim.world import WorldConfig, WorldState


class CrowdNavEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(
        self,
        config: WorldConfig | None = None,
        scenario: Scenario | None = None,
        env_action_fn: Callable[[np.random.Generator, int], ArrayLike] | None = None,
    ) -> None:
        self.scenario = scenario
        self.config = scenario.config(config) if scenario else (config or WorldConfig())
        self.env_action_fn = env_action_fn
        n = self.config.human_num
        bound = 1e3  # metres and m/s: far beyond any reachable position or speed
        self.observation_space = spaces.Dict(
            {
                "robot_node": spaces.Box(-bound, bound, (ROBOT_NODE_SIZE,), np.float32),
                "temporal_edges": spaces.Box(-bound, bound, (2,), np.float32),
                "spatial_edges": spaces.Box(-bound, bound, (n, 2), np.float32),
            }
        )
        if self.config.kinematics == "holonomic":
            v = self.config.robot_v_pref
            self.action_space = spaces.Box(-v, v, (2,), np.float32)
        else:
            limit = np.array([self.config.unicycle_max_dv, self.config.unicycle_max_dtheta], np.float32)
            self.action_space = spaces.Box(-limit, limit, (2,), np.float32)
        self.state: WorldState | None = None

    def _observation(self, state: WorldState) -> dict[str, np.ndarray]:
        obs = observe(state, self.config, robot=0)
        return {
            "robot_node": obs.robot_node[0].astype(np.float32),
            "temporal_edges": obs.temporal_edges[0].astype(np.float32),
            "spatial_edges": obs.spatial_edges[0].astype(np.float32),
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        if self.scenario is not None:
            self.state = self.scenario.initial_state(self.config)
        else:
            self.state = sample_training_states(self.config, self.np_random, 1)
        return self._observation(self.state), {}

    def step(self, action: ArrayLike) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        env_action = None
        if self.env_action_fn is not None:
            env_action = np.asarray(self.env_action_fn(self.np_random, self.config.human_num))[None]
        robot_action = np.asarray(action, dtype=np.float64).reshape(1, 1, 2)
        reward = float(world.step(self.state, self.config, robot_action, env_action)[0, 0])
        outcome = int(self.state.outcome[0, 0])
        terminated = outcome in (SUCCESS, COLLISION)
        truncated = outcome == TIMEOUT
        info = {"outcome": OUTCOME_NAMES[outcome], "time": float(self.state.time[0])}
        return self._observation(self.state), reward, terminated, truncated, info
