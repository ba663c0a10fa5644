"""The screens of a participant's plan, one model per kind, told apart by `kind`.

A plan is stored as JSON (app.store.models.ParticipantPlan): `parse_plan` reads it through the union, `dump_plan` writes
it. Only the fields that were set are written, in the order declared here, so a plan reads and writes as the same
JSON, and plans stored before a field existed (`position`, `round_start`, a ranking's clips) still read. The fields
a screen sets last, its `progress` line and its `position` in the plan, come last in every kind.
"""

from __future__ import annotations

from functools import cached_property
from typing import Annotated, Literal, TypeGuard

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter


class _Stored(BaseModel):
    model_config = ConfigDict(extra="forbid")


class _Screen(_Stored):
    @cached_property
    def text(self) -> str:
        """The screen as text, made once: the page cache's key (a screen read from a stored plan never changes)."""
        return repr(self)


class Robot(_Stored):
    """An answer option: the label the page shows and the real agent behind it, which never leaves the server."""

    label: str
    agent: str


class Shape(_Stored):
    """A clip's playing time (ms) and picture size, from its file; not set for a bundle without its files."""

    clip_ms: int | None = None
    width: int | None = None
    height: int | None = None


class Instructions(_Screen):
    """The instructions and comprehension questions, always the first screen."""

    kind: Literal["instructions"]
    progress: str = ""
    position: tuple[int, int] | None = None  # (index in the plan, number of screens)


class _ClipScreen(_Screen):
    kind: Literal["pairwise", "watch"]
    part: int
    clip: str
    media: str  # the clip file's sha256: its address
    scheme: str
    scenario: str
    robots: list[Robot]  # in the order the robots are offered as answers
    better: str
    questions: list[str]
    clip_ms: int | None = None
    width: int | None = None
    height: int | None = None


class Pairwise(_ClipScreen):
    """A clip of two robots and the part's questions about it."""

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


class Ranking(_Screen):
    """The ranking of a round's robots, after its clips (`clips`, `media_list`, `shapes`, in the order shown)."""

    kind: Literal["ranking"]
    part: int
    block: int
    scheme: str
    scenario: str
    clips: list[str]
    media_list: list[str] = []
    shapes: list[Shape] = []
    robots: list[Robot]
    true_order: list[str] | None  # best to worst; None when the clips do not give a strict order
    questions: list[str]
    progress: str = ""
    position: tuple[int, int] | None = None


class Attention(_Screen):
    """Attention check number `check` of the study file; with a clip, a video attention check."""

    kind: Literal["attention"]
    part: int
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


class Closing(_Screen):
    """The closing questions and feedback box, after the last part."""

    kind: Literal["closing"]
    questions: list[str]
    feedback: bool
    progress: str = ""
    position: tuple[int, int] | None = None


Screen = Annotated[Instructions | Pairwise | Watch | Ranking | Attention | Closing, Field(discriminator="kind")]
Asking = Pairwise | Watch | Ranking | Closing  # screens with the study file's questions (a watch screen: none)
InPart = Pairwise | Watch | Ranking | Attention
WithRobots = Pairwise | Watch | Ranking
Round = Watch | Ranking  # screens of a ranking round (`block`)
PLAN: TypeAdapter[list[Screen]] = TypeAdapter(list[Screen])


def shows_clip(screen: Screen) -> TypeGuard[Pairwise | Watch | Attention]:
    """Whether the screen shows a clip that must be watched before it is answered."""
    return isinstance(screen, Pairwise | Watch) or (isinstance(screen, Attention) and screen.media is not None)


def parse_plan(stored: list) -> list[Screen]:
    """A stored plan as typed screens; a stored plan that is not one is a clear ValidationError."""
    return PLAN.validate_python(stored)


def dump_plan(plan: list[Screen]) -> list[dict]:
    """A plan as stored: the fields each screen set, in the order declared."""
    return PLAN.dump_python(plan, mode="json", exclude_unset=True)
