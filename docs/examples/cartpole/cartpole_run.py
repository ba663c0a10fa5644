"""Snapshots of one training run of a CartPole controller, for a study of updates (studies/cartpole-updates.toml).

The controller pushes the cart the way a weighted sum of its observation (x, x_dot, theta, theta_dot) leans. The
run (`train`) starts from `cartpole_push.nudge`'s weights and at every update tries weights perturbed at random
(seeded), keeping them when the new weights' training episode in gusts lasts at least 60% as long as the kept
ones' did: a noisy learner, so some updates help, some hurt, and some are rejected (the snapshot is then the same
controller as the one before it). `snapshot_K` is the controller after update K. `train()` gives the weights again.
"""

from __future__ import annotations

import gymnasium
import numpy as np
from cartpole_push import GUST

# The weights after each update of `train()`, as it gives them (rounded to 6 decimals)
WEIGHTS = [
    [0.0, 0.0, 1.0, 0.0],
    [0.075438, -0.079263, 1.384254, 0.06294],
    [-0.245963, 0.137694, 2.166654, 0.631189],
    [-0.245963, 0.137694, 2.166654, 0.631189],
]


def _episode(weights: np.ndarray, seed: int) -> float:
    """Steps one training episode lasts in random gusts (CartPole's reward)."""
    env = gymnasium.make("CartPole-v1")
    observation, _ = env.reset(seed=seed)
    gusts = np.random.default_rng(seed)
    for step in range(500):
        x, x_dot, theta, theta_dot = env.unwrapped.state
        env.unwrapped.state = (x, x_dot, theta, theta_dot + GUST * gusts.uniform(-1, 1))
        observation, _, terminated, truncated, _ = env.step(int(observation @ weights > 0))
        if terminated or truncated:
            return step + 1.0
    return 500.0


def train(updates: int = len(WEIGHTS) - 1) -> list[list[float]]:
    """The run: the weights after each update, the first the starting weights."""
    rng = np.random.default_rng(0)
    weights = np.array(WEIGHTS[0])
    kept = _episode(weights, 0)
    run = [weights.round(6).tolist()]
    for update in range(1, updates + 1):
        tried = weights + rng.normal(0.0, 0.6, 4)
        lasted = _episode(tried, 100 * update)
        if lasted >= 0.6 * kept:
            weights, kept = tried, lasted
        run.append(weights.round(6).tolist())
    return run


def _snapshot(weights: list[float]):
    def controller(observations):
        return (np.asarray(observations, dtype=np.float64) @ np.asarray(weights) > 0).astype(np.int64)

    return controller


snapshot_0, snapshot_1, snapshot_2, snapshot_3 = (_snapshot(w) for w in WEIGHTS)
