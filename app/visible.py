"""What a clip visibly shows, judged the way a viewer would: the rule the `foil simulate` bots answer by and the
one `foil bundle` audits every clip with against the ground truth, and the words a world's pages use for it.

Only what is on screen counts: how each robot ended (in the crowd: which bumped into a person, which reached its
goal and when, how far one that is still on its way got, how close each came to people). A world (`World`) says
which rule judges its clips ("goal": reach it, sooner is better; "survival": last, longer is better) and the words
its participants, audit and report read (`Words`); the bundle's manifest carries it, so the server never needs the
offline side. Light on purpose (no numpy, no search code), so the survey server's bots and the offline bundle
builder share it.
"""

from __future__ import annotations

import math
import random
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

SCORE_SUCCESS, SCORE_COLLISION = 2.0, -1.0
RULES = ("goal", "survival")


@dataclass(frozen=True)
class Words:
    """What a world's pages call the things its clips show; the defaults are the crowd's. Legend lines are plain
    text where ``**text**`` reads in bold (the pages escape everything else); an empty `legend_trails` or
    `others_marker` leaves that line or marker out. The outcome phrases follow a robot's label ("Robot 2 ...");
    `success` and `collision` may say ``{seconds}``, the seconds the clip shows it took (one decimal, as the clip)."""

    agent: str = "Robot"  # the word before an agent's number, on its clips and the pages: "Robot 2"
    clip_title: str = "Clip of two robots in a crowd"  # the video's accessible name on a question's page
    # a pair of reels (each robot on its own, in moments of its own runs): the line above them and each reel's
    # accessible name, which the page follows with the robot's label
    reels_intro: str = "Each robot is shown on its own, in moments from its own runs through a crowd."
    reel_title: str = "Clip of one robot on its own in a crowd"
    example_caption: str = (  # under the instructions' example clip, unless the study file says otherwise
        "An example: two robots, each with its own colour, shape and name, walk through a crowd to the same goal."
    )
    legend_robots: str = (
        "Robots: each has a colour, a shape (disc, square, diamond, triangle, upside-down triangle or plus) and a"
        " number of its own, drawn on it; its name, such as Robot 7, is listed below the picture."
    )
    others_marker: str = "0"  # the text in the grey disc that marks the others' legend line
    legend_others: str = "People: grey discs with a number, each with a short tail showing where it walks."
    legend_trails: str = "Trails: the line behind a robot is the path it has taken."
    legend_crash: str = (
        "A yellow-and-black burst and **CRASH** mark a robot bumping into a person; the list below the picture then"
        " says **CRASHED**."
    )
    legend_status: str = (
        "Below the picture each robot's line says **reached goal** or **out of time** with the time, or **on its"
        " way** (**still on its way** when the clip ends, with how far it stopped from its goal)."
    )
    success: str = "reached the goal after {seconds} seconds"
    collision: str = "bumped into a person"
    timeout: str = "ran out of time before reaching the goal"
    running: str = "was still on its way when the clip ended"
    close_call: str = "came close to people"


@dataclass(frozen=True)
class World:
    """Which world a bundle's clips show, the rule that judges them (`RULES`) and its words: the manifest's
    `world` object, absent for the crowd."""

    domain: str = "crowd"
    rule: str = "goal"
    words: Words = Words()

    def to_manifest(self) -> dict[str, Any]:
        return {"domain": self.domain, "rule": self.rule, "words": asdict(self.words)}

    @classmethod
    def from_manifest(cls, data: Mapping[str, Any] | None) -> World:
        """The world of a manifest's `world` object (None: the crowd's). Words it leaves out keep the crowd's; a
        key, rule or word this version does not know is a ValueError that names it."""
        if data is None:
            return cls()
        if not isinstance(data, Mapping):
            raise ValueError(f"world must be an object with domain, rule and words, not {data!r}")
        _known("world", data, ("domain", "rule", "words"))
        domain, rule, words = data.get("domain", "crowd"), data.get("rule", "goal"), data.get("words", {})
        if not isinstance(domain, str) or not domain:
            raise ValueError(f"world.domain must be a world's name, not {domain!r}")
        if rule not in RULES:
            raise ValueError(f"world.rule must be one of {', '.join(map(repr, RULES))}, not {rule!r}")
        if not isinstance(words, Mapping):
            raise ValueError(f"world.words must be an object of texts, not {words!r}")
        _known("world.words", words, tuple(f.name for f in fields(Words)))
        for name, text in words.items():
            if not isinstance(text, str):
                raise ValueError(f"world.words.{name} must be a text, not {text!r}")
            try:
                text.format(seconds=0)
            except (KeyError, IndexError, ValueError) as error:
                raise ValueError(f"world.words.{name}: {text!r} may name only {{seconds}} ({error})") from None
        return cls(domain=domain, rule=rule, words=Words(**words))


def _known(where: str, data: Mapping[str, Any], keys: tuple[str, ...]) -> None:
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise ValueError(f"{where} has unknown key(s) {', '.join(map(repr, unknown))}; it knows {', '.join(keys)}")


@dataclass(frozen=True)
class Observer:
    """How a viewer judges a robot in a clip. By the "goal" rule reaching the goal beats timing out beats
    colliding, and sooner is better; by the "survival" rule (the task is to last: driving, balancing) lasting
    the clip beats crashing, and crashing later is better. Coming closer than `comfort_m` to a person counts
    against a robot that did not collide. `noise` is the standard deviation of
    the perception noise, in the same units (reaching the goal at once versus at the end of the clip is 1).
    Scores closer than `tie_margin` look the same (two robots both still on their way, a few metres apart)."""

    noise: float = 0.5
    comfort_m: float = 0.5
    closeness_weight: float = 2.0
    tie_margin: float = 0.25

    def visible_score(self, outcome: Mapping[str, Any], end_s: float, progress: float, rule: str = "goal") -> float:
        if rule not in RULES:
            raise ValueError(f"a clip is judged by one of the rules {', '.join(map(repr, RULES))}, not {rule!r}")
        event = outcome.get("event")
        lasted = min(1.0, float(outcome.get("time") or end_s) / end_s)  # share of the clip until the event
        if event == "collision":
            return SCORE_COLLISION + (lasted if rule == "survival" else 0.0)
        if event == "success":
            score = SCORE_SUCCESS + (0.0 if rule == "survival" else 1 - lasted)
        elif rule == "survival":  # timeout, or still running when the clip ends: it lasted the clip
            score = 1.0
        else:  # judged by how far it got
            score = progress
        closest = outcome.get("min_other_distance")
        if closest is not None:
            score -= self.closeness_weight * max(0.0, self.comfort_m - float(closest))
        return score

    def perceive(self, clip: Visible, rng: random.Random) -> dict[str, float]:
        """Each on-screen label's perceived score for one viewing (``rng``: a ``random.Random``)."""
        return {label: score + rng.gauss(0.0, self.noise) for label, score in clip.scores(self).items()}


def contrast(a: float, b: float) -> float:
    """How different two perceived scores look, from 0 (the same) towards 1."""
    return 1 - math.exp(-abs(a - b))


@dataclass(frozen=True)
class VisibleClip:
    """What a clip shows: per on-screen label its outcome and how far it got towards the goal, in its world."""

    labels: tuple[str, ...]
    outcomes: tuple[Mapping[str, Any], ...]
    progress: tuple[float, ...]
    end_s: float
    to_goal: tuple[float | None, ...] = ()  # metres from the goal at the end, where known
    world: World = World()

    @classmethod
    def of_summary(
        cls, summary: Mapping[str, Any], agents: list[str], labels: list[str], world: World | None = None
    ) -> VisibleClip:
        """The clip of a summary.json whose robots ``agents`` (on-screen order) carry ``labels``, in ``world``
        (the crowd's when None)."""
        names = [agent["name"] for agent in summary["agents"]]
        order = [names.index(agent) for agent in agents]  # the summary's index of each label's robot
        return cls._of_robots(summary, order, labels, world)

    @classmethod
    def of_segment(cls, summary: Mapping[str, Any], label: str, world: World | None = None) -> VisibleClip:
        """One segment of a reel as a clip of the one robot labelled ``label``: in a segment every agent's instance
        follows the reel's agent (the summary's ``follow.leader``), so the leader's outcome is what it shows."""
        follow = summary.get("follow")
        if not isinstance(follow, Mapping) or not isinstance(follow.get("leader"), int):
            raise ValueError(f"a reel's segment says whom its robots follow (follow.leader); this one has {follow!r}")
        return cls._of_robots(summary, [follow["leader"]], [label], world)

    @classmethod
    def _of_robots(
        cls, summary: Mapping[str, Any], order: Sequence[int], labels: Sequence[str], world: World | None
    ) -> VisibleClip:
        """The clip of the summary's robots ``order`` (its indices), labelled ``labels``. A summary with a ``window``
        is seen as its clip shows it: its clock starts at the window's first state, so times count from there."""
        steps = summary.get("steps") or [{"t": 1.0}]
        first = int((summary.get("window") or [0])[0])
        start_s = float(steps[first - 1]["t"]) if 0 < first <= len(steps) else 0.0
        return cls(
            labels=tuple(labels),
            outcomes=tuple(_since(summary["outcomes"][k], start_s) for k in order),
            progress=tuple(_progress(summary, k) for k in order),
            end_s=max(float(steps[-1]["t"]) - start_s, 1e-6),
            world=world or World(),
            to_goal=tuple(_to_goal(summary, k) for k in order),
        )

    def scores(self, observer: Observer) -> dict[str, float]:
        return {
            label: observer.visible_score(outcome, self.end_s, progress, self.world.rule)
            for label, outcome, progress in zip(self.labels, self.outcomes, self.progress, strict=True)
        }

    def describe(self, label: str) -> str:
        """How the robot labelled ``label`` visibly ended, as one sentence in the world's words."""
        outcome = self.outcomes[self.labels.index(label)]
        event = outcome.get("event")
        words = self.world.words
        # anything else is still moving when the clip ends, as the clip's "still on its way"
        phrase = {"success": words.success, "collision": words.collision, "timeout": words.timeout}.get(
            str(event), words.running
        )
        text = f"{label} {phrase.format(seconds=one_decimal(float(outcome.get('time') or self.end_s)))}"
        to_goal = self.to_goal[self.labels.index(label)] if self.to_goal else None
        if event not in ("success", "collision", "timeout") and to_goal is not None:
            text += f", {one_decimal(to_goal)} m from the goal"
        closest = outcome.get("min_other_distance")
        if closest is not None and event != "collision" and float(closest) < 0.5:
            text += f" and {words.close_call}"
        return text + "."


@dataclass(frozen=True)
class VisibleReels:
    """What a pair of reels shows (HIGHLIGHTS: each agent on its own, in moments of its own episodes): per on-screen
    label the segments of its reel, each a one-robot `VisibleClip`. A robot is judged by its visible score averaged
    over its reel's segments, by the same observer as a clip of both."""

    labels: tuple[str, ...]
    reels: tuple[tuple[VisibleClip, ...], ...]  # per label, its reel's segments in the order shown
    world: World = World()

    @classmethod
    def of_summaries(
        cls, reels: Sequence[Sequence[Mapping[str, Any]]], labels: Sequence[str], world: World | None = None
    ) -> VisibleReels:
        """The reels whose segments' summary.json objects are ``reels``, one list per label in ``labels``."""
        if any(not segments for segments in reels):
            raise ValueError("every reel needs the summary of at least one segment")
        shown = tuple(
            tuple(VisibleClip.of_segment(summary, label, world) for summary in segments)
            for label, segments in zip(labels, reels, strict=True)
        )
        return cls(labels=tuple(labels), reels=shown, world=world or World())

    @property
    def reel_s(self) -> tuple[float, ...]:
        """The seconds each reel shows."""
        return tuple(sum(segment.end_s for segment in reel) for reel in self.reels)

    @property
    def end_s(self) -> float:
        """The seconds the reels show, one after the other."""
        return sum(self.reel_s)

    def scores(self, observer: Observer) -> dict[str, float]:
        return {
            label: statistics.fmean(segment.scores(observer)[label] for segment in reel)
            for label, reel in zip(self.labels, self.reels, strict=True)
        }

    def describe(self, label: str) -> str:
        """How the robot labelled ``label`` ended in each moment of its reel, as one sentence in the world's words."""
        reel = self.reels[self.labels.index(label)]
        moments = "; ".join(segment.describe(label).removeprefix(f"{label} ").removesuffix(".") for segment in reel)
        return f"{label}, in {len(reel)} moment{'' if len(reel) == 1 else 's'} of its own: {moments}."


Visible = VisibleClip | VisibleReels  # what one question's video shows: a clip of both robots, or their reels


def audit(clip: Visible, better: str, observer: Observer | None = None) -> dict[str, str]:
    """Whether a two-robot clip (or pair of reels) visibly shows the better robot (label ``better``) as better, as
    worse, or shows no difference, judged without perception noise: ``{"shows": "better" | "worse" | "tie", "why":
    ...}``."""
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
        return robot["start"], robot["goal"], summary["steps"][-1]["agent_positions"][k]
    except (KeyError, IndexError, TypeError):
        return None


def _progress(summary: Mapping[str, Any], k: int) -> float:
    """Share of the start-to-goal distance robot k covered by the end of the clip (0 when unknown)."""
    ends = _ends(summary, k)
    return progress_towards(*ends) if ends else 0.0


def _since(outcome: Mapping[str, Any], start_s: float) -> Mapping[str, Any]:
    """An outcome with its time counted from ``start_s`` (an event before it happened at the clip's start)."""
    if not start_s or outcome.get("time") is None:
        return outcome
    return {**outcome, "time": max(0.0, float(outcome["time"]) - start_s)}


def _to_goal(summary: Mapping[str, Any], k: int) -> float | None:
    """How far robot k's centre is from its goal at the end of the clip (None when unknown)."""
    ends = _ends(summary, k)
    return math.dist(ends[1], ends[2]) if ends else None


def progress_towards(start: Sequence[float], goal: Sequence[float], end: Sequence[float]) -> float:
    """Share of the start-to-goal distance covered at ``end`` (none when farther from the goal than the start)."""
    total = math.dist(start, goal)
    return max(0.0, 1 - math.dist(end, goal) / total) if total > 0 else 1.0
