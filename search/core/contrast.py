"""What a clip visibly shows of two agents, and how strongly rollouts from many starting states vote for one: the
library the representative solver, the representativeness check of a study's fixed scenarios, the bundle's audit
and every world's rollouts share (docs/search.md, "The representative solver").

A rollout's clip is scored by the viewer's rule (`app.visible.Observer`, no perception noise): the first agent's
visible score minus the second's, none (0) under the observer's tie margin. A state weighs in by how plainly its
clips show that difference: the mean over its rollouts of a viewer's expected vote (`Observer.expected_vote`,
the `foil simulate` bots' own rule), so a state where one agent crashes and the other drives on outweighs one where
both drive on at speeds a viewer can barely tell apart. A vote's strength is the sign-flip test of the states'
weights (`weighted_test`: with equal weights, the sign test), held to Bonferroni's level over the looks that could
have stopped it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Any, TypeVar

import numpy as np
from scipy.stats import permutation_test

from app.visible import Observer, VisibleClip, World
from search.core.problem import Problem
from search.core.rollout import Tracker

# A pair's rollouts of some drawn states, counted against a tracker: (states, tracker) -> Rollouts (a
# `search.solvers.pool.Pool`'s, read from every agent's).
RollOut = Callable[[list[Any], Tracker], "Rollouts"]
# What a rollout's clip shows the moment its row ends: (a Coupled, the row, the steps it took) -> the clip of every
# agent (labels "0", "1", ...) and the step each agent's episode ended on (0: it ran on). (A Coupled is Any here: the
# domain module imports this one, and no module imports itself back, tests/test_layers.py.)
Seen = Callable[[Any, int, int], tuple[VisibleClip, list[int]]]

OBSERVER = Observer()
ALPHA = 0.05  # a vote is decided when its test's p is below this, over its looks (`strength`)
FLIPS = 9_999  # the sign flips `weighted_test` draws where there are too many to count


@dataclass
class Played:
    """Every agent's rollouts of some drawn states. Each row is pushed until every agent's episode has ended (or
    the horizon), so each agent's record in it (its outcome, progress and score up to its ending) is its own,
    whichever agents are played beside it: any pair's rollouts read from it (`pair`) are those of the pair played
    alone, and each agent plays each state and push once, however many pairs read it."""

    state: np.ndarray  # (K,) index of the starting state
    env: list[np.ndarray]  # K arrays (L_k, *action_shape): the pushes until every agent's episode ended or the horizon
    ends: np.ndarray  # (K, N) the step each agent's episode ended on; 0 where it ran on to the horizon
    clips: list[VisibleClip]  # K clips of every agent (labels "0", "1", ...), each agent's record up to its ending

    @classmethod
    def of_state(cls, index: int, env: list[np.ndarray], ends: np.ndarray, clips: list[VisibleClip]) -> Played:
        """One state's rows."""
        return cls(np.full(len(env), index), env, np.asarray(ends, dtype=np.int64), clips)

    @classmethod
    def join(cls, parts: list[Played]) -> Played:
        return joined(cls, parts)

    def states(self, start: int, end: int) -> Played:
        """The rows of states ``start`` to ``end`` (not included), each state counted from the first's index."""
        low, high = (int(np.searchsorted(self.state, bound)) for bound in (start, end))
        return Played(self.state[low:high] - start, self.env[low:high], self.ends[low:high], self.clips[low:high])

    def pair(self, first: int, second: int) -> tuple[Rollouts, int]:
        """The rollouts of agents ``first`` and ``second`` (their columns), as a search of the pair alone under
        ``finish = "last"`` finds them: each row's pushes up to where the later of the two ended (the horizon where
        one ran on), and its clip's contrast from there; with the steps they took together (a coupled step
        counted once, as a search of the pair counts it)."""
        both = self.ends[:, [first, second]]
        lengths = [max(ends) if min(ends) else len(env) for ends, env in zip(both.tolist(), self.env, strict=True)]
        contrast = np.array(
            [visible_contrast(clip.pick((first, second), pair_end_s(clip, (first, second)))) for clip in self.clips]
        )
        actions = [env[:n] for env, n in zip(self.env, lengths, strict=True)]
        return Rollouts(self.state.copy(), actions, contrast), sum(lengths)


def pair_end_s(clip: VisibleClip, pair: tuple[int, int]) -> float:
    """When a pair's clip ends: where both agents' episodes ended, with the later of them; else at the horizon,
    where the rollout of every agent ended too."""
    times = [clip.outcomes[k].get("time") for k in pair]
    ended = [float(time) for time in times if time is not None]
    return max(max(ended), 1e-6) if len(ended) == len(times) else clip.end_s


@dataclass
class Rollouts:
    """Every rollout: the state it started from, its searched environment actions and its visible contrast."""

    state: np.ndarray  # (K,) index of the starting state
    actions: list[np.ndarray]  # K arrays (L_k, *action_shape): the environment actions up to the search's end
    contrast: np.ndarray  # (K,) first agent's visible score minus the second's; 0 under the tie margin

    @classmethod
    def join(cls, parts: list[Rollouts]) -> Rollouts:
        return joined(cls, parts)


Rows = TypeVar("Rows", Played, Rollouts)


def joined(cls: type[Rows], parts: list[Rows]) -> Rows:
    """The rows of ``parts`` in order, as one: each field's arrays concatenated, its lists chained."""
    chained: dict[str, Any] = {}
    for name in (field.name for field in fields(cls)):
        values = [getattr(part, name) for part in parts]
        chained[name] = (
            [v for value in values for v in value] if isinstance(values[0], list) else np.concatenate(values)
        )
    return cls(**chained)


def weighted_test(weights: np.ndarray) -> float:
    """The two-sided sign-flip test's p of states' weights: the chance of a sum at least as far from 0 were each
    state as likely to weigh in for either agent by the same amount. States that weigh nothing are left out, as the
    sign test leaves out ties (one or none left: 1); with equal weights it is the sign test. Exact up to 13 states, else
    over 9,999 seeded sign flips (scipy's `permutation_test`), so the same weights always give the same p."""
    weighed = np.asarray(weights, dtype=float)
    weighed = weighed[weighed != 0]
    if len(weighed) < 2:  # one state flipped is as far from 0 as it is
        return 1.0
    tested = permutation_test(
        (weighed,),
        lambda x, axis: np.sum(x, axis=axis),
        permutation_type="samples",
        vectorized=True,
        n_resamples=FLIPS,
        alternative="two-sided",
        random_state=np.random.default_rng(0),
    )
    return float(min(1.0, tested.pvalue))


def strength(weights: np.ndarray, alpha: float = ALPHA, looks: int = 1) -> dict[str, Any]:
    """A vote's test and whether it is decided, as its record says them: p below ``alpha / looks``. Looking again
    until a vote decides would make a split between equally good agents look decided more often than ``alpha``
    (about 0.11 at 0.05 with 8 looks), so each of the ``looks`` that could have stopped it is tested at the
    Bonferroni level."""
    p = weighted_test(weights)
    return {"p": p, "alpha": alpha, "looks": looks, "decided": p < alpha / looks}


@dataclass(frozen=True)
class Vote:
    """How the states voted: each state's weight, a viewer's expected vote over its clips from -1 (every viewer
    would pick the second agent) to +1 (the first), 0 where its clips show no difference or cancel out."""

    state_weights: np.ndarray  # (M,) one weight per state rolled out
    direction: int  # the sign of the summed weights

    @property
    def state_votes(self) -> np.ndarray:
        """Which way each state leans: +1, -1, or 0 for none."""
        leans: np.ndarray = np.sign(self.state_weights).astype(np.int64)
        return leans

    @property
    def p(self) -> float:
        """The sign-flip test of the states' weights (`weighted_test`)."""
        return weighted_test(self.state_weights)

    def record(self, rollouts: Rollouts, alpha: float = ALPHA, looks: int = 1) -> dict[str, Any]:
        """What run.json says of the vote, with its strength (`strength`)."""
        signs = np.sign(rollouts.contrast)
        votes = self.state_votes
        return {
            "states": len(votes),
            "rollouts": len(signs),
            "for_first": int((votes > 0).sum()),
            "for_second": int((votes < 0).sum()),
            "no_majority": int((votes == 0).sum()),
            "direction": self.direction,
            "weight": round(float(self.state_weights.sum()), 6),
            "tied": self.direction == 0,
            "agreeing_share": float((signs == self.direction).mean()) if self.direction else None,
        } | strength(self.state_weights, alpha, looks)


def vote(rollouts: Rollouts, states: int, observer: Observer = OBSERVER) -> Vote:
    """Each state's weight, the mean of its rollouts' expected votes (`Observer.expected_vote`), and the sign of
    their sum."""
    expected = np.array([observer.expected_vote(c) for c in rollouts.contrast.tolist()])
    weights = np.array(
        [expected[rollouts.state == s].mean() if (rollouts.state == s).any() else 0.0 for s in range(states)]
    )
    return Vote(weights, int(np.sign(weights.sum())))


def summary_contrast(summary: dict[str, Any], world: World) -> float:
    """``visible_contrast`` of a two-agent summary's clip, in its agents' order."""
    agents = [a["name"] for a in summary["agents"]]
    return visible_contrast(VisibleClip.of_summary(summary, agents, ["first", "second"], world))


def visible_contrast(clip: VisibleClip) -> float:
    """First agent's visible score minus the second's as the viewer sees the clip; 0 under the clip's tie margin
    (`VisibleClip.margin`: by a visible score, sums that read the same)."""
    first, second = clip.scores(OBSERVER).values()
    difference = first - second
    return difference if abs(difference) >= clip.margin(OBSERVER) else 0.0


def describe_vote(agents: Sequence[str], won: Sequence[int], no_majority: int, p: float) -> str:
    """A vote in words, by agent name: how many starting states showed each agent as better, and its test, which
    weighs each state by how plainly it showed it."""
    states = sum(won) + no_majority
    return (
        f"of {states} starting state{'' if states == 1 else 's'}, {won[0]} showed {agents[0]} as better, "
        f"{won[1]} {agents[1]} and {no_majority} neither (weighed by how plainly, p "
        f"{'< 0.001' if p < 0.001 else f'= {p:.2g}'})"
    )


def largest_contrast(summaries: list[dict[str, Any]], world: World) -> int:
    """Which of a search's summaries (two agents, best reward first) shows the largest non-tie visible contrast,
    in either direction: outcome-contrast selection. The first where none shows a visible difference."""
    contrasts = [abs(summary_contrast(s, world)) for s in summaries]
    best = max(range(len(contrasts)), key=contrasts.__getitem__)  # the first of equals
    return best if contrasts[best] > 0 else 0


def play_problem(coupled: list[Any], pushes: int, rng: np.random.Generator, seen: Seen | None = None) -> Played:
    """Every agent's rollouts through any domain's coupled problems (one `search.core.domain.Coupled` per state,
    its reward ending as ``finish = "last"``): from each state one without pushes and ``pushes`` under uniform
    pushes (`draw_pushes`), stepped together until every agent's episode has ended or the horizon (`play_rows`)."""
    parts = []
    for index, found in enumerate(coupled):
        env = draw_pushes(found.problem, pushes, rng)
        parts.append(Played.of_state(index, *play_rows(found, env, seen)))
    return Played.join(parts)


def draw_pushes(problem: Problem, pushes: int, rng: np.random.Generator) -> np.ndarray:
    """The environment actions of one state's rollouts, (pushes + 1, horizon, *action_shape): none in the first,
    uniform within the prior's bound in the others."""
    env = np.zeros((pushes + 1, problem.horizon, *problem.action_shape))
    bound = problem.prior.bound
    env[1:] = rng.uniform(-bound, bound, (pushes, problem.horizon, *problem.action_shape))
    return env


def play_rows(found: Any, env: np.ndarray, seen: Seen | None = None) -> tuple[list[np.ndarray], np.ndarray, list[Any]]:
    """One state's rollouts, a row each under ``env`` (rows, horizon, ...), stepped together until each row's
    problem ends it (every agent's episode ended, or the horizon): each one's environment actions up to its end,
    the step each agent's episode ended on (0: it ran on) and its clip of every agent. The clip is read by
    ``seen(coupled, row, steps)`` the moment a row ends (a domain's fast path), or else from each rollout's
    summary (exact, at twice the steps)."""
    problem = found.problem
    rows, horizon = env.shape[:2]
    searched = np.full(rows, horizon)
    read: dict[int, tuple[Any, list[int]]] = {}
    running = np.ones(rows, dtype=bool)
    problem.reset(rows)
    for t in range(1, horizon + 1):
        _, terminal = problem.step(env[:, t - 1])
        ended = running & np.asarray(terminal, dtype=bool)
        searched[ended] = t
        running &= ~ended
        if seen is not None:
            for row in np.flatnonzero(ended):
                read[int(row)] = seen(found, int(row), t)
        if not running.any():
            break
    actions = [env[row, : searched[row]] for row in range(rows)]
    if seen is None:
        read = dict(enumerate(summary_clip(found.summarize(a, {}), found.world) for a in actions))
    ends = np.array([read[row][1] for row in range(rows)], dtype=np.int64)
    return actions, ends, [read[row][0] for row in range(rows)]


def summary_clip(summary: dict[str, Any], world: World) -> tuple[VisibleClip, list[int]]:
    """The clip of every agent of a summary, and the step each agent's episode ended on (0: it ran on), as
    `play_rows` reads a rollout without a fast path."""
    times = [float(step["t"]) for step in summary["steps"]]
    ends = [
        0 if outcome.get("time") is None else 1 + int(np.argmin(np.abs(np.subtract(times, outcome["time"]))))
        for outcome in summary["outcomes"]
    ]
    agents = [a["name"] for a in summary["agents"]]
    return VisibleClip.of_summary(summary, agents, [str(k) for k in range(len(agents))], world), ends
