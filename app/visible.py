"""What a clip visibly shows, judged the way a viewer would: the rule the `foil simulate` bots answer by and the
one `foil bundle` audits every clip with against the ground truth.

Only what is on screen counts: which robot bumped into a person, which reached its goal and when, how far a robot
that is still on its way got, and how close each came to people. Light on purpose (no numpy, no search code), so
the survey server's bots and the offline bundle builder share it.
"""

from __future__ import annotations

import math
import random
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

SCORE_SUCCESS, SCORE_COLLISION = 2.0, -1.0


@dataclass(frozen=True)
class Observer:
    """How a viewer judges a robot in a clip: reaching the goal beats timing out beats colliding; sooner is
    better; coming closer than `comfort_m` to a person counts against it. `noise` is the standard deviation of
    the perception noise, in the same units (reaching the goal at once versus at the end of the clip is 1).
    Scores closer than `tie_margin` look the same (two robots both still on their way, a few metres apart)."""

    noise: float = 0.5
    comfort_m: float = 0.5
    closeness_weight: float = 2.0
    tie_margin: float = 0.25

    def visible_score(self, outcome: Mapping[str, Any], end_s: float, progress: float) -> float:
        event = outcome.get("event")
        if event == "collision":
            return SCORE_COLLISION
        if event == "success":
            score = SCORE_SUCCESS + 1 - min(1.0, float(outcome.get("time") or end_s) / end_s)
        else:  # timeout, or still running when the clip ends: judged by how far it got
            score = progress
        closest = outcome.get("min_human_distance")
        if closest is not None:
            score -= self.closeness_weight * max(0.0, self.comfort_m - float(closest))
        return score

    def perceive(self, clip: VisibleClip, rng: random.Random) -> dict[str, float]:
        """Each on-screen label's perceived score for one viewing (``rng``: a ``random.Random``)."""
        return {label: score + rng.gauss(0.0, self.noise) for label, score in clip.scores(self).items()}


def contrast(a: float, b: float) -> float:
    """How different two perceived scores look, from 0 (the same) towards 1."""
    return 1 - math.exp(-abs(a - b))


@dataclass(frozen=True)
class VisibleClip:
    """What a clip shows: per on-screen label its outcome and how far it got towards the goal."""

    labels: tuple[str, ...]
    outcomes: tuple[Mapping[str, Any], ...]
    progress: tuple[float, ...]
    end_s: float
    to_goal: tuple[float | None, ...] = ()  # metres from the goal at the end, where known

    @classmethod
    def of_summary(cls, summary: Mapping[str, Any], agents: list[str], labels: list[str]) -> VisibleClip:
        """The clip of a summary.json whose robots ``agents`` (on-screen order) carry ``labels``."""
        names = [agent["name"] for agent in summary["agents"]]
        order = [names.index(agent) for agent in agents]  # the summary's index of each label's robot
        steps = summary.get("steps") or [{"t": 1.0}]
        return cls(
            labels=tuple(labels),
            outcomes=tuple(summary["outcomes"][k] for k in order),
            progress=tuple(_progress(summary, k) for k in order),
            end_s=max(float(steps[-1]["t"]), 1e-6),
            to_goal=tuple(_to_goal(summary, k) for k in order),
        )

    def scores(self, observer: Observer) -> dict[str, float]:
        return {
            label: observer.visible_score(outcome, self.end_s, progress)
            for label, outcome, progress in zip(self.labels, self.outcomes, self.progress, strict=True)
        }

    def describe(self, label: str) -> str:
        outcome = self.outcomes[self.labels.index(label)]
        event = outcome.get("event")
        if event == "success":
            text = f"{label} reached the goal after {one_decimal(float(outcome.get('time') or self.end_s))} seconds"
        elif event == "collision":
            text = f"{label} bumped into a person"
        elif event == "timeout":
            text = f"{label} ran out of time before reaching the goal"
        else:  # still moving when the clip ends, as the clip's "still on its way", and as close as the clip says
            text = f"{label} was still on its way when the clip ended"
            to_goal = self.to_goal[self.labels.index(label)] if self.to_goal else None
            if to_goal is not None:
                text += f", {one_decimal(to_goal)} m from the goal"
        closest = outcome.get("min_human_distance")
        if closest is not None and event != "collision" and float(closest) < 0.5:
            text += " and came close to people"
        return text + "."


def audit(clip: VisibleClip, better: str, observer: Observer | None = None) -> dict[str, str]:
    """Whether a two-robot clip visibly shows the better robot (label ``better``) as better, as worse, or shows
    no difference, judged without perception noise: ``{"shows": "better" | "worse" | "tie", "why": ...}``."""
    observer = observer or Observer()
    scores = clip.scores(observer)
    if better not in scores or len(scores) != 2:
        raise ValueError(f"an audit compares two robots, one of them {better!r}; the clip has {list(scores)}")
    other = next(label for label in clip.labels if label != better)
    difference = scores[better] - scores[other]
    shows = "tie" if abs(difference) < observer.tie_margin else "better" if difference > 0 else "worse"
    return {"shows": shows, "why": f"{clip.describe(better)} {clip.describe(other)}"}


def one_decimal(value: float) -> str:
    """A time or distance as the clips write it, so that a page never says another number than its clip."""
    return f"{value:.1f}"


def _ends(summary: Mapping[str, Any], k: int) -> tuple[Sequence[float], Sequence[float], Sequence[float]] | None:
    """Robot k's start, goal and place at the end of the clip (None when the summary lacks them)."""
    try:
        robot = summary["scenario"]["robot"]
        return robot["start"], robot["goal"], summary["steps"][-1]["robots"][k]
    except (KeyError, IndexError, TypeError):
        return None


def _progress(summary: Mapping[str, Any], k: int) -> float:
    """Share of the start-to-goal distance robot k covered by the end of the clip (0 when unknown)."""
    ends = _ends(summary, k)
    return progress_towards(*ends) if ends else 0.0


def _to_goal(summary: Mapping[str, Any], k: int) -> float | None:
    """How far robot k's centre is from its goal at the end of the clip (None when unknown)."""
    ends = _ends(summary, k)
    return math.dist(ends[1], ends[2]) if ends else None


def progress_towards(start: Sequence[float], goal: Sequence[float], end: Sequence[float]) -> float:
    """Share of the start-to-goal distance covered at ``end`` (none when farther from the goal than the start)."""
    total = math.dist(start, goal)
    return max(0.0, 1 - math.dist(end, goal) / total) if total > 0 else 1.0
