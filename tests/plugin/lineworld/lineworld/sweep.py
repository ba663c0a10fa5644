"""A summary method of the line world's own, registered through the ``foil.solvers`` entry point: each of a few
steady winds, from the strongest headwind to the strongest tailwind, blown for a whole run. It knows nothing of
the carts, so it shows a plugin method needs only the solver interface."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from search.api import Problem, ProblemSearch, Tracker, fresh, register, rollout


@dataclass(frozen=True)
class SweepConfig:
    winds: int = 5  # steady winds tried, evenly spaced over the wind's range


def sweep(problem: Problem, tracker: Tracker, rng: np.random.Generator, config: SweepConfig) -> None:
    count = tracker.affordable(config.winds, problem.horizon)
    winds = np.linspace(-problem.prior.bound, problem.prior.bound, config.winds)[:count]
    if count:
        actions, lengths, returns = fresh(problem, count)
        rollout(problem, tracker, actions, lengths, returns, lambda rows, depth: winds[rows][:, None])


register(ProblemSearch("line-sweep", SweepConfig, sweep))
