"""A tiny Gymnasium environment written for the tests, with an adapter made from the documented template.

A walker crosses a corridor from (0, 0) to the goal (5, 0); an obstacle on the line x = 2.5 slides up and down,
driven by the environment action; a little random wind (from the environment's own generator) pushes the
walker, so a snapshot that forgot the generator would show. Actions are velocities (Box) or one of five moves
(Discrete).
"""

from __future__ import annotations

import gymnasium
import numpy as np

from search.api import Adapter

GOAL = np.array([5.0, 0.0])
MOVES = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


class Corridor(gymnasium.Env):
    dt, max_steps, radius = 0.5, 40, 0.5

    def __init__(self, discrete: bool = False):
        self.discrete = discrete
        self.action_space = (
            gymnasium.spaces.Discrete(5) if discrete else gymnasium.spaces.Box(-1.0, 1.0, (2,), dtype=np.float64)
        )
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (4,), dtype=np.float64)
        self.obstacle_velocity = 0.0

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.walker, self.obstacle])

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.walker = np.zeros(2)
        self.obstacle = np.array([2.5, self.np_random.uniform(-1.0, 1.0)])
        self.steps = 0
        return self._observation(), {}

    def step(self, action):
        velocity = MOVES[int(action)] if self.discrete else np.clip(action, -1.0, 1.0)
        self.walker = self.walker + self.dt * velocity + self.np_random.normal(0.0, 0.01, 2)
        self.obstacle = self.obstacle + [0.0, self.dt * self.obstacle_velocity]
        self.steps += 1
        crashed = bool(np.linalg.norm(self.walker - self.obstacle) < self.radius)
        arrived = bool(np.linalg.norm(self.walker - GOAL) < 0.3)
        info = {"crashed": crashed, "is_success": arrived}
        return (
            self._observation(),
            float(arrived) - float(crashed),
            crashed or arrived,
            self.steps >= self.max_steps,
            info,
        )


class CorridorAdapter(Adapter):
    """The template filled in: the environment action is the obstacle's vertical speed (at most 1 m/s)."""

    env_action_shape = (1,)
    dt = Corridor.dt

    def make(self, render=False):
        return Corridor(discrete=bool(self.settings.get("discrete", False)))

    def apply(self, env, action):
        env.unwrapped.obstacle_velocity = float(action[0])

    def position(self, env):
        return env.unwrapped.walker

    def others(self, env):
        return [env.unwrapped.obstacle.tolist()]


def straight(observations):
    """Walks straight at the goal."""
    return np.tile([1.0, 0.0], (len(observations), 1))


def dodging(observations):
    """Walks at the goal, stepping aside when the obstacle is near ahead."""
    near = (np.abs(observations[:, 2] - observations[:, 0]) < 1.5) & (
        np.abs(observations[:, 3] - observations[:, 1]) < 1.0
    )
    side = np.where(observations[:, 3] > observations[:, 1], -1.0, 1.0)
    return np.stack([np.where(near, 0.3, 1.0), np.where(near, side, -0.5 * observations[:, 1])], axis=1)


def straight_moves(observations):
    return np.ones(len(observations), dtype=np.int64)


def dodging_moves(observations):
    actions = dodging(observations)
    return np.where(np.abs(actions[:, 1]) > 0.6, np.where(actions[:, 1] > 0, 3, 4), 1)


class FastCorridorAdapter(CorridorAdapter):
    """The same world with the faster state get/set hook: a snapshot is the few numbers that make the state (the
    random generator's included), and a restore writes them into a fresh environment."""

    def snapshot_env(self, env):
        e = env.unwrapped
        return (
            e.discrete,
            e.walker.copy(),
            e.obstacle.copy(),
            e.steps,
            e.obstacle_velocity,
            e.np_random.bit_generator.state,
        )

    def restore_env(self, saved):
        discrete, walker, obstacle, steps, velocity, rng_state = saved
        env = Corridor(discrete)
        env.reset(seed=0)
        env.walker, env.obstacle, env.steps, env.obstacle_velocity = walker.copy(), obstacle.copy(), steps, velocity
        env.np_random.bit_generator.state = rng_state
        return env
