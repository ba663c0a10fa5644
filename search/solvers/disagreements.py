"""Agent Disagreements (Amitai & Amir, AAAI 2022), in any world: where would agent B have acted differently from
agent A, and what came of it?

1. Agent A plays episodes (`search.solvers.episodes`); every agent's instance follows A (`search.solvers.follow`),
   and at each step agent B is asked what it would do. A step where they disagree (discrete actions: a different
   action; continuous: an action gap above ``threshold``, coordinates scaled to [-1, 1]) is a disagreement.
2. Each disagreement is forked from a snapshot of the state before it: A's instance goes on with A, B's with B, for
   h/2 steps (``horizon`` h), under the episode's own environment actions.
3. Each is scored by the published ``last_state`` importance where both agents have a value of a state: with V_X
   agent X's value, |(V_A(s_A) r + V_B(s_A)) - (V_A(s_B) r + V_B(s_B))| for the branches' end states s_A, s_B
   (``agent_ratio`` r; the original's best Q value is a state's value). For agents with no value (scripted, any
   callable) it is the value-free ``outcome`` score: how different the two agents visibly end up (the absolute
   visible contrast of the fork's clip as it shows it, from h/2 steps before the fork, `search.solvers.representative`).
4. The top K go first, most important first, skipping one that shares more than ``overlap`` of A's steps with a
   disagreement already chosen in its episode (the original's ``similarity_limit``); skipped ones fill up when
   fewer than K remain.

A disagreement needs room for its branches: one less than h/2 steps before the search's horizon is not sought.
Where none is found, the clip is the first episode with each agent on its own for h steps (recorded as such).

A clip shows h/2 steps of shared history, the moment of disagreement, then the two branches side by side: its
summary replays the episode with every agent following A up to the fork (``follow``) and shows the ``window``
from h/2 steps before it to the branches' end. The defaults are the published ones (h = 10 steps, given as 2.5 s:
10 of the crowd's 0.25 s steps; 3 episodes, overlap 3); the published summary has K = 5 (``--top-k 5``).

Budget: finding disagreements may use up to half the simulator steps; the forks use the rest. Where there are more
disagreements than forks the budget pays for, an evenly spaced share of them is forked. In a world without a batched
fast path the starting states' episodes play, and their disagreements fork, over worker processes
(`search.solvers.episodes.in_turn`), with the same clips.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from search.core.problem import ActionGap, Follows, StateValues
from search.core.rollout import Tracker
from search.solvers.episodes import Episodes, Source, continuing, in_turn, play, tracker_at, within
from search.solvers.follow import ALWAYS, Follow
from search.solvers.reward import RewardConfig
from search.solvers.solver import Comparison, held, register
from search.solvers.watching import Summarize, Watching, spread_source

IMPORTANCE = ("auto", "last_state", "outcome")


@dataclass(frozen=True)
class DisagreementsConfig:
    episodes: int = 3  # episodes agent A plays
    # h: steps a clip shows, h/2 before the disagreement and h/2 after; given in seconds (search.core.settings)
    horizon: int = field(default=10, metadata={"seconds": 2.5})
    overlap: int = 3  # steps of A's trajectory a chosen disagreement may share with another of its episode
    threshold: float = 0.25  # continuous actions: the smallest action gap that counts as a disagreement
    importance: str = "auto"  # "last_state" (values), "outcome" (visible contrast), "auto": values where both have one
    agent_ratio: float = 1.0  # weight of agent A's values against B's in last_state

    def __post_init__(self) -> None:
        checks = [
            (self.episodes >= 1, "episodes must be >= 1"),
            (self.horizon >= 2, "horizon must be >= 2 steps"),
            (self.overlap >= 0, "overlap must be >= 0"),
            (self.threshold >= 0, "threshold must be >= 0"),
            (self.importance in IMPORTANCE, f"importance must be one of {IMPORTANCE}"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid disagreements setting: {message}")


@dataclass
class Disagreement:
    episode: int  # index among all episodes
    step: int  # steps A had taken when B would have acted differently (the fork's state)
    branch: int  # steps each agent went on alone
    importance: float = 0.0
    forked: bool = True  # False: none was found, and this is the first episode with each agent on its own

    def shared(self, half: int) -> set[int]:
        """The steps of A's trajectory its clip shows."""
        return set(range(max(0, self.step - half), self.step + self.branch))


def last_state(values: np.ndarray, ratio: float) -> np.ndarray:
    """The published last-state importance from ``values[x, y]`` (B,): agent x's value of the state agent y's
    branch ended in (agents 0 = A, 1 = B)."""
    score_a = values[0, 0] * ratio + values[1, 0]
    score_b = values[0, 1] * ratio + values[1, 1]
    importance: np.ndarray = np.abs(score_a - score_b)
    return importance


def top_k(found: list[Disagreement], k: int, overlap: int, half: int) -> list[Disagreement]:
    """The ``k`` most important disagreements under the overlap limit (ties: the first found first); skipped ones
    fill up when fewer than ``k`` pass it."""
    ordered = sorted(found, key=lambda d: -d.importance)  # stable
    chosen: list[Disagreement] = []
    skipped: list[Disagreement] = []
    seen: dict[int, set[int]] = {}
    for d in ordered:
        steps = d.shared(half)
        if len(seen.get(d.episode, set()) & steps) > overlap:
            skipped.append(d)
            continue
        seen.setdefault(d.episode, set()).update(steps)
        chosen.append(d)
        if len(chosen) == k:
            return chosen
    return (chosen + skipped)[:k]


# A step with disagreements: (steps taken, snapshot of every row before that step or None, rows that disagreed).
Found = tuple[int, Any, list[int]]


def find(group: Episodes, tracker: Tracker, config: DisagreementsConfig, budget: int) -> list[Found]:
    """Play A's episodes with B asked at every step, until they end or ``budget`` steps are spent; the
    disagreements as (steps taken, snapshot of every row before that step, rows that disagreed there)."""
    problem = group.coupled.problem
    problem.reset(len(group.env))
    problem.override = Follow(0, ALWAYS)
    found: list[Found] = []
    running = np.ones(len(group.env), dtype=bool)
    for t in range(group.env.shape[1] - config.horizon // 2 + 1):  # a fork needs room for its branches
        if tracker.steps + running.sum() > budget:
            break
        before = problem.snapshot()
        _, terminal = problem.step(group.env[:, t])
        tracker.count(int(running.sum()))
        proposed = problem.proposed
        rows = np.flatnonzero(running & (problem.action_gap(proposed[0], proposed[1]) > config.threshold))
        if rows.size:
            found.append((t, before, rows.tolist()))
        running &= ~np.asarray(terminal, dtype=bool)
        if not running.any():
            break
    return found


def fork(
    group: Episodes,
    found: list[Found],
    tracker: Tracker,
    config: DisagreementsConfig,
    shown: Callable[..., float],
    summarize: Callable[[Episodes, Disagreement], dict[str, Any]],
) -> list[Disagreement]:
    """Each disagreement's two branches, h/2 steps each, all stepped together, and their importance."""
    problem, half = group.coupled.problem, config.horizon // 2
    parts, forks = [], []
    for t, before, rows in found:
        problem.restore(before)
        parts.append(problem.snapshot(rows))
        forks += [Disagreement(group.first + row, t, 0) for row in rows]
    if not forks:
        return []
    problem.restore(problem.concat(parts))
    problem.override = None
    env = np.stack([continuing(group.env[d.episode - group.first], d.step, half) for d in forks])
    lengths = play(problem, env, tracker, lambda t, running: None)
    for d, length in zip(forks, lengths.tolist(), strict=True):
        d.branch = length
    kind = importance_kind(problem, config)
    if kind == "last_state":
        values = np.array([[problem.values(x, of=y) for y in (0, 1)] for x in (0, 1)])
        scores = last_state(values, config.agent_ratio)
    else:
        scores = np.array(
            [
                abs(
                    shown(group.coupled, row, d.step + d.branch, max(0, d.step - half), lambda d=d: summarize(group, d))
                )
                for row, d in enumerate(forks)
            ]
        )
    for d, score in zip(forks, scores, strict=True):
        d.importance = float(score)
    return [d for d in forks if d.branch > 0]


def found_rows(
    group: Episodes, tracker: Tracker, config: DisagreementsConfig, budget: int
) -> list[tuple[int, list[int]]]:
    """`find`'s disagreements as (steps taken, rows), without the snapshots: what a worker process sends back."""
    return [(t, rows) for t, _, rows in find(group, tracker, config, budget)]


def replayed_forks(
    group: Episodes,
    tracker: Tracker,
    config: DisagreementsConfig,
    found_from: int,
    limit: int,
    kept: list[tuple[int, list[int]]],
    source: Source,
    summarize: Callable[[Episodes, Disagreement], dict[str, Any]],
) -> list[Disagreement]:
    """The ``kept`` disagreements (steps taken, rows) of a group forked, in a process of its own: its episodes
    played again as `find` played them from ``found_from`` steps (for the snapshots), then `fork`."""
    rows_at = dict(kept)
    found = find(group, tracker_at(tracker.budget, found_from), config, limit)
    chosen = [(t, before, rows_at[t]) for t, before, _ in found if t in rows_at]
    return fork(group, chosen, tracker, config, source.domain().shown, summarize)


def unforked(group: Episodes, tracker: Tracker, config: DisagreementsConfig) -> Disagreement:
    """Where the agents never disagree (or never with room to fork), the clip is still a clip of the pair: the
    first episode with each agent on its own for h steps (``forked`` False)."""
    problem = group.coupled.problem
    problem.reset(1)
    problem.override = None
    length = play(problem, group.env[:1], tracker, lambda t, running: None, steps=config.horizon)
    return Disagreement(group.first, 0, int(length[0]), forked=False)


def importance_kind(problem: StateValues, config: DisagreementsConfig) -> str:
    """The importance a search uses: ``last_state`` needs both agents' values."""
    has_values = all(problem.values(x, of=x) is not None for x in (0, 1))
    if config.importance == "last_state" and not has_values:
        raise ValueError("last_state importance needs both agents' values of a state; these agents have none")
    if config.importance == "auto":
        return "last_state" if has_values else "outcome"
    return config.importance


def disagreements(
    groups: list[Episodes],
    tracker: Tracker,
    config: DisagreementsConfig,
    shown: Callable[..., float],
    summarize: Callable[[Episodes, Disagreement], dict[str, Any]],
    source: Source | None = None,
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The top-K disagreements' summaries, most important first, and the record of the search.
    ``summarize(group, disagreement)`` builds a disagreement's summary; ``shown`` is `Domain.shown`. With a
    ``source`` the groups play over worker processes, where ``summarize`` must pickle."""
    half, limit = config.horizon // 2, tracker.budget // 2
    if source is None:
        found = [find(group, tracker, config, limit) for group in groups]
    else:
        played = in_turn(found_rows, source, groups, [(config, limit)] * len(groups), tracker, within(limit))
        found = [[(t, None, rows) for t, rows in rows_at] for _, rows_at in played]
    every = [(g, t, row) for g, rows_at in enumerate(found) for t, _, rows in rows_at for row in rows]
    affordable = max(1, tracker.remaining // max(half, 1))
    kept = {every[i] for i in np.linspace(0, len(every) - 1, min(len(every), affordable)).round().astype(int)}
    chosen_at = [
        [
            (t, before, kept_rows)
            for t, before, rows in found[g]
            if (kept_rows := [r for r in rows if (g, t, r) in kept])
        ]
        for g in range(len(groups))
    ]
    forked: list[Disagreement] = []
    if source is None:
        for group, chosen_here in zip(groups, chosen_at, strict=True):
            forked += fork(group, chosen_here, tracker, config, shown, summarize)
    else:
        forking = [g for g in range(len(groups)) if chosen_at[g]]
        tasks = [
            (config, played[g][0], limit, [(t, rows) for t, _, rows in chosen_at[g]], source, summarize)
            for g in forking
        ]
        forks = in_turn(replayed_forks, source, [groups[g] for g in forking], tasks, tracker, within(tracker.budget))
        forked = [d for _, found_here in forks for d in found_here]
        groups[0].coupled.problem.reset(1)  # the record's importance asks the agents of a state
    chosen = top_k(forked, tracker.queue.k, config.overlap, half) or [unforked(groups[0], tracker, config)]
    by_episode = {group.first + e: group for group in groups for e in range(len(group.env))}
    record = {
        "disagreements": len(every),
        "forked": len(forked),
        "importance": importance_kind(groups[0].coupled.problem, config),
        "chosen": [
            {"episode": d.episode, "step": d.step, "branch": d.branch, "importance": d.importance}
            for d in chosen
            if d.forked
        ],
    }
    return [summarize(by_episode[d.episode], d) for d in chosen], record


@dataclass(frozen=True)
class DisagreementSummary:
    """A disagreement's clip as a summary: a value, so that a worker process that scores a fork by its summary
    builds it as this one would."""

    summary: Summarize
    horizon: int

    def __call__(self, group: Episodes, d: Disagreement) -> dict[str, Any]:
        end = d.step + d.branch
        if not d.forked:
            return self.summary(group, d.episode, end, None, None, {"episode": d.episode, "disagreement_step": None})
        window = (max(0, d.step - self.horizon // 2), end)
        note = {"episode": d.episode, "disagreement_step": d.step, "importance": d.importance}
        return self.summary(group, d.episode, end, Follow(0, d.step), window, note)


class AgentDisagreements(Watching):
    name = "disagreements"
    config_class = DisagreementsConfig
    needs = (Follows, ActionGap, StateValues)

    def held_to_clip(
        self, config: DisagreementsConfig, reward: RewardConfig, steps: int, given: dict[str, Any]
    ) -> tuple[DisagreementsConfig, RewardConfig]:
        """A disagreement's clip shows its h steps."""
        return replace(config, horizon=held(given, "settings", "horizon", steps)), reward

    def watch(
        self,
        groups: list[Episodes],
        tracker: Tracker,
        config: DisagreementsConfig,
        summary: Summarize,
        comparison: Comparison,
    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        summarize = DisagreementSummary(summary, config.horizon)
        return disagreements(
            groups, tracker, config, comparison.domain.shown, summarize, spread_source(comparison, groups)
        )


register(AgentDisagreements())
