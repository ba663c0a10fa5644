"""The study definition: a TOML file validated with pydantic, with errors that name the line and the field.

The file says what participants see (texts, parts, questions), how they are assigned (design), where they come from
(platform) and where they go at the end (completion). A top-level `[build]` table says which clips `foil bundle`
searches for and renders: the bundle builder owns it (`search.bundle.spec`), so it is any table here. Errors are
located in the file by `app.toml_errors`, as the bundle builder's are.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

from app.toml_errors import Loc, Problem, TomlFileError, load_toml, validated


class StudyError(TomlFileError):
    """A study file that cannot be used; the message names the file, line and field."""


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


Text = Annotated[str, Field(min_length=1)]


def distinct(values: list[str]) -> list[str]:
    """Names given once each (a validator)."""
    if len(set(values)) != len(values):
        raise ValueError("names must not repeat")
    return values


def _two_different(pair: tuple[str, str]) -> tuple[str, str]:
    if pair[0] == pair[1]:
        raise ValueError("a pair needs two different agents")
    return pair


Names = Annotated[list[Text], Field(min_length=1), AfterValidator(distinct)]
Pair = Annotated[tuple[Text, Text], AfterValidator(_two_different)]


class ClipRef(Strict):
    """A clip named the way the bundle names it: scheme, scenario and the agents it shows (any on-screen order)."""

    scheme: Text
    scenario: Text
    agents: tuple[Text, Text]


class StudyInfo(Strict):
    id: Annotated[str, Field(pattern=r"^[A-Za-z0-9_.-]{1,64}$")]
    title: Text
    platform: Literal["prolific", "mturk", "none"]
    assignment: Literal["balanced", "self-select"] = "balanced"
    seed: int
    device: Literal["any", "desktop"] = "any"
    require_full_view: bool = True
    preload_timeout_s: Annotated[float, Field(gt=0, le=300)] = 20.0
    estimated_minutes: Annotated[int, Field(gt=0)] | None = None
    contact: str = ""
    consent_version: Annotated[str, Field(max_length=64)] = ""  # recorded per participant; default: text hash
    progress_bar: bool = True  # a bar with "screen N of M" above every screen


class Design(Strict):
    schemes: Names
    scheme_factor: Literal["within", "between"] = "within"
    scenarios: Names
    counterbalance_scenarios: bool = True
    counterbalance_scheme_order: bool = True
    # a scheme whose clips come from other scenarios than `scenarios`, as many (e.g. a distribution of starting
    # states for the representative solver): scheme -> its scenario for each of the design's scenarios
    scheme_scenarios: dict[Text, Annotated[list[Text], Field(min_length=1)]] = {}
    # a study of updates: pairs (earlier, later) of versions of one agent, each a pair of a pairwise part; the
    # pages never say which is which. `controls`: update pairs the study holds to be equal (two snapshots the
    # ground truth calls equal), whatever the truth decides
    updates: list[Pair] = []
    controls: list[Pair] = []

    @model_validator(mode="after")
    def _scheme_scenarios(self) -> Design:
        for scheme, names in self.scheme_scenarios.items():
            if scheme not in self.schemes:
                raise ValueError(f"scheme_scenarios names {scheme!r}, which is not one of schemes {self.schemes}")
            if len(names) != len(self.scenarios):
                raise ValueError(
                    f"scheme_scenarios.{scheme} gives {len(names)} scenarios; the design has "
                    f"{len(self.scenarios)}, one for each"
                )
        if len({frozenset(pair) for pair in self.updates}) != len(self.updates):
            raise ValueError("updates lists a pair twice: list each (earlier, later) pair once")
        for earlier, later in self.controls:
            if (earlier, later) not in self.updates:
                raise ValueError(
                    f"controls names [{earlier!r}, {later!r}], which is not one of updates: a control is an update "
                    "pair, (earlier, later) as updates lists it"
                )
        return self

    def update_of(self, agents: tuple[str, str] | list[str]) -> tuple[str, str] | None:
        """The (earlier, later) update pair of these two agents, in either order; None for no update pair."""
        return next((pair for pair in self.updates if set(pair) == set(agents)), None)


class Texts(Strict):
    consent: Text
    instructions: Text
    agree: Text = "I agree to take part"
    decline: Text = "I do not agree"
    declined: Text = "You chose not to take part. Thank you for your time; you can close this page."
    completion: Text = "Thank you for taking part."
    debrief: str = ""  # shown on the completion page: what the study was about
    preview: Text = "Accept the HIT to start the study."
    watch: Text = "Watch the clip to the end. The questions unlock when it has finished; you can replay it."
    watch_only: Text = "Watch the clip to the end. The Next button unlocks when it has finished; you can replay it."
    watch_reels: Text = (  # above a pair of reels, each agent's clip on its own
        "Play both clips to the end, one after the other (the second is beside or below the first). The questions "
        "unlock when both have finished; you can replay them."
    )
    watch_reels_only: Text = (  # above a ranking round's pair of reels, watched without questions
        "Play both clips to the end, one after the other (the second is beside or below the first). The Next "
        "button unlocks when both have finished; you can replay them."
    )
    example_caption: str = ""  # under the instructions' example clip; empty: the caption of the bundle's world
    # empty: the words of the bundle's world (app.visible.Words names, names_in_round, new_round)
    robot_names: str = ""  # on the instructions page: how agents are named
    names_in_round: str = ""  # above a ranking round's clips
    new_round: str = ""  # at the start of every ranking round after the first


class Completion(Strict):
    code: str = ""
    redirect_url: Annotated[str, Field(pattern=r"^(https://\S+)?$")] = ""

    @model_validator(mode="after")
    def _something(self) -> Completion:
        if not self.code and not self.redirect_url:
            raise ValueError("give a completion code, a redirect_url (https://...), or both")
        return self


# Checking a submitted form field: `read(field)` gives the field's one value (None when it is missing or repeated),
# `labels` the agents on the screen; a check gives (the answer, None) or (None, the message shown next to the field).
FieldReader = Callable[[str], str | None]
Answer = str | int | list[str]
CheckedAnswer = tuple[Answer, None] | tuple[None, str]


def digits(value: str) -> bool:
    """Whether `value` is a whole number in ASCII digits: str.isdigit alone also takes '²', which int() refuses."""
    return value.isascii() and value.isdigit()


def check_option(options: list[str], value: str | None) -> CheckedAnswer:
    """One of `options`, as a choice question and the instructions' check question take it."""
    return (value, None) if value in options else (None, "Choose one of the answers.")


class ChooseQuestion(Strict):
    """Pick one of the agents shown in the clip."""

    type: Literal["choose"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        value = read(name)
        if value not in labels:
            return None, "Choose one of the names shown." if not value else "That name is not in this clip."
        return value, None


NO_DIFFERENCE = "no difference"  # the answer of a compare question that sees no difference between the agents


class CompareQuestion(Strict):
    """Which of the two agents in the clip is better, or no difference seen: three answers, the two agents in the
    order the clip's legend lists them (the bundle draws their numbers per clip, so either may come first) and
    "no difference I can see" between them, in the words of the bundle's world (`app.visible.Words`)."""

    type: Literal["compare"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)

    def answers(self, labels: list[str]) -> list[str]:
        """The answers in the order the page lists them: "no difference" between the two agents it compares."""
        return [labels[0], NO_DIFFERENCE, *labels[1:]]

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        value = read(name)
        if value != NO_DIFFERENCE and value not in labels:
            return None, "Choose one of the answers." if not value else "That name is not in this clip."
        return value, None


class TextQuestion(Strict):
    type: Literal["text"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)
    min_length: Annotated[int, Field(ge=1)] = 1
    max_length: Annotated[int, Field(ge=1, le=10_000)] = 2000
    rows: Annotated[int, Field(ge=1, le=20)] = 3

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        value = read(name) or ""
        if len(value.strip()) < self.min_length:
            at_least = f"at least {self.min_length} characters" if self.min_length > 1 else "an answer"
            return None, f"Please write {at_least}."
        if len(value) > self.max_length:
            return None, f"Please keep this under {self.max_length} characters (you wrote {len(value)})."
        return value, None


class ScaleQuestion(Strict):
    """Points 1..n; `anchors` label both ends, `labels` every point (e.g. a Likert scale)."""

    type: Literal["scale"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)
    points: Annotated[int, Field(ge=2, le=11)]
    anchors: tuple[Text, Text] | None = None
    labels: list[Text] | None = None

    @model_validator(mode="after")
    def _labelled(self) -> ScaleQuestion:
        if self.labels is None and self.anchors is None:
            raise ValueError("label the scale: give anchors = [low, high] or labels = [one per point]")
        if self.labels is not None and len(self.labels) != self.points:
            raise ValueError(f"labels has {len(self.labels)} entries but points = {self.points}")
        return self

    def point_labels(self) -> list[str]:
        """Text for every point: the given labels, or the anchors at the ends and the number in between."""
        if self.labels is not None:
            return list(self.labels)
        assert self.anchors is not None  # _labelled: labels or anchors
        low, high = self.anchors
        return [low if i == 1 else high if i == self.points else str(i) for i in range(1, self.points + 1)]

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        value = read(name)
        if not value:
            return None, "Choose one point on the scale."
        if not digits(value) or not 1 <= int(value) <= self.points:
            return None, f"The answer must be a whole number from 1 to {self.points}."
        return int(value), None


class RankQuestion(Strict):
    """Order every agent of a ranking part from best to worst."""

    type: Literal["rank"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        """The agents best first, from the fields `name-1` (the best place) to `name-N`."""
        ranking = [read(f"{name}-{place}") for place in range(1, len(labels) + 1)]
        if any(not value for value in ranking):
            return None, "Put a name in every place of the ranking."
        if any(value not in labels for value in ranking):
            return None, "The ranking has a name that is not in this study."
        if len(set(ranking)) != len(ranking):
            return None, "Each name can take only one place: the ranking has a name twice."
        return [value for value in ranking if value is not None], None


class ChoiceQuestion(Strict):
    """One of the researcher's options, such as an age range (a closing question, see `ClosingQuestions`)."""

    type: Literal["choice"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)
    options: Annotated[list[Text], Field(min_length=2)]

    @field_validator("options")
    @classmethod
    def _distinct(cls, values: list[str]) -> list[str]:
        if len(set(values)) != len(values):
            raise ValueError("options must not repeat")
        return values

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        return check_option(self.options, read(name))


Question = Annotated[
    ChooseQuestion | CompareQuestion | TextQuestion | ScaleQuestion | RankQuestion | ChoiceQuestion,
    Field(discriminator="type"),
]

FEEDBACK = "feedback"  # the name of the closing screen's feedback box in the data


class ClosingQuestions(Strict):
    """An optional last screen after the parts, before the completion page: closing questions (demographics,
    experience with agents) and a free-text feedback box, every answer optional unless named in `required`."""

    title: Text = "Before you finish"
    intro: str = "These last questions are optional: answer the ones you are comfortable answering."
    questions: list[Text] = []  # names of [questions] entries of type choice, scale or text
    feedback: str = ""  # the feedback box's question; empty: no box
    required: list[Text] = []  # closing questions (or "feedback") that must be answered

    def asks(self) -> list[str]:
        """Every answer the screen can hold, in order: the questions, then the feedback box."""
        return [*self.questions, *([FEEDBACK] if self.feedback else [])]


class PairwisePart(Strict):
    """One screen per clip: the clip of each pair under each scheme, answered on its own."""

    kind: Literal["pairwise"]
    title: Text
    intro: str = ""
    pairs: Annotated[list[Pair], Field(min_length=1)]
    order: Literal["shuffled", "blocked"] = "shuffled"
    questions: Annotated[list[Text], Field(min_length=1)]


class RankingPart(Strict):
    """Per scheme: one screen per pairwise clip of `agents`, then one screen ranking them all."""

    kind: Literal["ranking"]
    title: Text
    intro: str = ""
    agents: Annotated[list[Text], Field(min_length=2)]
    questions: Annotated[list[Text], Field(min_length=1)]


Part = Annotated[PairwisePart | RankingPart, Field(discriminator="kind")]


class AttentionCheck(Strict):
    """An instructed-response item shown after screen `after` of part `part` (both counted from 1). With `clip`,
    a video attention check: the clip is shown (and must be watched) and the question has a known answer about
    what it visibly shows (say, whether an agent crashed)."""

    part: Annotated[int, Field(ge=1)]
    after: Annotated[int, Field(ge=0)]
    text: Text
    options: Annotated[list[Text], Field(min_length=2)]
    expected: Text
    clip: ClipRef | None = None

    @model_validator(mode="after")
    def _expected_is_an_option(self) -> AttentionCheck:
        if self.expected not in self.options:
            raise ValueError(f"expected {self.expected!r} is not one of the options")
        return self


class ComprehensionCheck(Strict):
    """A question about the instructions, asked on the instructions page; the participant goes on only once it is
    answered right (every attempt is counted on their record)."""

    text: Text
    options: Annotated[list[Text], Field(min_length=2)]
    expected: Text

    @model_validator(mode="after")
    def _expected_is_an_option(self) -> ComprehensionCheck:
        if self.expected not in self.options:
            raise ValueError(f"expected {self.expected!r} is not one of the options")
        return self


class Study(Strict):
    study: StudyInfo
    design: Design
    texts: Texts
    completion: Completion
    example: ClipRef | None = None
    parts: Annotated[list[Part], Field(min_length=1)]
    questions: dict[str, Question]
    attention_checks: list[AttentionCheck] = []
    comprehension: list[ComprehensionCheck] = []
    closing: ClosingQuestions | None = None
    build: dict[str, Any] | None = None  # the bundle builder's table (search.bundle.spec), left alone here

    def consent_version(self) -> str:
        """The version of the consent text each participant is recorded with: `[study] consent_version`, or
        `sha256:` and the first 12 hex digits of the consent text's hash (any edit gives a new version)."""
        if self.study.consent_version:
            return self.study.consent_version
        return "sha256:" + hashlib.sha256(self.texts.consent.encode()).hexdigest()[:12]

    def part_questions(self) -> set[str]:
        """The questions asked about the clips, in the parts (not on the closing screen)."""
        return {name for part in self.parts for name in part.questions}

    def rotations(self) -> range:
        """How far the scenarios are rotated across parts, one value per scenario counterbalancing level."""
        counterbalanced = self.design.counterbalance_scenarios
        return range(len(self.design.scenarios) if counterbalanced else 1)

    def part_scenario(self, part_index: int, rotation: int, scheme: str | None = None) -> str:
        """The scenario feeding a part: parts take the design's scenarios in turn, rotated per condition; a scheme
        with scenarios of its own takes its scenario at the same place."""
        names = self.design.scheme_scenarios.get(scheme or "", self.design.scenarios)
        return names[(part_index + rotation) % len(names)]


def _reference_problems(study: Study) -> list[Problem]:
    """Checks across tables that pydantic's per-field validation cannot see, as (location, message)."""
    problems: list[Problem] = []
    for name in study.questions:
        if not re.fullmatch(r"[a-z][a-z0-9_]{0,39}", name):
            problems.append((("questions", name), "question names are lower_snake_case, at most 40 characters"))
    for p, part in enumerate(study.parts):
        allowed = {"pairwise": {"choose", "compare", "text", "scale"}, "ranking": {"rank", "text", "scale"}}[part.kind]
        for q, name in enumerate(part.questions):
            question = study.questions.get(name)
            if question is None:
                problems.append((("parts", p, "questions", q), f"no question named {name!r} in [questions]"))
            elif question.type not in allowed:
                message = f"a {question.type!r} question cannot be asked in a {part.kind} part"
                problems.append((("parts", p, "questions", q), message))
        if part.kind == "ranking":
            ranks = [n for n in part.questions if getattr(study.questions.get(n), "type", None) == "rank"]
            if len(ranks) != 1:
                problems.append((("parts", p, "questions"), "a ranking part asks exactly one 'rank' question"))
            if len(set(part.agents)) != len(part.agents):
                problems.append((("parts", p, "agents"), "agents must not repeat"))
    if study.closing is not None:
        closing = study.closing
        for q, name in enumerate(closing.questions):
            question = study.questions.get(name)
            if question is None:
                problems.append((("closing", "questions", q), f"no question named {name!r} in [questions]"))
            elif question.type not in ("choice", "scale", "text"):
                message = f"a {question.type!r} question cannot be asked on the closing screen (choice, scale, text)"
                problems.append((("closing", "questions", q), message))
        if len(set(closing.questions)) != len(closing.questions):
            problems.append((("closing", "questions"), "questions must not repeat"))
        if closing.feedback and (FEEDBACK in study.questions):
            problems.append(
                (
                    ("closing", "feedback"),
                    f"the feedback box's answers are named {FEEDBACK!r}: rename [questions.{FEEDBACK}]",
                )
            )
        for r, name in enumerate(closing.required):
            if name not in closing.asks():
                problems.append((("closing", "required", r), f"{name!r} is not asked on the closing screen"))
        if not closing.asks():
            problems.append((("closing",), "give closing questions, a feedback question, or both"))
    problems += _update_problems(study)
    for c, check in enumerate(study.attention_checks):
        if check.part > len(study.parts):
            problems.append((("attention_checks", c, "part"), f"there are only {len(study.parts)} parts"))
    return problems


def _update_problems(study: Study) -> list[Problem]:
    """Each update pair is a pair of a pairwise part that asks a compare question about it."""
    problems: list[Problem] = []
    for u, pair in enumerate(study.design.updates):
        parts = [p for p in study.parts if p.kind == "pairwise" and any(set(pair) == set(q) for q in p.pairs)]
        if not parts:
            problems.append(
                (("design", "updates", u), f"{list(pair)} is no pair of a pairwise part: add it to a part's pairs")
            )
        elif not all(any(getattr(study.questions.get(n), "type", "") == "compare" for n in p.questions) for p in parts):
            message = f"a part that shows {list(pair)} asks no 'compare' question: add one to its questions"
            problems.append((("design", "updates", u), message))
    return problems


def _loc_without_union_tags(loc: Loc) -> Loc:
    """Pydantic puts the chosen union member (`questions.NAME.scale...`) in the location; the file does not."""
    tags = {"parts": {"pairwise", "ranking"}, "questions": {"choose", "compare", "text", "scale", "rank", "choice"}}
    if len(loc) >= 3 and loc[0] in tags and loc[2] in tags[str(loc[0])]:
        return loc[:2] + loc[3:]
    return loc


def parse_study(text: str, source: str = "study file") -> Study:
    """Parse and validate study TOML; raise StudyError listing every problem with its line and field."""
    return validated(
        Study,
        load_toml(text, source, StudyError),
        text,
        source,
        checks=_reference_problems,
        error=StudyError,
        unknown_key="unknown key (check the spelling; see docs/survey.md for the keys a study file takes)",
        tidy=_loc_without_union_tags,
    )


def load_study(path: str | Path) -> Study:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise StudyError(f"cannot read study file {path}: {error.strerror}") from None
    return parse_study(text, source=str(path))
