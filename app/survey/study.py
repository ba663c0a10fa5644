"""The study definition: a TOML file validated with pydantic, with errors that name the line and the field.

The file says what participants see (texts, parts, questions), how they are assigned (design), where they come from
(platform) and where they go at the end (completion). A top-level `[build]` table says which clips `foil bundle`
searches for and renders; it is checked here too, so the server and the bundle builder report a bad line alike.
"""

from __future__ import annotations

import itertools
import re
import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)


class StudyError(ValueError):
    """A study file that cannot be used; the message names the file, line and field."""


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


Text = Annotated[str, Field(min_length=1)]


def _distinct(values: list) -> list:
    if len(set(values)) != len(values):
        raise ValueError("names must not repeat")
    return values


def _two_different(pair: tuple[str, str]) -> tuple[str, str]:
    if pair[0] == pair[1]:
        raise ValueError("a pair needs two different agents")
    return pair


Names = Annotated[list[Text], Field(min_length=1), AfterValidator(_distinct)]
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
        return self


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
    example_caption: Text = (
        "An example: two robots, each with its own colour, shape and name, walk through a crowd to the same goal."
    )
    robot_names: Text = (
        "Every robot has a name (such as Robot 7), colour and shape of its own. A name never stands "
        "for two different robots in this study, and in a ranking round each name is one robot in "
        "all of the round's clips. Each new round brings robots with new names."
    )
    names_in_round: Text = "In this round each name, colour and shape is one robot in all three clips."
    new_round: Text = (
        "A new round begins. Its robots have names you have not seen in the earlier rounds: judge them "
        "from this round's clips."
    )


class Completion(Strict):
    code: str = ""
    redirect_url: Annotated[str, Field(pattern=r"^(https://\S+)?$")] = ""

    @model_validator(mode="after")
    def _something(self) -> Completion:
        if not self.code and not self.redirect_url:
            raise ValueError("give a completion code, a redirect_url (https://...), or both")
        return self


class ChooseQuestion(Strict):
    """Pick one of the robots shown in the clip."""

    type: Literal["choose"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)


class TextQuestion(Strict):
    type: Literal["text"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)
    min_length: Annotated[int, Field(ge=1)] = 1
    max_length: Annotated[int, Field(ge=1, le=10_000)] = 2000
    rows: Annotated[int, Field(ge=1, le=20)] = 3


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
        low, high = self.anchors
        return [low if i == 1 else high if i == self.points else str(i) for i in range(1, self.points + 1)]


class RankQuestion(Strict):
    """Order every robot of a ranking part from best to worst."""

    type: Literal["rank"]
    text: Text
    help: str = ""  # neutral help text under the question (never an example answer)


class ChoiceQuestion(Strict):
    """One of the researcher's options, such as an age range (a closing question, see `Closing`)."""

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


Question = Annotated[
    ChooseQuestion | TextQuestion | ScaleQuestion | RankQuestion | ChoiceQuestion, Field(discriminator="type")
]

FEEDBACK = "feedback"  # the name of the closing screen's feedback box in the data


class Closing(Strict):
    """An optional last screen after the parts, before the completion page: closing questions (demographics,
    experience with robots) and a free-text feedback box, every answer optional unless named in `required`."""

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
    what it visibly shows (say, whether a robot crashed)."""

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


def _settings(value):
    """A table of key = value settings as `foil search --set` takes them: scalars, no nested tables."""
    if not isinstance(value, dict) or not all(isinstance(v, bool | int | float | str) for v in value.values()):
        raise ValueError("must be a table of key = value settings (numbers, strings, true/false; no nested tables)")
    return value


Settings = Annotated[dict[str, bool | int | float | str], BeforeValidator(_settings)]


def _whole(minimum: int):
    """A whole number >= minimum; strict, so a string or true/false is refused rather than converted."""
    return Annotated[int, Field(ge=minimum, strict=True)]


class BuildEval(Strict):
    """The ground truth: each agent's `foil eval` on these test episodes."""

    episodes: _whole(2) = 500
    seed: _whole(0) = 0


class BuildScheme(Strict):
    """How one scheme's clips are found: a solver of `foil search` with its simulator-step budget, seed and top-K,
    and its solver, reward and world settings (checked against their fields by the bundle builder)."""

    solver: Text  # mcts, nfirst, random, cem, representative
    budget: _whole(1)
    seed: _whole(0)
    top_k: _whole(1) = 1
    select: Literal["reward", "contrast"] = "reward"  # which of the top-K becomes the clip (docs/clips.md)
    settings: Settings = {}
    reward: Settings = {}
    world: Settings = {}


class BuildSet(Strict):
    """Every pair under every scheme on every scenario, feeding the survey parts named."""

    parts: Annotated[list[Literal["pairwise", "ranking", "example"]], Field(min_length=1), AfterValidator(_distinct)]
    schemes: Names
    scenarios: Names
    agents: Annotated[Names, Field(min_length=2)] | None = None  # every pair of these ...
    pairs: Annotated[list[Pair], Field(min_length=1)] | None = None  # ... or these pairs

    @model_validator(mode="after")
    def _agents_or_pairs(self) -> BuildSet:
        if (self.agents is None) == (self.pairs is None):
            raise ValueError("give either agents = [...] (every pair of them) or pairs = [[a, b], ...]")
        if self.agents is None and "ranking" in self.parts:
            raise ValueError(
                "a set that feeds a ranking part lists its agents (agents = [...]), so each agent "
                "keeps one robot number in all its clips"
            )
        return self

    def clip_pairs(self) -> tuple[tuple[str, str], ...]:
        if self.agents is not None:
            return tuple(itertools.combinations(self.agents, 2))
        return tuple(self.pairs)

    def all_agents(self) -> tuple[str, ...]:
        """Every agent of the set's clips, in the order given."""
        return tuple(dict.fromkeys(a for pair in self.clip_pairs() for a in pair))


class BuildRepresentativeness(Strict):
    """How `foil bundle` measures the study's fixed scenarios against the task's distribution of starting states."""

    distribution: Text = "training"
    states: _whole(1) = 64  # starting states drawn from the distribution
    pushes: _whole(1) = 32  # rollouts per state (and per fixed scenario) under uniform pushes
    seed: _whole(0) = 0


class Build(Strict):
    """The `[build]` table: which clips `foil bundle` searches for and renders (docs/clips.md)."""

    seed: _whole(0)  # seeds which robot number each agent gets in each clip
    eval: BuildEval = BuildEval()
    representativeness: BuildRepresentativeness = BuildRepresentativeness()
    render: Settings = {}  # RenderOptions fields, checked by the renderer
    schemes: Annotated[dict[str, BuildScheme], Field(min_length=1)]
    sets: Annotated[list[BuildSet], Field(min_length=1)]


def _build_problems(build: Build) -> list[tuple[tuple, str]]:
    """Checks across the [build] tables: every scheme a set names is defined, and every clip is listed once."""
    problems = []
    seen: dict[tuple, int] = {}
    for i, clip_set in enumerate(build.sets):
        for j, name in enumerate(clip_set.schemes):
            if name not in build.schemes:
                problems.append(
                    (("build", "sets", i, "schemes", j), f"no scheme {name!r}; defined: {sorted(build.schemes)}")
                )
        for scheme, scenario, pair in itertools.product(clip_set.schemes, clip_set.scenarios, clip_set.clip_pairs()):
            key = (scheme, scenario, frozenset(pair))
            if key in seen:
                problems.append(
                    (
                        ("build", "sets", i),
                        f"the clip of {scheme}, {scenario}, {pair[0]} and {pair[1]} "
                        f"is already in sets[{seen[key]}]; list each clip once, with every part it feeds",
                    )
                )
                break
            seen[key] = i
    return problems


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
    closing: Closing | None = None
    build: Build | None = None  # checked here, used by `foil bundle` alone

    def consent_version(self) -> str:
        """The version of the consent text each participant is recorded with: `[study] consent_version`, or
        `sha256:` and the first 12 hex digits of the consent text's hash (any edit gives a new version)."""
        import hashlib

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
        names = self.design.scheme_scenarios.get(scheme, self.design.scenarios)
        return names[(part_index + rotation) % len(names)]


def _reference_problems(study: Study) -> list[tuple[tuple, str]]:
    """Checks across tables that pydantic's per-field validation cannot see, as (location, message)."""
    problems = []
    for name in study.questions:
        if not re.fullmatch(r"[a-z][a-z0-9_]{0,39}", name):
            problems.append((("questions", name), "question names are lower_snake_case, at most 40 characters"))
    for p, part in enumerate(study.parts):
        allowed = {"pairwise": {"choose", "text", "scale"}, "ranking": {"rank", "text", "scale"}}[part.kind]
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
    for c, check in enumerate(study.attention_checks):
        if check.part > len(study.parts):
            problems.append((("attention_checks", c, "part"), f"there are only {len(study.parts)} parts"))
    if study.build is not None:
        problems += _build_problems(study.build)
    return problems


def _table_path(header: str, arrays: dict[tuple, int], new_element: bool = False) -> tuple:
    """Resolve a dotted header to a path with the current index of every array-of-tables along it; a `[[...]]`
    header (`new_element`) starts the next element of the array it names, so that one gets no index here."""
    names = [name.strip().strip('"') for name in header.split(".")]
    path: tuple = ()
    for i, name in enumerate(names):
        path += (name,)
        if path in arrays and not (new_element and i == len(names) - 1):
            path += (arrays[path],)
    return path


def locate(text: str, loc: tuple) -> int | None:
    """The line of `text` that best matches a pydantic error location (the deepest key or table defining it)."""
    want = tuple(str(x) for x in loc)
    arrays: dict[tuple, int] = {}
    table: tuple = ()
    best, best_depth = None, -1
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if line.startswith("[["):
            names = _table_path(line[2 : line.find("]]")], arrays, new_element=True)
            arrays[names] = arrays.get(names, -1) + 1
            table = names + (arrays[names],)
            path = table
        elif line.startswith("["):
            table = _table_path(line[1 : line.find("]")], arrays)
            path = table
        elif "=" in line and not line.startswith("#"):
            key = line.split("=", 1)[0].strip()
            path = table + tuple(k.strip().strip('"') for k in key.split("."))
        else:
            continue
        path = tuple(str(x) for x in path)
        depth = len(path) if want[: len(path)] == path else len(want) if path[: len(want)] == want else -1
        if depth > best_depth:  # a table only made by its subtables is found at the first of them
            best, best_depth = number, depth
    return best


def _field(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(top level)"


def _loc_without_union_tags(loc: tuple) -> tuple:
    """Pydantic puts the chosen union member (`questions.NAME.scale...`) in the location; the file does not."""
    tags = {"parts": {"pairwise", "ranking"}, "questions": {"choose", "text", "scale", "rank", "choice"}}
    if len(loc) >= 3 and loc[0] in tags and loc[2] in tags[loc[0]]:
        return loc[:2] + loc[3:]
    return loc


def _toml(text: str, source: str) -> dict:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise StudyError(f"{source}: not valid TOML: {error}") from None


def refuse(text: str, source: str, problems: list[tuple[tuple, str]]) -> None:
    """Raise StudyError listing every (location, message) problem with the file, the line and the field."""
    if problems:
        lines = []
        for loc, message in problems:
            line = locate(text, loc)
            lines.append(f"{source}, {f'line {line}' if line else 'no line'}, {_field(loc)}: {message}")
        raise StudyError("\n".join(lines))


def _validated(model: type[Strict], data: dict, text: str, source: str, at: tuple, checks):
    """`data` (the table at location `at` of the file) as `model`, then `checks(value)`'s problems; every problem
    of either refused with its line and field."""
    problems: list[tuple[tuple, str]] = []
    try:
        value = model.model_validate(data)
    except ValidationError as error:
        for item in error.errors():
            loc = _loc_without_union_tags(at + item["loc"])
            message = item["msg"].removeprefix("Value error, ")
            if item["type"] == "extra_forbidden":
                docs = "docs/clips.md" if loc[0] == "build" else "docs/survey.md"
                message = f"unknown key (check the spelling; see {docs} for the keys a study file takes)"
            problems.append((loc, message))
    else:
        problems = checks(value)
    refuse(text, source, problems)
    return value


def parse_study(text: str, source: str = "study file") -> Study:
    """Parse and validate study TOML; raise StudyError listing every problem with its line and field."""
    return _validated(Study, _toml(text, source), text, source, (), _reference_problems)


def parse_build(text: str, source: str = "study file") -> Build:
    """The `[build]` table of study TOML alone, with the same errors as `parse_study`: `foil bundle` may build a
    study whose survey tables are not final yet."""
    data = _toml(text, source)
    if "build" not in data:
        raise StudyError(
            f"{source}: no [build] table: it says which clips to search for and render (see docs/clips.md)"
        )
    return _validated(Build, data["build"], text, source, ("build",), _build_problems)


def load_study(path: str | Path) -> Study:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise StudyError(f"cannot read study file {path}: {error.strerror}") from None
    return parse_study(text, source=str(path))
