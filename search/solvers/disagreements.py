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
disagreements than forks the budget pays for, an evenly spaced share of them is forked.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from search.solvers.episodes import Episodes, continuing, play
from search.solvers.follow import ALWAYS, Follow
from search.solvers.problem import ActionGap, Follows, StateValues
from search.solvers.reward import RewardConfig
from search.solvers.rollout import Tracker
from search.solvers.solver import Comparison, held, register
from search.solvers.watching import Summarize, Watching

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

    def __post_init__(self):
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
    return np.abs(score_a - score_b)


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


def find(group: Episodes, tracker: Tracker, config: DisagreementsConfig, budget: int) -> list[tuple[int, Any, list]]:
    """Play A's episodes with B asked at every step, until they end or ``budget`` steps are spent; the
    disagreements as (steps taken, snapshot of every row before that step, rows that disagreed there)."""
    problem = group.coupled.problem
    problem.reset(len(group.env))
    problem.override = Follow(0, ALWAYS)
    found: list[tuple[int, Any, list]] = []
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
    found: list[tuple[int, Any, list]],
    tracker: Tracker,
    config: DisagreementsConfig,
    shown: Callable[..., float],
    summarize: Callable[[Episodes, Disagreement], dict],
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


def unforked(group: Episodes, tracker: Tracker, config: DisagreementsConfig) -> Disagreement:
    """Where the agents never disagree (or never with room to fork), the clip is still a clip of the pair: the
    first episode with each agent on its own for h steps (``forked`` False)."""
    problem = group.coupled.problem
    problem.reset(1)
    problem.override = None
    length = play(problem, group.env[:1], tracker, lambda t, running: None, steps=config.horizon)
    return Disagreement(group.first, 0, int(length[0]), forked=False)


def importance_kind(problem, config: DisagreementsConfig) -> str:
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
    summarize: Callable[[Episodes, Disagreement], dict],
) -> tuple[list[dict], dict]:
    """The top-K disagreements' summaries, most important first, and the record of the search.
    ``summarize(group, disagreement)`` builds a disagreement's summary; ``shown`` is `Domain.shown`."""
    half = config.horizon // 2
    found = [find(group, tracker, config, tracker.budget // 2) for group in groups]
    every = [(g, t, row) for g, rows_at in enumerate(found) for t, _, rows in rows_at for row in rows]
    affordable = max(1, tracker.remaining // max(half, 1))
    kept = {every[i] for i in np.linspace(0, len(every) - 1, min(len(every), affordable)).round().astype(int)}
    forked: list[Disagreement] = []
    for g, group in enumerate(groups):
        chosen_here = [(t, before, [row for row in rows if (g, t, row) in kept]) for t, before, rows in found[g]]
        forked += fork(group, [f for f in chosen_here if f[2]], tracker, config, shown, summarize)
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


class AgentDisagreements(Watching):
    name = "disagreements"
    config_class = DisagreementsConfig
    needs = (Follows, ActionGap, StateValues)

    def held_to_clip(
        self, config: DisagreementsConfig, reward: RewardConfig, steps: int, given: dict
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
    ) -> tuple[list[dict], dict]:
        def of_disagreement(group: Episodes, d: Disagreement) -> dict:
            end = d.step + d.branch
            if not d.forked:
                return summary(group, d.episode, end, None, None, {"episode": d.episode, "disagreement_step": None})
            window = (max(0, d.step - config.horizon // 2), end)
            note = {"episode": d.episode, "disagreement_step": d.step, "importance": d.importance}
            return summary(group, d.episode, end, Follow(0, d.step), window, note)

        return disagreements(groups, tracker, config, comparison.domain.shown, of_disagreement)


register(AgentDisagreements())
