"""A small search problem with a known optimum, stepped in batches like the coupled simulator.

A combination lock: each step's action (one number in [-1, 1]) is right when it exceeds ``threshold``
(probability 0.2 under the uniform prior). A right action earns 1 and goes on; a wrong one ends the trajectory.
The optimum is ``horizon`` (every action right), which uniform sampling finds with probability 0.2**horizon.
"""

from __future__ import annotations

import numpy as np

from search.core.prior import ActionPrior


class LockProblem:
    def __init__(self, horizon: int = 8, threshold: float = 0.6):
        self.action_shape = (1,)
        self.horizon = horizon
        self.threshold = threshold
        self.prior = ActionPrior(self.action_shape, 1.0)
        self.reset(1)

    @property
    def batch(self) -> int:
        return self.depth.size

    def reset(self, batch: int) -> None:
        self.depth = np.zeros(batch, dtype=np.int64)

    def step(self, actions):
        right = np.asarray(actions)[:, 0] > self.threshold
        self.depth = self.depth + 1
        return right.astype(float), ~right | (self.depth >= self.horizon)

    def snapshot(self, index=None):
        return self.depth.copy() if index is None else self.depth[np.asarray(index)].copy()

    def restore(self, snapshot) -> None:
        self.depth = snapshot.copy()

    def concat(self, snapshots):
        return np.concatenate(snapshots)

    def assign(self, index, snapshot) -> None:
        self.depth[np.asarray(index)] = snapshot
