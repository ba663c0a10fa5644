"""The bounded top-K queue of trajectories that every solver fills."""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np


@dataclass(order=True)
class Found:
    """One complete trajectory: its environment actions from the initial state and the reward the search saw.

    Ordered by (reward, -arrival), so among equal rewards the one found first ranks higher: ties are broken by
    search order, which a seed fixes.
    """

    reward: float
    arrival: int  # stored negated for ordering; see TopK.push
    actions: np.ndarray = field(compare=False)  # (L, *action_shape)
    sim_steps: int = field(compare=False, default=0)  # simulator steps the search had used when it finished


class TopK:
    """The K best trajectories by reward; an action sequence already held is rejected."""

    def __init__(self, k: int):
        if k < 1:
            raise ValueError("top-k must be at least 1")
        self.k = k
        self._heap: list[Found] = []  # min-heap: the worst kept entry first
        self._keys: set[bytes] = set()
        self._arrivals = 0

    def __len__(self) -> int:
        return len(self._heap)

    def admits(self, reward: float) -> bool:
        """Whether a trajectory of this reward may be kept: there is room, or it beats the worst kept one (equal
        rewards: the first found wins). A solver can skip assembling the actions of one that may not."""
        return len(self._heap) < self.k or reward > self._heap[0].reward

    def push(self, reward: float, actions: np.ndarray, sim_steps: int = 0) -> bool:
        """Offer a trajectory; True if it was kept."""
        if not self.admits(reward):
            return False
        actions = np.ascontiguousarray(actions, dtype=np.float64)
        key = _key(actions)
        if key in self._keys:
            return False
        self._arrivals += 1
        entry = Found(float(reward), -self._arrivals, actions.copy(), sim_steps)
        if len(self._heap) < self.k:
            heapq.heappush(self._heap, entry)
        elif entry > self._heap[0]:
            dropped = heapq.heapreplace(self._heap, entry)
            self._keys.discard(_key(dropped.actions))
        else:
            return False
        self._keys.add(key)
        return True

    @property
    def best(self) -> float:
        return max(self._heap).reward if self._heap else -np.inf

    def ranked(self) -> list[Found]:
        """Kept trajectories, best first."""
        return sorted(self._heap, reverse=True)


def _key(actions: np.ndarray) -> bytes:
    rows: int = actions.shape[0]
    return rows.to_bytes(4, "little") + actions.tobytes()
