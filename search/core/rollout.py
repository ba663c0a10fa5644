"""What every solver shares: the step budget, the top-K queue, the best-so-far curve, and batched rollouts.

The budget is a bound on the simulator steps a search takes (each row of a batch stepped once is one step): no
solver steps a row the budget no longer pays for. The replays that turn kept trajectories into summaries are not
searching and are not counted."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import cast

import numpy as np

from search.core.problem import Problem
from search.core.topk import TopK


class Tracker:
    """Counts simulator steps against the budget and collects finished trajectories.

    ``curve`` holds ``(sim_steps, best_reward)`` each time the best reward improves, with the steps counted when
    that trajectory finished, so solvers that batch differently compare on the same axis.
    """

    def __init__(self, budget: int, top_k: int, progress: bool = False, description: str = "search"):
        if budget < 1:
            raise ValueError("the budget must be at least 1 simulator step")
        self.budget = int(budget)
        self.steps = 0
        self.trajectories = 0
        self.queue = TopK(top_k)
        self.curve: list[tuple[int, float]] = []
        self.best = -np.inf
        self._bar = None
        if progress:
            from tqdm import tqdm

            self._bar = tqdm(total=self.budget, unit="step", unit_scale=True, desc=description, leave=False)

    @property
    def exhausted(self) -> bool:
        return self.steps >= self.budget

    @property
    def remaining(self) -> int:
        return max(self.budget - self.steps, 0)

    def affordable(self, count: int, longest: int) -> int:
        """How many of ``count`` new trajectories fit in the remaining budget (at least one): at their mean cost so
        far, or before any has finished at ``longest``, the most steps one can take. Few of a batch's trajectories
        are then cut short where the budget ends."""
        if not self.trajectories:
            return max(1, min(count, self.remaining // longest))
        return max(1, min(count, math.ceil(self.remaining / (self.steps / self.trajectories))))

    def count(self, steps: int) -> None:
        self.steps += int(steps)
        if self._bar is not None:
            self._bar.update(min(int(steps), cast(float, self._bar.total) - self._bar.n))  # total: the budget

    def finish(self, reward: float, actions: np.ndarray) -> None:
        self.trajectories += 1
        reward = float(reward)
        self.queue.push(reward, actions, self.steps)
        if reward > self.best:
            self.best = reward
            self.curve.append((self.steps, reward))

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def fresh(problem: Problem, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` new trajectories at the initial state: action buffer, lengths and returns for ``rollout``."""
    problem.reset(count)
    return (np.zeros((count, problem.horizon, *problem.action_shape)), np.zeros(count, dtype=np.int64), np.zeros(count))


def rollout(
    problem: Problem,
    tracker: Tracker,
    actions: np.ndarray,
    lengths: np.ndarray,
    returns: np.ndarray,
    choose: Callable[[np.ndarray, np.ndarray], np.ndarray],
    max_steps: int | None = None,
    on_step: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
) -> np.ndarray:
    """Step the problem's current rows until each trajectory ends, batched, dropping rows as they end.

    ``actions`` (B, H, *shape) holds each row's environment actions from the initial state (``lengths`` (B,) of
    them so far) and ``returns`` (B,) its reward so far; both are extended in place. ``choose(rows, depth)``
    gives the next actions of the rows still running (their original indices and current lengths). Finished
    trajectories go to the tracker. ``on_step(taken, rows, terminal)`` sees the batch after each step, before
    ended rows are dropped (MCTS snapshots its new tree nodes there). The budget is a bound: a step takes only the
    rows the budget still pays for, and the others stop unfinished. Returns which rows ended; the others were cut by
    ``max_steps`` or the budget.
    """
    rows = np.arange(problem.batch)
    ended = np.zeros(problem.batch, dtype=bool)
    taken = 0
    while rows.size and (max_steps is None or taken < max_steps):
        if rows.size > tracker.remaining:
            rows = rows[: tracker.remaining]
            if not rows.size:
                break
            problem.restore(problem.snapshot(np.arange(rows.size)))
        step_actions = choose(rows, lengths[rows])
        reward, terminal = problem.step(step_actions)
        tracker.count(rows.size)
        actions[rows, lengths[rows]] = step_actions
        lengths[rows] += 1
        returns[rows] += reward
        taken += 1
        if on_step is not None:
            on_step(taken, rows, terminal)
        if terminal.any():
            for row in rows[terminal]:
                tracker.finish(returns[row], actions[row, : lengths[row]])
            ended[rows[terminal]] = True
            keep = np.flatnonzero(~terminal)
            if keep.size:
                problem.restore(problem.snapshot(keep))
            rows = rows[keep]
    return ended
