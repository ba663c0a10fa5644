"""Episodes for the summary methods that watch agents play (Agent Disagreements, HIGHLIGHTS): where they start and
under which environment actions they run, the same for every agent compared.

From a fixed scenario the first episode runs without pushes and the others under environment actions drawn
uniformly within their bound (the world's own variation, as the representative solver's rollouts); from a
distribution each episode starts from its own drawn state, without pushes.

In a world without a batched fast path the groups of episodes from drawn states play over worker processes
(`in_turn`), with the same result as one after another in one process, whatever the number of workers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from search.core.problem import Problem
from search.core.rollout import Tracker
from search.core.workers import in_order

if TYPE_CHECKING:
    from search.core.domain import Coupled, Domain  # the domain module imports the solvers

# groups played at once over the workers, each from the steps counted when its chunk starts: a constant, so how far
# ahead they play never depends on the number of workers
CHUNK = 8


@dataclass
class Episodes:
    """Episodes from one starting state: its coupled problem and each episode's environment actions."""

    coupled: Coupled
    env: np.ndarray  # (E, horizon, *action_shape)
    first: int  # the index of its first episode among all episodes
    state: Any = None  # the starting state, which a worker process rebuilds the coupled problem from


@dataclass(frozen=True)
class Source:
    """What a worker process rebuilds a group's coupled problem from: the world's name, the agents and the reward's
    settings (with the group's starting state)."""

    world: str
    agents: tuple[str, ...]
    reward: dict[str, Any]

    def domain(self) -> Domain:
        from search.core.domain import domain_named  # the domain module imports the solvers

        return domain_named(self.world)

    def episodes(self, state: Any, env: np.ndarray, first: int) -> Episodes:
        return Episodes(self.domain().coupled(self.agents, state, self.reward), env, first, state)


def draw_episodes(
    coupled_of: Callable[[Any], Coupled], states: list[Any], count: int, rng: np.random.Generator
) -> list[Episodes]:
    """``count`` episodes: from a single state, one without pushes then uniform pushes; from several drawn
    states, one episode each without pushes. ``coupled_of(state)`` is the coupled problem of a state."""
    if len(states) == 1:
        coupled = coupled_of(states[0])
        problem = coupled.problem
        env = np.zeros((count, problem.horizon, *problem.action_shape))
        bound = problem.prior.bound
        env[1:] = rng.uniform(-bound, bound, env[1:].shape)
        return [Episodes(coupled, env, 0, states[0])]
    found: list[Episodes] = []
    for index, state in enumerate(states[:count]):
        coupled = coupled_of(state)
        problem = coupled.problem
        found.append(Episodes(coupled, np.zeros((1, problem.horizon, *problem.action_shape)), index, state))
    return found


def continuing(env: np.ndarray, start: int, steps: int) -> np.ndarray:
    """An episode's environment actions (horizon, ...) from step ``start`` on, ``steps`` of them (none beyond the
    horizon: zero there)."""
    part = env[start : start + steps]
    return np.concatenate([part, np.zeros((steps - len(part), *env.shape[1:]))])


def play(
    problem: Problem,
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


def tracker_at(budget: int, steps: int) -> Tracker:
    """A tracker of ``budget`` steps that has counted ``steps``: a group played apart, as it would be played in
    turn."""
    tracker = Tracker(budget, 1)
    tracker.steps = steps
    return tracker


Same = Callable[[tuple[Any, ...], Any, int, int, int], bool]


def in_turn(
    function: Callable[..., Any],
    source: Source,
    groups: list[Episodes],
    arguments: list[tuple[Any, ...]],
    tracker: Tracker,
    same: Same,
) -> list[tuple[int, Any]]:
    """``function(group, tracker, *arguments[g])`` of each group in turn, as one process plays them one after
    another on one tracker, over worker processes; with the steps counted before each.

    Each group's result depends on the steps counted before it (where the budget stops its play), which the groups
    before it decide. So a chunk of groups plays at once, each from the steps counted when the chunk starts (the
    most any of them can have left), then their results are taken in order: a result is kept where
    ``same(arguments, result, steps, start, now)`` says that played from ``now`` steps, where the groups before it
    leave the count, instead of ``start``, it comes out the same (no budget check goes another way), else that
    group plays again here, from ``now``. ``steps`` is what the result counted. ``function`` must pickle."""
    done = []
    for first in range(0, len(groups), CHUNK):
        start = tracker.steps
        tasks = [
            (function, source, group.state, group.env, group.first, tracker.budget, start, *arguments[first + i])
            for i, group in enumerate(groups[first : first + CHUNK])
        ]
        for task, (result, steps) in zip(tasks, in_order(_played, tasks), strict=True):
            now = tracker.steps
            if now != start and not same(task[7:], result, steps, start, now):
                result, steps = _played(*task[:6], now, *task[7:])
            tracker.count(steps)
            done.append((now, result))
    return done


def within(limit: int) -> Same:
    """`in_turn`'s test for a play that stops before a step would take the count past ``limit`` (`find`, `play`):
    from a later start it plays the same where all its steps still fit."""
    return lambda arguments, result, steps, start, now: now + steps <= limit


def _played(
    function: Callable[..., Any],
    source: Source,
    state: Any,
    env: np.ndarray,
    first: int,
    budget: int,
    start: int,
    *arguments: Any,
) -> tuple[Any, int]:
    """One group played apart, from ``start`` steps: its result and the steps it counted."""
    tracker = tracker_at(budget, start)
    result = function(source.episodes(state, env, first), tracker, *arguments)
    return result, tracker.steps - start
