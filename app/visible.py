"""What a clip visibly shows, judged the way a viewer would: the rule the `foil simulate` bots answer by and the
one `foil bundle` audits every clip with against the ground truth, and the words a world's pages use for it.

Only what is on screen counts: how each agent ended (in the crowd: which bumped into a person, which reached its
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
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

SCORE_SUCCESS, SCORE_COLLISION = 2.0, -1.0
RULES = ("goal", "survival", "score")
SUMS = ("final", "mean", "band")  # how a visible score is summed over a clip (`Score`)
BETTER = ("higher", "lower")
SCORE_MARGIN = 1e-9  # visible scores' sums are rounded as the screen shows them: any difference is seen


def a_or_an(word: str) -> str:
    """The article before ``word``, by its first letter: "an error", "a speed"."""
    return "an" if word[:1].lower() in "aeiou" else "a"


@dataclass(frozen=True)
class Score:
    """A quantity each view shows on screen as it changes (a distance travelled, the error from a set point, a
    game's score), and how a viewer sums it over a clip: "final" (its value when the clip ends), "mean" (its mean
    over the clip's steps) or "band" (the seconds it spent within ``band``, [low, high]). ``better`` says which
    way the summed value is better. A viewer reads it at ``digits`` decimals (seconds in a band at one): two
    agents whose sums read the same are a tie. ``span`` is a difference of the sum that looks as plain as reaching
    a goal at once versus at the clip's end (1 on the observer's scale); a band's sum is seen as the share of the
    clip spent in it, so it needs none.

    Examples: locomotion ``Score("distance", "m", "higher", "final", span=5.0)``; a set point
    ``Score("error", "", "higher", "band", band=(-0.1, 0.1), digits=2)``; a game ``Score("score", "", "higher",
    "final", digits=0, span=10.0)``."""

    name: str
    unit: str = ""
    better: str = "higher"
    summed: str = "final"
    band: tuple[float, float] | None = None
    digits: int = 1
    span: float | None = None

    def __post_init__(self) -> None:
        where = f"visible score {self.name!r}"
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"a visible score needs a name to show on screen, such as 'distance', not {self.name!r}")
        if self.better not in BETTER:
            raise ValueError(f"{where}: better must be 'higher' or 'lower', not {self.better!r}")
        if self.summed not in SUMS:
            raise ValueError(f"{where}: summed must be one of {', '.join(map(repr, SUMS))}, not {self.summed!r}")
        if not isinstance(self.digits, int) or isinstance(self.digits, bool) or not 0 <= self.digits <= 6:
            raise ValueError(f"{where}: digits must be a whole number of decimals from 0 to 6, not {self.digits!r}")
        if self.summed == "band":
            if self.band is None or len(self.band) != 2 or not float(self.band[0]) <= float(self.band[1]):
                raise ValueError(f"{where}: summed 'band' needs band=(low, high) with low <= high, not {self.band!r}")
            if self.span is not None:
                raise ValueError(f"{where}: a band's sum is seen as a share of the clip: leave span unset")
        else:
            if self.band is not None:
                raise ValueError(f"{where}: band is for summed 'band' only, not {self.summed!r}")
            if self.span is None or not float(self.span) > 0:
                raise ValueError(
                    f"{where}: summed {self.summed!r} needs span > 0, the difference of its sum that looks as plain "
                    f"as reaching a goal at once versus at the clip's end; got {self.span!r}"
                )

    def to_manifest(self) -> dict[str, Any]:
        data = asdict(self)
        data["band"] = None if self.band is None else [float(v) for v in self.band]
        return data

    @classmethod
    def from_manifest(cls, data: Any) -> Score:
        if not isinstance(data, Mapping):
            raise ValueError(f"world.score must be an object with name, unit, better, summed, ..., not {data!r}")
        _known("world.score", data, tuple(f.name for f in fields(Score)))
        band = data.get("band")
        return cls(**{**data, "band": None if band is None else tuple(band)})

    def of(self, values: Sequence[float], dt: float) -> float:
        """The clip's sum of the values of the states it shows after its first (one a step, ``dt`` seconds apart),
        as a viewer reads it: rounded to what the screen shows."""
        if not values:
            raise ValueError(f"visible score {self.name!r}: a clip shows at least one step of it")
        if self.summed == "final":
            value = float(values[-1])
        elif self.summed == "mean":
            value = statistics.fmean(float(v) for v in values)
        else:
            assert self.band is not None
            value = dt * sum(1 for v in values if self.band[0] <= float(v) <= self.band[1])
        return round(value, 1 if self.summed == "band" else self.digits)

    def seen(self, summed: float, end_s: float) -> float:
        """A clip's sum on the observer's scale (larger is better): over ``span``, or a band's share of the clip."""
        scale = end_s if self.summed == "band" else float(self.span or 1.0)
        return (1.0 if self.better == "higher" else -1.0) * summed / max(scale, 1e-9)

    def reading(self, value: float) -> str:
        """A value as the screen shows it, with its unit: ``0.04``, ``12.3 m``."""
        return f"{value:.{self.digits}f}{' ' + self.unit if self.unit else ''}"

    def caption(self, now: float, since_first: Sequence[float], dt: float, moment: bool = False) -> str:
        """What a view shows under it at a state, number first so a line too short for the name still shows it
        (`search.clips.render.fit_text` cuts the end): the value ``now`` (``12.3 m distance``), or for a mean or a
        band what the clip has summed so far over ``since_first``, the values of the states after its first
        (``0.35 rad mean angle error``, ``1.2 s in band``). In a ``moment`` of a reel the sum starts again with
        each moment, so a mean or a band says whose it is (``92 km/h mean speed this moment``), never read as the
        reel's running sum."""
        over = " this moment" if moment else ""
        if self.summed == "band":
            return f"{one_decimal(self.of(since_first, dt) if since_first else 0.0)} s in band{over}"
        if self.summed == "mean":
            return f"{self.reading(self.of(since_first, dt) if since_first else now)} mean {self.name}{over}"
        return f"{self.reading(now)} {self.name}"

    def describe(self, summed: float) -> str:
        """A clip's sum in words, after an agent's label: ``ended with a distance of 12.3 m``, ``had a mean speed of
        72 km/h``, ``kept its offset within -0.20 to 0.20 for 3.5 seconds``."""
        if self.summed == "final":
            return f"ended with {a_or_an(self.name)} {self.name} of {self.reading(summed)}"
        if self.summed == "mean":
            return f"had a mean {self.name} of {self.reading(summed)}"
        assert self.band is not None
        low, high = (f"{v:.{self.digits}f}" for v in self.band)
        return f"kept its {self.name} within {low} to {high} for {one_decimal(summed)} seconds"


# The words' defaults speak of agents and outcomes in general. A default text may name the agent's word: ``{Agent}``
# as given ("Car"), ``{agent}`` in lower case, ``{an_agent}`` after its article ("a car", "an agent"), ``{agents}``
# and ``{Agents}`` the agents in running text (`Words.many`) and capitalised; a `Words` fills them in when made, so
# ``Words(agent="Car")`` reads "Car 7" and "cars" in every text it leaves at its default.
_NAMED = ("{Agent}", "{agent}", "{an_agent}", "{Agents}", "{agents}")


@dataclass(frozen=True)
class Words:
    """What a world's pages call the things its clips show. The defaults speak of agents and outcomes in general,
    in the agent's word (`agent`, `agents`): a world sets the texts its clips need in words of their own; the
    crowd's are `CROWD_WORDS`. Legend lines are plain text where ``**text**`` reads in bold (the pages escape
    everything else); an empty `legend_trails` or `others_marker` leaves that line or marker out. The outcome
    phrases follow an agent's label ("Agent 2 ..."); `success` and `collision` may say ``{seconds}``, the run's time
    it happened as the clip's clock shows it (one decimal)."""

    agent: str = "Agent"  # the word before an agent's number, on its clips and the pages: "Agent 2"
    agents: str = ""  # the agents in running text ("the cars"); empty: the agent's word and an s ("agents")
    clip_title: str = "Clip of two {agents} side by side, each in its own copy of the same world"  # a video's name
    # a pair of reels (each agent on its own, in moments of its own runs): the line above them and each reel's
    # accessible name, which the page follows with the agent's label
    reels_intro: str = "Each {agent} is shown on its own, in moments from its own runs."
    reel_title: str = "Clip of one {agent} on its own"
    # under the instructions' example clip, unless the study file says otherwise
    example_caption: str = "An example: two {agents}, each in its own copy of the same world, side by side."
    legend_robots: str = (
        "{Agents}: each view shows one {agent}, named below the picture, such as {Agent} 7, with a colour and a"
        " shape of its own."
    )
    others_marker: str = ""  # the text in the grey disc that marks the others' legend line
    legend_others: str = "Everything else in a view is the world: it starts the same in both views."
    legend_trails: str = ""
    legend_crash: str = (
        "A yellow-and-black burst marks the moment {an_agent} fails; the list below the picture then says **failed**."
    )
    legend_status: str = (
        "Below the picture each {agent}'s line says **succeeded**, **failed**, **out of time** or **running**, with"
        " the time."
    )
    success: str = "succeeded after {seconds} seconds"
    collision: str = "failed after {seconds} seconds"
    timeout: str = "ran out of time"
    running: str = "was still going when the clip ended"
    close_call: str = ""
    # what a clip visibly shows of a run, in a few words: where the bundle's gallery says what makes a clip misleading
    shown: str = "how each {agent}'s run ended, and when"
    # a compare question's answers (app.survey.study.CompareQuestion): after an agent's label, that it is better;
    # or no difference seen between the two
    is_better: str = "is better"
    no_difference: str = "No difference I can see between the two {agents}"
    # the instructions' paragraph on how agents are named, the line above a ranking round's clips and the notice
    # at each new round: a study file's [texts] robot_names, names_in_round and new_round say otherwise
    names: str = (
        "Every {agent} has a name (such as {Agent} 7), colour and shape of its own. A name never stands for two"
        " different {agents} in this study, and in a ranking round each name is one {agent} in all of the round's"
        " clips. Each new round brings {agents} with new names."
    )
    names_in_round: str = "In this round each name, colour and shape is one {agent} in all three clips."
    new_round: str = (
        "A new round begins. Its {agents} have names you have not seen in the earlier rounds: judge them from this"
        " round's clips."
    )

    def __post_init__(self) -> None:
        """Fills the agent's word into each text left at its default (a text of the world's own stays as given)."""
        for field in fields(self):
            text = getattr(self, field.name)
            if text == field.default and any(name in text for name in _NAMED):
                object.__setattr__(self, field.name, self.say(text))

    def say(self, text: str) -> str:
        """``text`` with the agent's word filled in where it names it (``{Agent}``, ``{agent}``, ``{an_agent}``,
        ``{agents}``, ``{Agents}``): how the report, the codebook and the pages speak of this world's agents."""
        many = self.many()
        named = {
            "{Agent}": self.agent,
            "{agent}": self.one(),
            "{an_agent}": f"{a_or_an(self.agent)} {self.one()}",
            "{Agents}": many[:1].upper() + many[1:],
            "{agents}": many,
        }
        for name, word in named.items():
            text = text.replace(name, word)
        return text

    def many(self) -> str:
        """The agents in running text: `agents`, or the agent's word in lower case with an s."""
        return self.agents or self.agent.lower() + "s"

    def one(self) -> str:
        """One agent in running text: the agent's word in lower case ("robot", "car")."""
        return self.agent.lower()


# The crowd's words: robots among people, reaching a goal. A crowd bundle's manifest has no `world` object, and its
# pages read these.
CROWD_WORDS = Words(
    agent="Robot",
    clip_title="Clip of two robots in a crowd",
    reels_intro="Each robot is shown on its own, in moments from its own runs through a crowd.",
    reel_title="Clip of one robot on its own in a crowd",
    example_caption=(
        "An example: two robots, each with its own colour, shape and name, move through a crowd to the same goal."
    ),
    legend_robots=(
        "Robots: each has a colour, a shape (disc, square, diamond, triangle, upside-down triangle or plus) and a"
        " number of its own, drawn on it; its name, such as Robot 7, is listed below the picture."
    ),
    others_marker="0",
    legend_others="People: grey discs with a number, each with a short tail showing where it walks.",
    legend_trails="Trails: the line behind a robot is the path it has taken.",
    legend_crash=(
        "A yellow-and-black burst and **CRASH** mark a robot bumping into a person; the list below the picture then"
        " says **CRASHED**."
    ),
    legend_status=(
        "Below the picture each robot's line says **reached goal** or **out of time** with the time, or **on its"
        " way** (**still on its way** when the clip ends, with how far it stopped from its goal)."
    ),
    success="reached the goal after {seconds} seconds",
    collision="bumped into a person",
    timeout="ran out of time before reaching the goal",
    running="was still on its way when the clip ended",
    close_call="came close to people",
    shown="who bumped into a person, who reached the goal and when, how far the others got",
    names=(
        "Every robot has a name (such as Robot 7), colour and shape of its own. A name never stands "
        "for two different robots in this study, and in a ranking round each name is one robot in "
        "all of the round's clips. Each new round brings robots with new names."
    ),
    names_in_round="In this round each name, colour and shape is one robot in all three clips.",
    new_round=(
        "A new round begins. Its robots have names you have not seen in the earlier rounds: judge them "
        "from this round's clips."
    ),
)


@dataclass(frozen=True)
class World:
    """Which world a bundle's clips show, the rule that judges them (`RULES`) and its words: the manifest's
    `world` object, absent for the crowd (`CROWD`). The defaults are a world's in general, in `Words`' defaults."""

    domain: str = "world"
    rule: str = "goal"
    words: Words = Words()
    score: Score | None = None  # what each view shows of how its agent is doing (`Score`); None: nothing

    def __post_init__(self) -> None:
        if self.rule == "score" and self.score is None:
            raise ValueError(
                f"world {self.domain!r} is judged by the rule 'score' but declares no visible score: declare one "
                "(app.visible.Score: its name, unit, which way is better, how a clip sums it) or use 'goal' or "
                "'survival'"
            )
        if not self.has_outcomes():  # no goal, no crash: the default legend lines of outcomes are left out
            unsaid = {
                name: ""
                for name in ("legend_crash", "legend_status")
                if getattr(self.words, name) == getattr(Words(agent=self.words.agent, agents=self.words.agents), name)
            }
            if unsaid:
                object.__setattr__(self, "words", replace(self.words, **unsaid))

    def to_manifest(self) -> dict[str, Any]:
        """The manifest's `world` object; a world without a score writes no `score` key."""
        shown = {"domain": self.domain, "rule": self.rule, "words": asdict(self.words)}
        return shown if self.score is None else shown | {"score": self.score.to_manifest()}

    @classmethod
    def from_manifest(cls, data: Mapping[str, Any] | None) -> World:
        """The world of a manifest's `world` object (None: the crowd's, `CROWD`). Words it leaves out keep their
        defaults (`Words`, in its agent's word); a key, rule or word this version does not know is a ValueError
        that names it."""
        if data is None:
            return CROWD
        if not isinstance(data, Mapping):
            raise ValueError(f"world must be an object with domain, rule, words and score, not {data!r}")
        _known("world", data, ("domain", "rule", "words", "score"))
        domain, rule, words = data.get("domain", "world"), data.get("rule", "goal"), data.get("words", {})
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
        score = None if data.get("score") is None else Score.from_manifest(data["score"])
        return cls(domain=domain, rule=rule, words=Words(**words), score=score)

    def has_outcomes(self) -> bool:
        """Whether its clips end in outcomes a viewer reads (reaching a goal, a crash, lasting): not a world judged
        by its visible score alone (the rule "score"), whose pages and reports speak of the score instead."""
        return self.rule != "score"


# The crowd's world: a manifest without a `world` object shows it, and the crowd's domain says so.
CROWD = World(domain="crowd", rule="goal", words=CROWD_WORDS)


def _known(where: str, data: Mapping[str, Any], keys: tuple[str, ...]) -> None:
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise ValueError(f"{where} has unknown key(s) {', '.join(map(repr, unknown))}; it knows {', '.join(keys)}")


@dataclass(frozen=True)
class Observer:
    """How a viewer judges an agent in a clip. By the "goal" rule reaching the goal beats timing out beats
    colliding, and sooner is better; by the "survival" rule (the task is to last: driving, balancing) lasting
    the clip beats crashing, and crashing later is better. Coming closer than `comfort_m` to a person counts
    against an agent that did not collide. `noise` is the standard deviation of
    the perception noise, in the same units (reaching the goal at once versus at the end of the clip is 1).
    Scores closer than `tie_margin` look the same (two agents both still on their way, a few metres apart). A
    world's visible score (`Score`) judges its clips by the "score" rule, and breaks such ties in the others: there
    two agents look the same only where their sums read the same (`VisibleClip.margin`)."""

    noise: float = 0.5
    comfort_m: float = 0.5
    closeness_weight: float = 2.0
    tie_margin: float = 0.25

    def visible_score(self, outcome: Mapping[str, Any], end_s: float, progress: float, rule: str = "goal") -> float:
        """An agent's score by its outcome under the rule "goal" or "survival" (a "score" world's clips are judged
        by their `Score` instead, `VisibleClip.scores`)."""
        if rule not in ("goal", "survival"):
            raise ValueError(f"an outcome is judged by the rule 'goal' or 'survival', not {rule!r}")
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

    def expected_vote(self, difference: float) -> float:
        """What a clip whose two agents' scores differ by ``difference`` (first minus second) is worth to a vote: the
        share of viewers who pick the first minus the share who pick the second, as `perceive` picks (each score
        seen with independent noise: P(first) = Phi(difference / (noise * sqrt 2)), so erf(difference / (2 * noise)));
        a difference of a crash against lasting (1 or more) counts almost fully, one a viewer barely sees almost
        nothing. Without noise, every viewer picks the higher score."""
        if self.noise == 0:
            return float((difference > 0) - (difference < 0))
        return math.erf(difference / (2 * self.noise))

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
    world: World = CROWD
    summed: tuple[float, ...] = ()  # per label its visible score summed over the clip (`Score.of`), where shown
    clock_s: float = 0.0  # the run's seconds before the clip's first state (a window's start), as its clock shows

    @classmethod
    def of_summary(
        cls, summary: Mapping[str, Any], agents: list[str], labels: list[str], world: World | None = None
    ) -> VisibleClip:
        """The clip of a summary.json whose agents ``agents`` (in on-screen order) carry ``labels``, in ``world``
        (the crowd's when None)."""
        names = [agent["name"] for agent in summary["agents"]]
        order = [names.index(agent) for agent in agents]  # the summary's index of each label's agent
        return cls._of_robots(summary, order, labels, world)

    @classmethod
    def of_segment(cls, summary: Mapping[str, Any], label: str, world: World | None = None) -> VisibleClip:
        """One segment of a reel as a clip of the one agent labelled ``label``: in a segment every agent's instance
        follows the reel's agent (the summary's ``follow.leader``), so the leader's outcome is what it shows."""
        follow = summary.get("follow")
        if not isinstance(follow, Mapping) or not isinstance(follow.get("leader"), int):
            raise ValueError(f"a reel's segment says whom its agents follow (follow.leader); this one has {follow!r}")
        return cls._of_robots(summary, [follow["leader"]], [label], world)

    @classmethod
    def _of_robots(
        cls, summary: Mapping[str, Any], order: Sequence[int], labels: Sequence[str], world: World | None
    ) -> VisibleClip:
        """The clip of the summary's agents ``order`` (its indices), labelled ``labels``. A summary with a ``window``
        is judged as its clip shows it, from the window's first state on; its times read, as its clock, the run's."""
        steps = summary.get("steps") or [{"t": 1.0}]
        first = int((summary.get("window") or [0])[0])
        start_s = float(steps[first - 1]["t"]) if 0 < first <= len(steps) else 0.0
        return cls(
            labels=tuple(labels),
            outcomes=tuple(_since(summary["outcomes"][k], start_s) for k in order),
            progress=tuple(_progress(summary, k) for k in order),
            end_s=max(float(steps[-1]["t"]) - start_s, 1e-6),
            world=world or CROWD,
            to_goal=tuple(_to_goal(summary, k) for k in order),
            summed=_summed(summary, order, first, world or CROWD),
            clock_s=start_s,
        )

    def pick(self, indices: Sequence[int], end_s: float) -> VisibleClip:
        """The clip of the agents at ``indices`` alone, ending at ``end_s``: a pair's clip read from a rollout of
        more agents, in which each agent's outcome, progress and score are its own up to its ending."""

        def of(values: tuple[Any, ...]) -> tuple[Any, ...]:
            return tuple(values[i] for i in indices) if values else ()

        return replace(
            self,
            labels=of(self.labels),
            outcomes=of(self.outcomes),
            progress=of(self.progress),
            to_goal=of(self.to_goal),
            summed=of(self.summed),
            end_s=end_s,
        )

    def scores(self, observer: Observer) -> dict[str, float]:
        return self._judged(observer)[0]

    def margin(self, observer: Observer) -> float:
        """How far apart two labels' scores must be to look different: the observer's tie margin, or where the
        visible score judges the clip, any difference at all (sums that read the same are equal)."""
        return SCORE_MARGIN if self._judged(observer)[1] else observer.tie_margin

    def _judged(self, observer: Observer) -> tuple[dict[str, float], bool]:
        """Each label's score, and whether its visible score judged it: in a "score" world always; in the others
        where the outcomes tie (within the tie margin), each then scores their mean plus its visible score."""
        score = self.world.score
        if score is not None and len(self.summed) != len(self.labels):
            raise ValueError(
                f"a clip of world {self.world.domain!r} is judged by its visible score {score.name!r}, but its "
                "summary records none per step (steps[i].scores): build it again with this version's foil search"
            )
        if self.world.rule == "score":
            assert score is not None
            return {label: score.seen(s, self.end_s) for label, s in zip(self.labels, self.summed, strict=True)}, True
        shown = {
            label: observer.visible_score(outcome, self.end_s, progress, self.world.rule)
            for label, outcome, progress in zip(self.labels, self.outcomes, self.progress, strict=True)
        }
        if score is None or len(shown) < 2 or max(shown.values()) - min(shown.values()) >= observer.tie_margin:
            return shown, False
        middle = statistics.fmean(shown.values())
        return {
            label: middle + score.seen(s, self.end_s) for label, s in zip(self.labels, self.summed, strict=True)
        }, True

    def describe(self, label: str) -> str:
        """How the agent labelled ``label`` visibly ended, as one sentence in the world's words: by its visible
        score in a "score" world, its outcome then the score where a world shows both."""
        score = self.world.score
        if score is None or len(self.summed) != len(self.labels):
            return self._ending(label)
        summed = score.describe(self.summed[self.labels.index(label)])
        if self.world.rule == "score":
            return f"{label} {summed}."
        return f"{self._ending(label).removesuffix('.')}; it {summed}."

    def _ending(self, label: str) -> str:
        """How the agent labelled ``label`` visibly ended by its outcome."""
        outcome = self.outcomes[self.labels.index(label)]
        event = outcome.get("event")
        words = self.world.words
        # anything else is still moving when the clip ends, as the clip's "still on its way"
        phrase = {"success": words.success, "collision": words.collision, "timeout": words.timeout}.get(
            str(event), words.running
        )
        seconds = float(outcome.get("time") or self.end_s) + self.clock_s  # the run's time, as the clip's clock
        text = f"{label} {phrase.format(seconds=one_decimal(seconds))}"
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
    label the segments of its reel, each a one-agent `VisibleClip`. An agent is judged by its visible score averaged
    over its reel's segments, by the same observer as a clip of both."""

    labels: tuple[str, ...]
    reels: tuple[tuple[VisibleClip, ...], ...]  # per label, its reel's segments in the order shown
    world: World = CROWD

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
        return cls(labels=tuple(labels), reels=shown, world=world or CROWD)

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

    def margin(self, observer: Observer) -> float:
        """As `VisibleClip.margin`: a reel's segment shows one agent, so only a "score" world's reels are judged by
        their visible score."""
        return SCORE_MARGIN if self.world.rule == "score" else observer.tie_margin

    def moments(self, label: str) -> list[str]:
        """How the agent labelled ``label`` ended in each moment of its reel, one sentence a moment, at its run's
        time as the reel's clock shows it: ``Moment 2 of 3: Agent 4 reached the goal after 17.2 seconds.``"""
        reel = self.reels[self.labels.index(label)]
        return [f"Moment {i} of {len(reel)}: {segment.describe(label)}" for i, segment in enumerate(reel, 1)]

    def describe(self, label: str) -> str:
        """How the agent labelled ``label`` ended in each moment of its reel, as one sentence in the world's words."""
        reel = self.reels[self.labels.index(label)]
        moments = "; ".join(segment.describe(label).removeprefix(f"{label} ").removesuffix(".") for segment in reel)
        return f"{label}, in {len(reel)} moment{'' if len(reel) == 1 else 's'} of its own: {moments}."


Visible = VisibleClip | VisibleReels  # what one question's video shows: a clip of both agents, or their reels


def audit(clip: Visible, better: str, observer: Observer | None = None) -> dict[str, str]:
    """Whether a two-agent clip (or pair of reels) visibly shows the better agent (label ``better``) as better, as
    worse, or shows no difference, judged without perception noise: ``{"shows": "better" | "worse" | "tie", "why":
    ...}``."""
    observer = observer or Observer()
    scores = clip.scores(observer)
    if better not in scores or len(scores) != 2:
        raise ValueError(f"an audit compares two agents, one of them {better!r}; the clip has {list(scores)}")
    other = next(label for label in clip.labels if label != better)
    difference = scores[better] - scores[other]
    shows = "tie" if abs(difference) < clip.margin(observer) else "better" if difference > 0 else "worse"
    return {"shows": shows, "why": f"{clip.describe(better)} {clip.describe(other)}"}


def one_decimal(value: float) -> str:
    """A time or distance as the clips write it, so that a page never says another number than its clip."""
    return f"{value:.1f}"


def _ends(summary: Mapping[str, Any], k: int) -> tuple[Sequence[float], Sequence[float], Sequence[float]] | None:
    """Agent k's start, goal and place at the end of the clip (None when the summary lacks them)."""
    try:
        robot = summary["scenario"]["robot"]
        return robot["start"], robot["goal"], summary["steps"][-1]["agent_positions"][k]
    except (KeyError, IndexError, TypeError):
        return None


def _progress(summary: Mapping[str, Any], k: int) -> float:
    """Share of the start-to-goal distance agent k covered by the end of the clip (0 when unknown)."""
    ends = _ends(summary, k)
    return progress_towards(*ends) if ends else 0.0


def _since(outcome: Mapping[str, Any], start_s: float) -> Mapping[str, Any]:
    """An outcome with its time counted from ``start_s`` (an event before it happened at the clip's start)."""
    if not start_s or outcome.get("time") is None:
        return outcome
    return {**outcome, "time": max(0.0, float(outcome["time"]) - start_s)}


def _summed(summary: Mapping[str, Any], order: Sequence[int], first: int, world: World) -> tuple[float, ...]:
    """Each agent's visible score summed over the states its clip shows after its first, up to its ending (a view
    stops where its agent's run ended, and so does its readout); none where the world shows no score or the
    summary records none."""
    steps = summary.get("steps") or []
    shown = steps[first:]
    if world.score is None or not shown or any("scores" not in step for step in shown):
        return ()
    start_s = float(steps[first - 1]["t"]) if first > 0 else 0.0
    dt = (float(shown[-1]["t"]) - start_s) / len(shown)
    return tuple(
        world.score.of([float(step["scores"][k]) for step in _until_ended(summary, k, shown)], dt) for k in order
    )


def _until_ended(summary: Mapping[str, Any], k: int, shown: Sequence[Mapping[str, Any]]) -> Sequence[Mapping[str, Any]]:
    """The states of ``shown`` up to agent k's ending (at least the first: one that ended before the clip began
    shows where it ended); all of them for an agent still running."""
    ended = summary["outcomes"][k]
    if ended.get("event") in (None, "running") or ended.get("time") is None:
        return shown
    until = [step for step in shown if float(step["t"]) <= float(ended["time"]) + 1e-9]
    return until or shown[:1]


def _to_goal(summary: Mapping[str, Any], k: int) -> float | None:
    """How far agent k's centre is from its goal at the end of the clip (None when unknown)."""
    ends = _ends(summary, k)
    return math.dist(ends[1], ends[2]) if ends else None


def progress_towards(start: Sequence[float], goal: Sequence[float], end: Sequence[float]) -> float:
    """Share of the start-to-goal distance covered at ``end`` (none when farther from the goal than the start)."""
    total = math.dist(start, goal)
    return max(0.0, 1 - math.dist(end, goal) / total) if total > 0 else 1.0
