"""Episodes for the summary methods that watch agents play (Agent Disagreements, HIGHLIGHTS): where they start and
under which environment actions they run, the same for every agent compared.

From a fixed scenario the first episode runs without pushes and the others under environment actions drawn
uniformly within their bound (the world's own variation, as the representative solver's rollouts); from a
distribution each episode starts from its own drawn state, without pushes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from search.solvers.rollout import Tracker


@dataclass
class Episodes:
    """Episodes from one starting state: its coupled problem and each episode's environment actions."""

    coupled: Any  # a search.solvers.domain.Coupled
    env: np.ndarray  # (E, horizon, *action_shape)
    first: int  # the index of its first episode among all episodes


def draw_episodes(coupled_of: Callable[[Any], Any], states: list, count: int, rng: np.random.Generator) -> list:
    """``count`` episodes: from a single state, one without pushes then uniform pushes; from several drawn
    states, one episode each without pushes. ``coupled_of(state)`` is the coupled problem of a state."""
    if len(states) == 1:
        coupled = coupled_of(states[0])
        problem = coupled.problem
        env = np.zeros((count, problem.horizon, *problem.action_shape))
        bound = problem.prior.bound
        env[1:] = rng.uniform(-bound, bound, env[1:].shape)
        return [Episodes(coupled, env, 0)]
    found = []
    for index, state in enumerate(states[:count]):
        coupled = coupled_of(state)
        problem = coupled.problem
        found.append(Episodes(coupled, np.zeros((1, problem.horizon, *problem.action_shape)), index))
    return found


def continuing(env: np.ndarray, start: int, steps: int) -> np.ndarray:
    """An episode's environment actions (horizon, ...) from step ``start`` on, ``steps`` of them (none beyond the
    horizon: zero there)."""
    part = env[start : start + steps]
    return np.concatenate([part, np.zeros((steps - len(part), *env.shape[1:]))])


def play(
    problem,
    env: np.ndarray,
    tracker: Tracker,
    on_step: Callable[[int, np.ndarray], None],
    steps: int | None = None,
) -> np.ndarray:
    """Step the problem's rows under ``env`` (B, horizon, ...) from the step each row has taken so far (``taken``
    (B,), all equal here: zero after a reset) until every row has ended or ``steps`` steps are taken or the budget
    no longer pays for a step of every row still running. ``on_step(t, running)`` sees the problem after each step
    t (1-based) with the rows still running before it. Returns each row's length (steps until its trajectory
    ended, or where it stopped)."""
    rows = env.shape[0]
    lengths = np.zeros(rows, dtype=np.int64)
    running = np.ones(rows, dtype=bool)
    limit = env.shape[1] if steps is None else min(steps, env.shape[1])
    for t in range(limit):
        if running.sum() > tracker.remaining:
            break
        _, terminal = problem.step(env[:, t])
        tracker.count(int(running.sum()))
        lengths[running] = t + 1
        on_step(t + 1, running.copy())
        running &= ~np.asarray(terminal, dtype=bool)
        if not running.any():
            break
    return lengths
