"""Ground truth with its uncertainty: which agent of a pair is better, and whether the evaluation can tell at all.

Every agent's evaluation at one seed starts its episode i from the same state (the crowd's i-th drawn starting
state, a Gymnasium world's i-th reset seed), so two agents are compared episode by episode: the **paired t-test**
on the per-episode differences in reward (first agent minus second), with the interval of their mean.

The study's own episodes are the first look. A pair it leaves undecided (the interval holds 0) is evaluated again
at the same seed on twice as many episodes, and so on: ``LOOKS`` looks in all, so at most ``8 x`` the study's
episodes. Looking again until a difference shows would inflate a fixed-level test's error, so every look is
tested at the Bonferroni level ``ALPHA / LOOKS``: the chance that any planned look's interval misses the true
difference is at most 5%. The interval reported is that of the last look at this level (a simultaneous 95%
interval, wider than one look's 95% interval), and the p-value is the last look's, times ``LOOKS``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

ALPHA = 0.05  # the error allowed over all the looks together
LOOKS = 4  # the study's episodes, then 2, 4 and 8 times as many: the cap is 8 times the study's episodes

Rewards = Callable[[set[tuple[str, int]]], Mapping[tuple[str, int], Sequence[float]]]


@dataclass(frozen=True)
class PairedComparison:
    """Two agents on the same test episodes: ``difference`` is the mean of first minus second per episode."""

    agents: tuple[str, str]
    difference: float
    ci95: tuple[float, float]  # simultaneous over the planned looks (Bonferroni)
    p: float  # two-sided paired t-test of the last look, Bonferroni-adjusted over the planned looks
    episodes: int  # paired episodes of the last look
    decided: bool  # the interval excludes 0

    @classmethod
    def from_manifest(cls, data: dict[str, Any]) -> PairedComparison:
        first, second = data["agents"]
        low, high = data["ci95"]
        return cls((first, second), data["difference"], (low, high), data["p"], data["episodes"], data["decided"])

    def to_manifest(self) -> dict[str, Any]:
        return {
            "agents": list(self.agents),
            "difference": self.difference,
            "ci95": list(self.ci95),
            "p": self.p,
            "episodes": self.episodes,
            "decided": self.decided,
        }


def paired_comparison(
    agents: tuple[str, str], first: Sequence[float], second: Sequence[float], looks: int = LOOKS
) -> PairedComparison:
    """The paired t-test of two agents' rewards on the same episodes, at the level ``ALPHA / looks``."""
    from scipy import stats

    if len(first) != len(second) or len(first) < 2:
        raise ValueError(
            f"a paired comparison needs two equal runs of 2 or more episodes, not {len(first)}, {len(second)}"
        )
    n = len(first)
    differences = [a - b for a, b in zip(first, second, strict=True)]
    mean = math.fsum(differences) / n
    se = math.sqrt(math.fsum((d - mean) ** 2 for d in differences) / (n - 1) / n)
    half = float(stats.t.ppf(1 - ALPHA / looks / 2, n - 1)) * se
    if se > 0:
        p = min(1.0, looks * 2 * float(stats.t.sf(abs(mean) / se, n - 1)))
    else:  # every episode differs by the same amount
        p = 1.0 if mean == 0 else 0.0
    low, high = mean - half, mean + half
    return PairedComparison(agents, mean, (low, high), p, n, low > 0 or high < 0)


def compare_pairs(
    pairs: Sequence[tuple[str, str]], episodes: int, rewards: Rewards, looks: int = LOOKS
) -> dict[tuple[str, str], PairedComparison]:
    """Each pair compared on ``episodes`` paired episodes, then, while undecided, on twice as many, up to ``looks``
    looks. ``rewards`` evaluates a set of (agent, episodes) at once (one batch per look, so a caller can run them
    in parallel) and gives each one's per-episode rewards, episode i from the same start for every agent."""
    compared: dict[tuple[str, str], PairedComparison] = {}
    todo = list(pairs)
    for look in range(looks):
        n = episodes * 2**look
        found = rewards({(agent, n) for pair in todo for agent in pair})
        for pair in todo:
            compared[pair] = paired_comparison(pair, found[pair[0], n], found[pair[1], n], looks)
        todo = [pair for pair in todo if not compared[pair].decided]
        if not todo:
            break
    return compared


def describe_close_pair(comparison: PairedComparison) -> str:
    """One line on a pair the study's episodes did not decide. It names agents, never robot labels, and for an
    undecided pair does not say which is better: its questions' right answer rests on a coin toss."""
    first, second = comparison.agents
    low, high = comparison.ci95
    numbers = (
        f"{first} - {second} {comparison.difference:.2f} reward, 95% interval {low:.2f} to {high:.2f}, "
        f"{comparison.episodes} paired episodes"
    )
    if comparison.decided:
        return f"close pair {first} and {second}: decided on more episodes ({numbers})"
    return (
        f"warning: {first} and {second} differ by less than the evaluation can decide ({numbers}): questions on "
        "this pair rest on a coin toss"
    )
