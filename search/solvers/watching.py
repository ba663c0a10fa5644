"""The summary methods of the literature that watch two agents play (Agent Disagreements, HIGHLIGHTS,
HIGHLIGHTS-DIV): what they share as solvers. Each plays episodes from the job's scenario, or from states drawn
from it when it is a distribution, chooses its own summaries and records how under ``method`` in run.json."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from search.core.problem import Follows, require
from search.core.rollout import Tracker
from search.core.workers import workers
from search.solvers.episodes import Episodes, Source, draw_episodes
from search.solvers.follow import Follow
from search.solvers.solver import Comparison, OwnSummaries

# A moment's summary: (its episodes, the episode, the steps it plays, whom the agents follow, the steps shown, what
# its solver entry adds).
Summarize = Callable[[Episodes, int, int, Follow | None, tuple[int, int] | None, dict[str, Any]], dict[str, Any]]


@dataclass(frozen=True)
class EpisodeSummary:
    """A moment's summary (`Summarize`) with the solver entry every summary carries: a value, so that a worker
    process that scores a fork by its summary builds it as this one would."""

    entry: dict[str, Any]

    def __call__(
        self,
        group: Episodes,
        episode: int,
        end: int,
        follow: Follow | None,
        window: tuple[int, int] | None,
        note: dict[str, Any],
    ) -> dict[str, Any]:
        actions = group.env[episode - group.first, :end]
        return group.coupled.summarize(actions, self.entry | note, follow=follow, window=window, horizon=end)


def spread_source(comparison: Comparison, groups: list[Episodes]) -> Source | None:
    """What worker processes rebuild the groups of episodes from, where they play over them
    (`search.solvers.episodes.in_turn`): in a world without a batched fast path, with more than one group and more
    than one worker; else None, and they play in this process."""
    if comparison.domain.batched or workers() <= 1 or len(groups) < 2:
        return None
    return Source(comparison.domain.name, tuple(comparison.agents), comparison.reward_settings)


class Watching(OwnSummaries):
    starts = "either"
    record_key = "method"
    needs: tuple[type, ...] = (Follows,)

    def longest_clip(self, config: Any, horizon: int) -> int | None:
        """None: its clips are moments of the episodes it watches, never longer than one."""
        return None

    def choose(
        self, comparison: Comparison, tracker: Tracker, rng: np.random.Generator, config: Any
    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """The summaries the method chooses from the episodes it watches, each with the steps the whole search
        took, as every solver's summaries say."""
        agents = comparison.pair(self.name, "method compares two agents")
        domain, scenario, world = comparison.domain, comparison.scenario, comparison.world_settings
        if domain.is_distribution(scenario):
            states = domain.draw_states(scenario, world, rng, config.episodes)
        else:
            states = [domain.state(scenario, world)]
        groups = draw_episodes(
            lambda s: domain.coupled(agents, s, comparison.reward_settings), states, config.episodes, rng
        )
        require(groups[0].coupled.problem, self.needs, self.name)
        summaries, record = self.watch(groups, tracker, config, EpisodeSummary(comparison.entry), comparison)
        for chosen in summaries:
            chosen["solver"]["budget_used"] = tracker.steps
        return summaries, record

    @abstractmethod
    def watch(
        self, groups: list[Episodes], tracker: Tracker, config: Any, summary: Summarize, comparison: Comparison
    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """The method's summaries of the watched episodes (each built by ``summary``) and its record."""
