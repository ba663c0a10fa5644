"""The screens of a participant's plan, one model per kind, told apart by `kind`; each kind's behaviour is on its
model: the answers its form asks for, the clips to watch first, what its page shows and how the admin pages name it.

A plan is stored as JSON (app.store.models.ParticipantPlan): `parse_plan` reads it through the union, `dump_plan` writes
it. Only the fields that were set are written, in the order declared here, so a plan reads and writes as the same
JSON, and plans stored before a field existed (`position`, `round_start`, a ranking's clips) still read. The fields
a screen sets last, its `progress` line and its `position` in the plan, come last in every kind.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Annotated, Any, ClassVar, Literal, NamedTuple, TypeGuard

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

from app.formats import ManifestReel, load_summary
from app.survey.bundle import Bundle
from app.survey.clip_length import clip_shape
from app.survey.study import FEEDBACK, CheckedAnswer, FieldReader, Question, Study, TextQuestion, check_option
from app.visible import VisibleClip, VisibleReels


@dataclass(frozen=True)
class OneOf:
    """A form field answered with one of `options`; with `expected`, only that one is right (and saved)."""

    options: list[str]
    expected: str | None = None

    def check(self, name: str, read: FieldReader, labels: list[str]) -> CheckedAnswer:
        value = read(name)
        if value in self.options and self.expected is not None and value != self.expected:
            return None, "That is not right. Read the instructions above again, then choose another answer."
        return check_option(self.options, value)


class Asked(NamedTuple):
    """A form field a screen asks for: its name, the question it answers, and whether it may be left empty."""

    name: str
    question: Question | OneOf
    required: bool = True


class _Stored(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Option(_Stored):
    """An answer option: the label the page shows and the real agent behind it, which never leaves the server."""

    label: str
    agent: str


class Shape(_Stored):
    """A clip's playing time (ms) and picture size, from its file; not set for a bundle without its files."""

    clip_ms: int | None = None
    width: int | None = None
    height: int | None = None


class Clip(NamedTuple):
    """A clip a screen shows: its file's sha256 (its address) and its shape."""

    media: str
    shape: Shape


class Reel(_Stored):
    """One agent's reel on a screen of reels (each agent on its own): its label, its file's sha256 and shape."""

    label: str
    media: str
    clip_ms: int | None = None
    width: int | None = None
    height: int | None = None

    def clip(self) -> Clip:
        return Clip(self.media, Shape(clip_ms=self.clip_ms, width=self.width, height=self.height))


def clip_view(clip: Clip) -> dict[str, Any]:
    """A clip's address and box as a page shows it."""
    return {
        "url": f"/clips/{clip.media}.mp4",
        "width": clip.shape.width or 720,
        "height": clip.shape.height or 880,
        "seconds": round((clip.shape.clip_ms or 0) / 1000, 1),
    }


def _showing(clip: Clip) -> dict[str, Any]:
    """The page's entries for the clip it shows above the questions."""
    view = clip_view(clip)
    return {"clip": view, "clip_url": view["url"]}


class _Screen(_Stored):
    """What every kind of screen does, unless its model says otherwise."""

    kind: str  # each kind narrows it to its own name, the union's discriminator
    template: ClassVar[str] = "screen.html"  # the page's template

    @cached_property
    def text(self) -> str:
        """The screen as text, made once: the page cache's key (a screen read from a stored plan never changes)."""
        return repr(self)

    def offered(self) -> list[Option]:
        """The agents the screen offers as answers, in order."""
        return []

    def question_names(self) -> list[str]:
        """The study file's questions on the screen, by name."""
        return []

    def asks(self, study: Study) -> list[Asked]:
        """The form fields a submission must hold, in the order they are checked and saved."""
        return [Asked(name, study.questions[name]) for name in self.question_names()]

    def clips_to_watch(self) -> list[Clip]:
        """The clips that must be played to their end before the screen is answered: none, its clip, or its reels."""
        return []

    def clip_names(self) -> list[str]:
        """The ids of the clips the screen is about (a ranking's: its round's clips), as the bundle names them."""
        return []

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        """The page's entries that only this kind has (`page_view` writes the ones every kind has)."""
        return {}

    def failed_check(self, answers: dict[str, Any]) -> bool:
        """Whether these saved answers fail an attention check."""
        return False

    def counts_comprehension(self, study: Study) -> bool:
        """Whether a valid submission is an attempt at the comprehension questions (counted per participant)."""
        return False


class Instructions(_Screen):
    """The instructions and comprehension questions, always the first screen."""

    kind: Literal["instructions"]
    progress: str = ""
    position: tuple[int, int] | None = None  # (index in the plan, number of screens)
    template: ClassVar[str] = "instructions.html"

    def asks(self, study: Study) -> list[Asked]:
        return [
            Asked(f"understand{number}", OneOf(check.options, check.expected))
            for number, check in enumerate(study.comprehension, start=1)
        ]

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        if study.example is None:
            return {}
        example = bundle.matching(study.example.scheme, study.example.scenario, study.example.agents)[0]
        sha = example.sha256.lower()
        shape = clip_shape(bundle.paths[sha])
        return _showing(Clip(sha, Shape(clip_ms=shape.ms, width=shape.width, height=shape.height)))

    def counts_comprehension(self, study: Study) -> bool:
        return bool(study.comprehension)

    def admin_name(self) -> str:
        return "Instructions"


class _InPart(_Screen):
    """A screen of one of the study's parts."""

    part: int

    def admin_name(self) -> str:
        """The screen's name on the admin pages when it has no `progress` line (plans stored before it existed)."""
        return f"Part {self.part}, {self.kind}"

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        part = study.parts[self.part - 1]
        return {"part_title": part.title, "part_intro": part.intro, "part_kind": part.kind}


class _ClipScreen(_InPart):
    """A screen of one clip of two agents: a video of both (`media`), or a pair of reels, one per agent (`reels`)."""

    kind: Literal["pairwise", "watch"]
    clip: str
    media: str = ""  # the clip file's sha256: its address; empty for a pair of reels
    scheme: str
    scenario: str
    robots: list[Option]  # in the order the agents are offered as answers
    better: str
    questions: list[str]
    clip_ms: int | None = None
    width: int | None = None
    height: int | None = None
    reels: list[Reel] = []  # in the order shown
    # an update pair of the study's design: its later version, and whether the two are equal (the ground truth
    # cannot tell them apart, or the study holds them to be a control); set only on update pairs
    later: str | None = None
    equal: bool | None = None

    def offered(self) -> list[Option]:
        return self.robots

    def update(self) -> str | None:
        """What the ground truth says of the update this screen shows: "better", "worse" or "equal"; None when it
        shows no update pair."""
        if self.later is None:
            return None
        return "equal" if self.equal else "better" if self.better == self.later else "worse"

    def question_names(self) -> list[str]:
        return self.questions

    def clip_names(self) -> list[str]:
        return [self.clip]

    def clips_to_watch(self) -> list[Clip]:
        if self.reels:
            return [reel.clip() for reel in self.reels]
        return [Clip(self.media, Shape(clip_ms=self.clip_ms, width=self.width, height=self.height))]

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        view = super().page(study, bundle)
        if self.reels:
            return view | {"reels": [clip_view(reel.clip()) | {"label": reel.label} for reel in self.reels]}
        return view | _showing(self.clips_to_watch()[0])


class Pairwise(_ClipScreen):
    """A clip of two agents and the part's questions about it."""

    kind: Literal["pairwise"]
    progress: str = ""
    position: tuple[int, int] | None = None


class Watch(_ClipScreen):
    """A clip of a ranking round, watched without questions; the round's ranking screen follows its clips."""

    kind: Literal["watch"]
    block: int
    round_start: bool = False
    progress: str = ""
    position: tuple[int, int] | None = None

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        return super().page(study, bundle) | {"block": self.block, "round_start": self.round_start}


class Ranking(_InPart):
    """The ranking of a round's agents, after its clips (`clips`, `media_list`, `shapes`, in the order shown)."""

    kind: Literal["ranking"]
    block: int
    scheme: str
    scenario: str
    clips: list[str]
    media_list: list[str] = []
    shapes: list[Shape] = []
    robots: list[Option]
    true_order: list[str] | None  # best to worst; None when the clips do not give a strict order
    questions: list[str]
    progress: str = ""
    position: tuple[int, int] | None = None

    def offered(self) -> list[Option]:
        return self.robots

    def question_names(self) -> list[str]:
        return self.questions

    def clip_names(self) -> list[str]:
        return self.clips

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        view = super().page(study, bundle) | {"block": self.block}
        if self.media_list:
            shapes = self.shapes or [Shape()] * len(self.media_list)
            view["round_clips"] = [
                clip_view(Clip(sha, shape)) | {"outcomes": _outcomes(bundle, sha)}
                for sha, shape in zip(self.media_list, shapes, strict=True)
            ]
            view["round_reels"] = any(reel.sha256.lower() in self.media_list for reel in _reels(bundle))
        return view


class Attention(_InPart):
    """Attention check number `check` of the study file; with a clip, a video attention check."""

    kind: Literal["attention"]
    check: int
    options: list[str]
    expected: str
    clip: str | None = None
    media: str | None = None
    clip_ms: int | None = None
    width: int | None = None
    height: int | None = None
    progress: str = ""
    position: tuple[int, int] | None = None

    def asks(self, study: Study) -> list[Asked]:
        return [Asked("attention", OneOf(self.options))]  # any option is saved; a wrong one is a failed check

    def clip_names(self) -> list[str]:
        return [] if self.clip is None else [self.clip]

    def clips_to_watch(self) -> list[Clip]:
        if self.media is None:
            return []
        return [Clip(self.media, Shape(clip_ms=self.clip_ms, width=self.width, height=self.height))]

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        view = super().page(study, bundle)
        for clip in self.clips_to_watch():
            view |= _showing(clip)
        return view | {"attention_text": study.attention_checks[self.check].text, "options": self.options}

    def failed_check(self, answers: dict[str, Any]) -> bool:
        return bool(answers["attention"] != self.expected)


class Closing(_Screen):
    """The closing questions and feedback box, after the last part."""

    kind: Literal["closing"]
    questions: list[str]
    feedback: bool
    progress: str = ""
    position: tuple[int, int] | None = None

    def question_names(self) -> list[str]:
        return self.questions

    def admin_name(self) -> str:
        return "Closing questions"

    def asks(self, study: Study) -> list[Asked]:
        """Every closing question may be left empty unless the study file requires it; all are required when the
        study file no longer has a closing table. The feedback box is optional unless required."""
        required = study.closing.required if study.closing is not None else None
        fields = [Asked(name, study.questions[name], required is None or name in required) for name in self.questions]
        if self.feedback:
            box = TextQuestion(type="text", text="feedback")
            fields.append(Asked(FEEDBACK, box, FEEDBACK in (required or [])))
        return fields

    def page(self, study: Study, bundle: Bundle) -> dict[str, Any]:
        closing = study.closing
        if closing is None:
            return {}
        view: dict[str, Any] = {
            "part_title": closing.title,
            "part_intro": closing.intro,
            "optional": [name for name in closing.asks() if name not in closing.required],
        }
        if self.feedback and closing.feedback:
            view["feedback"] = TextQuestion(type="text", text=closing.feedback, rows=4)
        return view


Screen = Annotated[Instructions | Pairwise | Watch | Ranking | Attention | Closing, Field(discriminator="kind")]
InPart = Pairwise | Watch | Ranking | Attention
WithOptions = Pairwise | Watch | Ranking
Round = Watch | Ranking  # screens of a ranking round (`block`)
PLAN: TypeAdapter[list[Screen]] = TypeAdapter(list[Screen])


def shows_clip(screen: Screen | None) -> TypeGuard[Pairwise | Watch | Attention]:
    """Whether the screen shows a clip that must be watched before it is answered."""
    return screen is not None and bool(screen.clips_to_watch())


def watching_ms(screen: Screen) -> int | None:
    """How long the screen must have been open before its answers are taken, in ms (None when a clip's playing
    time is unknown): its clip's playing time; on a screen of reels, the reels' playing times added up. That is the
    ranking part's rule for several clips: a round's clips are watched one after another, each on its own screen
    held for its playing time, so the round holds the participant for their sum; the page plays one reel at a time
    (starting one pauses the other), so a screen of reels is held for its reels' sum likewise."""
    times = [clip.shape.clip_ms for clip in screen.clips_to_watch()]
    known = [ms for ms in times if ms]
    return sum(known) if times and len(known) == len(times) else None


def page_view(screen: Screen, study: Study, bundle: Bundle) -> dict[str, Any]:
    """What a page may know about a screen: labels and the clip's address, never agent names or ground truth."""
    view = {
        "kind": screen.kind,
        "progress": screen.progress,
        "position": screen.position,
        "labels": [option.label for option in screen.offered()],
        "questions": [(name, study.questions[name]) for name in screen.question_names()],
        "block": None,
        "round_start": False,
        "optional": [],
    }
    return view | screen.page(study, bundle)


def _reels(bundle: Bundle) -> list[ManifestReel]:
    return [reel for clip in bundle.clips.values() for reel in clip.reels]


def _outcomes(bundle: Bundle, sha: str) -> list[str]:
    """How each agent of a clip visibly ends, by its label in the words of the bundle's world (what the clip itself
    shows, from its summary.json; nothing when the bundle has none): written beside a ranking round's clips."""
    clip = next((clip for clip in bundle.clips.values() if clip.sha256.lower() == sha), None)
    reel = next((reel for reel in _reels(bundle) if reel.sha256.lower() == sha), None)
    try:
        if reel is not None:  # one agent's reel: how it ended in each of its moments, a line each
            owner = next(c for c in bundle.clips.values() if reel in c.reels)
            label = owner.labels[owner.agents.index(reel.agent)]
            segments = [load_summary(bundle.root / path) for path in reel.summaries]
            return VisibleReels.of_summaries([segments], [label], bundle.world).moments(label)
        if clip is None or not clip.summary:
            return []
        summary = load_summary(bundle.root / clip.summary)
        shown = VisibleClip.of_summary(summary, clip.agents, clip.labels, bundle.world)
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        return []
    return [shown.describe(label) for label in clip.labels]


def parse_plan(stored: list[Any]) -> list[Screen]:
    """A stored plan as typed screens; a stored plan that is not one is a clear ValidationError."""
    return PLAN.validate_python(stored)


def dump_plan(plan: list[Screen]) -> list[dict[str, Any]]:
    """A plan as stored: the fields each screen set, in the order declared."""
    stored: list[dict[str, Any]] = PLAN.dump_python(plan, mode="json", exclude_unset=True)
    return stored
