"""What a solver searches: a batched, branchable, deterministic environment with a reward.

Solvers see only this protocol, so the same MCTS runs on the coupled crowd simulator
(`search.crowd.problem`) and on small synthetic problems with a known optimum (the tests use one).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from search.solvers.prior import ActionPrior


class Problem(Protocol):
    """B rows stepped together; each row is one trajectory from the problem's fixed initial state."""

    action_shape: tuple[int, ...]
    horizon: int  # no trajectory is longer
    prior: ActionPrior

    @property
    def batch(self) -> int: ...

    def reset(self, batch: int) -> None: ...

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance every row by one action (B, *action_shape); return (reward (B,), terminal (B,))."""

    def snapshot(self, index=None) -> Any:
        """A copy of rows ``index`` (all by default; indices may repeat)."""

    def restore(self, snapshot) -> None:
        """Continue from a snapshot; the batch becomes its rows."""

    def concat(self, snapshots: list) -> Any:
        """One snapshot holding the rows of several, in order."""

    def assign(self, index, snapshot) -> None:
        """Overwrite rows ``index`` with a snapshot's rows (as many); the other rows go on untouched. Optional:
        MCTS rebuilds the batch with snapshot/concat/restore where a problem lacks it (more slowly)."""
