"""B highway environments behind one interface: the kernel (search.highway.kernel) where it covers the settings,
highway-env itself, one environment at a time, where it does not (with a one-line notice, never silently).

Both take the same calls: ``reset(seeds, rows)``, ``apply(env_action, rows)`` (Foil's environment action),
``step(actions, rows)`` -> (observations, rewards, terminated, truncated) and ``snapshot()``/``restore()``;
``rows`` selects the environments a call acts on (default: all).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from search.highway.adapter import HighwayAdapter
from search.highway.kernel import HighwayKernel, HighwayState, adapter_spec, notice


class EnvBatch:
    """highway-env environments stepped one at a time: the fallback for settings the kernel does not cover."""

    def __init__(self, adapter: HighwayAdapter, batch: int):
        self.adapter, self.batch = adapter, batch
        self.envs = [adapter.make() for _ in range(batch)]

    def _rows(self, rows: np.ndarray | list[int] | None) -> np.ndarray:
        return np.arange(self.batch) if rows is None else np.asarray(rows)

    def reset(self, seeds: Sequence[int | None] | np.ndarray, rows: np.ndarray | list[int] | None = None) -> np.ndarray:
        pairs = zip(self._rows(rows), seeds, strict=True)
        return np.stack([self.envs[b].reset(seed=None if s is None else int(s))[0] for b, s in pairs])

    def apply(self, env_action: np.ndarray, rows: np.ndarray | list[int] | None = None) -> None:
        for b, action in zip(self._rows(rows), np.asarray(env_action), strict=True):
            self.adapter.apply(self.envs[b], action)

    def step(
        self, actions: np.ndarray, rows: np.ndarray | list[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        results = [self.envs[b].step(a)[:4] for b, a in zip(self._rows(rows), actions, strict=True)]
        observations, rewards, terminated, truncated = zip(*results, strict=True)
        return np.stack(observations), np.array(rewards), np.array(terminated), np.array(truncated)

    def ego(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ego's speed (m/s) and lane index in environments ``rows``."""
        egos = [self.envs[b].unwrapped.vehicle for b in rows]
        return np.array([v.speed for v in egos]), np.array([v.lane_index[2] for v in egos])

    def snapshot(self) -> list:
        return [self.adapter.snapshot_env(env) for env in self.envs]

    def restore(self, snapshot: list) -> None:
        self.envs = [self.adapter.restore_env(saved) for saved in snapshot]


class KernelBatch(HighwayKernel):
    """The kernel with the batch interface's snapshots."""

    def ego(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ego's speed (m/s) and lane index in environments ``rows``."""
        return self.state.speed[rows, 0].copy(), self.state.lane[rows, 0].copy()

    def snapshot(self) -> HighwayState:
        return self.state.copy()

    def restore(self, snapshot: HighwayState) -> None:
        self.state = snapshot.copy()


def make_batch(batch: int, settings: dict | None = None) -> KernelBatch | EnvBatch:
    """B highway environments with the adapter's settings (``discrete`` and highway-env config keys): the kernel,
    or highway-env itself with a one-line notice saying what the kernel does not cover."""
    adapter = HighwayAdapter(settings)
    spec = adapter_spec(adapter)
    if isinstance(spec, str):
        notice(spec)
        return EnvBatch(adapter, batch)
    return KernelBatch(spec, batch)
