"""The searches MCTS is measured against, all on the same budget of simulator steps and the same top-K queue.

- **N-first** (the paper's baseline): the first N trajectories under uniformly sampled environment actions,
  whatever their reward: what an observer sees who watches N runs. N is the top-K size; it stops there.
- **Random search**: trajectories under prior-sampled actions until the budget is spent; the best K are kept.
- **Cross-entropy method** over open-loop action sequences: sample a population of whole sequences from a
  per-step, per-coordinate Gaussian clipped to the bound, refit the Gaussian to the elite, repeat.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from search.core.problem import Problem
from search.core.rollout import Tracker, fresh, rollout
from search.solvers.solver import ProblemSearch, register


@dataclass(frozen=True)
class SamplingConfig:
    batch: int = 64  # trajectories rolled out together

    def __post_init__(self) -> None:
        if self.batch < 1:
            raise ValueError("invalid sampling setting: batch must be >= 1")


@dataclass(frozen=True)
class CEMConfig:
    population: int = 64
    elite_fraction: float = 0.125
    smoothing: float = 0.7  # weight of the elite's statistics in each refit
    initial_std: float = 1.0  # in units of the action bound
    min_std: float = 0.05  # in units of the action bound; keeps exploring after collapse

    def __post_init__(self) -> None:
        checks = [
            (self.population >= 2, "population must be >= 2"),
            (
                0 < self.elite_fraction <= 1 and self.population * self.elite_fraction >= 1,
                "elite_fraction must leave at least one elite in the population",
            ),
            (0 < self.smoothing <= 1, "smoothing must be in (0, 1]"),
            (self.initial_std > 0 and self.min_std >= 0, "initial_std must be > 0 and min_std >= 0"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid CEM setting: {message}")


def _sample_batches(
    problem: Problem, tracker: Tracker, rng: np.random.Generator, batch: int, stop_after: int | None = None
) -> None:
    """Prior-sampled trajectories, ``batch`` at a time, until the budget (or ``stop_after`` trajectories) runs out."""
    started = 0
    while not tracker.exhausted and (stop_after is None or started < stop_after):
        count = tracker.affordable(batch if stop_after is None else min(batch, stop_after - started), problem.horizon)
        started += count
        actions, lengths, returns = fresh(problem, count)
        rollout(problem, tracker, actions, lengths, returns, lambda rows, depth: problem.prior.sample(rng, rows.size))


def n_first(problem: Problem, tracker: Tracker, rng: np.random.Generator, config: SamplingConfig | None = None) -> None:
    _sample_batches(problem, tracker, rng, (config or SamplingConfig()).batch, stop_after=tracker.queue.k)


def random_search(
    problem: Problem, tracker: Tracker, rng: np.random.Generator, config: SamplingConfig | None = None
) -> None:
    _sample_batches(problem, tracker, rng, (config or SamplingConfig()).batch)


def cem(problem: Problem, tracker: Tracker, rng: np.random.Generator, config: CEMConfig | None = None) -> None:
    config = config or CEMConfig()
    bound = problem.prior.bound
    shape = (problem.horizon, *problem.action_shape)
    mean = np.zeros(shape)
    std = np.full(shape, config.initial_std * bound)
    n_elite = max(1, int(config.population * config.elite_fraction))
    while not tracker.exhausted:
        count = tracker.affordable(config.population, problem.horizon)  # the last generation may be cut short
        population = np.clip(mean + std * rng.standard_normal((count, *shape)), -bound, bound)
        actions, lengths, returns = fresh(problem, count)

        def choose(rows: np.ndarray, depth: np.ndarray, p: np.ndarray = population) -> np.ndarray:
            chosen: np.ndarray = p[rows, depth]
            return chosen

        rollout(problem, tracker, actions, lengths, returns, choose)
        if count < config.population:
            break
        elite = population[np.argsort(-returns, kind="stable")[:n_elite]]
        w = config.smoothing
        mean = (1 - w) * mean + w * elite.mean(axis=0)
        std = np.maximum((1 - w) * std + w * elite.std(axis=0), config.min_std * bound)


register(ProblemSearch("nfirst", SamplingConfig, n_first))
register(ProblemSearch("random", SamplingConfig, random_search))
register(ProblemSearch("cem", CEMConfig, cem))
