"""A submitted screen: its form checked on the server, then saved with the participant's next step, all in one
transaction. Nothing is saved unless every field is valid, and every answer is committed before the server replies.

`save_answer` returns what came of it (`Outcome`, or `Refused` with the errors); the page turns that into its reply.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import Enum
from typing import Any

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session
from starlette.datastructures import FormData

from app.store import queries
from app.store.database import Database, as_utc
from app.survey.screens import Asked, Screen, parse_plan, watching_ms
from app.survey.study import Study, digits

# Clip events the page records: playback, seeks (`seek`: allowed, after a first full viewing; `seek_blocked`: a
# seek forward on a first viewing, undone), playback rate changes (`ratechange`, its value in `v`), the tab being
# hidden or shown again, and `reload` (the page was reloaded; the events before it come from the earlier load). On
# a screen of reels each reel's events carry its place on the screen, `reel` (0, 1, ...).
VIDEO_EVENT_TYPES = {
    "play",
    "pause",
    "ended",
    "error",
    "stalled",
    "waiting",
    "seeking",
    "loaded",
    "timeout",
    "seek",
    "seek_blocked",
    "ratechange",
    "hidden",
    "visible",
    "reload",
}
MAX_VIDEO_EVENTS = 500
MAX_REELS = 8  # a place `reel` beyond this is no reel of any screen: left out of the record


VIEWPORT = re.compile(r"^[0-9]{2,5}x[0-9]{2,5}$")
# How much sooner than the clip's playing time (since the screen became current, by the server's clock) its
# answers are still accepted: clock granularity and the browser's own rounding, not a way to skip.
VIEW_TOLERANCE_MS = 1000


@dataclass
class Checked:
    answers: dict[str, Any] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)  # form field -> message shown next to it
    video_events: list[dict[str, Any]] = field(default_factory=list)
    client_ms: int | None = None
    viewport: str | None = None  # the browser window's size, WIDTHxHEIGHT, when it sent one that reads as such

    @property
    def plays(self) -> int:
        return sum(1 for event in self.video_events if event["type"] == "play")


def _one(form: FormData, name: str) -> str | None:
    """The field's value; None when it is missing, repeated or a file."""
    values = form.getlist(name)
    return values[0] if len(values) == 1 and isinstance(values[0], str) else None


def _unanswered(form: FormData, name: str) -> bool:
    """Whether an optional field was left empty (missing, or only whitespace): then nothing is stored for it."""
    values = form.getlist(name)
    return not values or (len(values) == 1 and isinstance(values[0], str) and not values[0].strip())


def _check_field(asked: Asked, labels: list[str], form: FormData, out: Checked) -> None:
    """One form field checked against its question: its answer into `out.answers`, or why not into `out.errors`."""
    answer, error = asked.question.check(asked.name, lambda name: _one(form, name), labels)
    if error is None:
        out.answers[asked.name] = answer
    else:
        out.errors[asked.name] = error


def _video_events(raw: str | None) -> list[dict[str, Any]] | None:
    """The browser's log of clip events, as [{"type": "play", "t": ms}, ...]; None when malformed."""
    if not raw:
        return []
    try:
        events = json.loads(raw)
    except (ValueError, RecursionError):  # RecursionError: nested deeper than the parser's limit
        return None
    if not isinstance(events, list) or len(events) > MAX_VIDEO_EVENTS:
        return None
    clean: list[dict[str, Any]] = []
    for event in events:
        if not isinstance(event, dict) or event.get("type") not in VIDEO_EVENT_TYPES:
            return None
        t = event.get("t")
        if not isinstance(t, int | float) or isinstance(t, bool) or not 0 <= t < 1e9:
            return None
        item: dict[str, Any] = {"type": event["type"], "t": int(t)}
        v = event.get("v")
        if isinstance(v, int | float) and not isinstance(v, bool) and -1e6 < v < 1e6:
            item["v"] = round(float(v), 3)
        reel = event.get("reel")
        if isinstance(reel, int) and not isinstance(reel, bool) and 0 <= reel < MAX_REELS:
            item["reel"] = reel
        clean.append(item)
    return clean


def _ends(events: list[dict[str, Any]], clips: int) -> Iterator[tuple[int, int | None, int, int | None]]:
    """Each `ended` of the screen's clips in the record: its index, its clip (None: the screen's one clip; else its
    `reel`), its stamp, and the earliest stamp of a `play` of that clip before it in the record (None: none).
    Stamps are the page's milliseconds since it loaded: they start again at a reload, so the earliest play, not the
    last, is what an honest end comes after."""
    first_play: dict[int | None, int] = {}
    for at, event in enumerate(events):
        clip = None if clips == 1 else event.get("reel")
        if event["type"] == "play":
            first_play[clip] = min(event["t"], first_play.get(clip, event["t"]))
        elif event["type"] == "ended":
            yield at, clip, event["t"], first_play.get(clip)


def full_view_at(events: list[dict[str, Any]], clips: int) -> int | None:
    """The index of the event by which the record shows every clip of the screen played to its end: its one clip
    (a `play`, then an `ended`), or each of its reels (a `play`, then an `ended`, of every `reel`); None when it
    shows none such. An `ended` counts only after a `play` of its clip, in the record and by the page's stamps (see
    `ended_before_played`): a page cannot end a clip it never started."""
    ended: set[int | None] = set()
    wanted = {None} if clips == 1 else set(range(clips))
    for at, clip, stamp, played in _ends(events, clips):
        if played is not None and played <= stamp:
            ended.add(clip)
            if wanted <= ended:
                return at
    return None


def ended_before_played(events: list[dict[str, Any]], clips: int) -> bool:
    """Whether the record ends a clip before it played: an `ended` stamped earlier than every `play` of its clip
    before it in the record, which no page writes (its play and its end come in one load of the page, in order)."""
    return any(played is not None and stamp < played for _, _, stamp, played in _ends(events, clips))


def clips_played(events: list[dict[str, Any]], clips: int) -> int:
    """How many of the screen's clips (its one clip, or its reels) the record shows played at least once."""
    reels = {e.get("reel") for e in events if e["type"] == "play"}
    return min(len(reels), 1) if clips == 1 else len(reels & set(range(clips)))


def check_screen(study: Study, screen: Screen, form: FormData) -> Checked:
    """The submitted form of `screen`: its answers, or the errors to show next to its fields."""
    out = Checked()
    labels = [option.label for option in screen.offered()]
    for asked in screen.asks(study):
        if not asked.required and _unanswered(form, asked.name):
            continue  # an optional answer left empty: nothing is stored for it
        _check_field(asked, labels, form, out)
    events = _video_events(_one(form, "video_events"))
    if events is None:
        out.errors["video"] = "The page sent a malformed record of the clip's playback; reload the page."
    elif (
        (clips := len(screen.clips_to_watch()))
        and study.study.require_full_view
        and full_view_at(events, clips) is None
    ):
        out.errors["video"] = (
            "Please watch the clip to the end before going on."
            if clips == 1
            else "Please watch each clip to the end before going on."
        )
    out.video_events = events or []
    client_ms = _one(form, "time_on_page_ms") or ""
    out.client_ms = int(client_ms) if digits(client_ms) and len(client_ms) < 10 else None
    viewport = form.get("viewport")
    out.viewport = viewport if isinstance(viewport, str) and VIEWPORT.match(viewport) else None
    return out


def viewing_problem(screen: Screen, started_at: datetime, now: datetime) -> str | None:
    """Why the server cannot accept a clip's answers yet: the screen has not been open as long as its clip plays
    (its reels, one after the other: `watching_ms`), by the server's own clock since the screen became current, so
    the clip cannot have been watched."""
    clip_ms = watching_ms(screen)
    if not clip_ms:
        return None
    open_ms = (now - as_utc(started_at)).total_seconds() * 1000
    if open_ms + VIEW_TOLERANCE_MS >= clip_ms:
        return None
    if len(screen.clips_to_watch()) == 1:
        plays, watch = f"The clip plays for {clip_ms / 1000:.0f} seconds", "play the clip from the start to the end"
    else:
        plays, watch = f"The clips play for {clip_ms / 1000:.0f} seconds together", "play each clip"
    return (
        f"{plays}, but this page has been open for only {open_ms / 1000:.0f} seconds, so it cannot have been "
        f"watched to the end at normal speed. Nothing was saved. Please {watch} from the start to the end, then "
        "answer again."
    )


class Outcome(Enum):
    """What came of a submission that was not refused."""

    SAVED = "saved"  # saved; or nothing was left to save (the participant finished, left, or resent the same)
    KEPT = "kept"  # the screen had been answered before with other answers: the first are kept
    NOT_OPEN = "not open"  # a screen after the participant's current one
    UNKNOWN = "unknown"  # no participant with the session's code


@dataclass(frozen=True)
class Refused:
    """Nothing was saved: the screen is shown again with why (`checked.errors`)."""

    screen: Screen
    checked: Checked


def current_with_plan(
    session: Session, study: Study, code: object
) -> tuple[queries.Record | None, list[Screen] | None]:
    """The participant with this session code and their screens (None before a condition is assigned)."""
    participant = queries.participant_with_plan(session, study.study.id, code) if isinstance(code, str) else None
    if participant is None or participant.plan is None:
        return participant, None
    return participant, parse_plan(participant.plan)


def save_answer(
    db: Database, study: Study, code: object, step: int, form: FormData, *, fast_link: bool
) -> Outcome | Refused:
    """Save the answers to screen `step` of the participant with session code `code`, and make the next screen
    current. `fast_link`: the session came from the researchers' pilot link, which may skip the viewing rule."""
    try:
        return _save_once(db, study, code, step, form, fast_link)
    except IntegrityError:
        # A concurrent submission saved this screen first (PostgreSQL; SQLite's writers take turns): this one is
        # now a resubmit, answered as one.
        return _save_once(db, study, code, step, form, fast_link)


def _save_once(
    db: Database, study: Study, code: object, step: int, form: FormData, fast_link: bool
) -> Outcome | Refused:
    with db.writing() as session:
        participant, plan = current_with_plan(session, study, code)
        if participant is None:
            return Outcome.UNKNOWN
        if participant.status != "started" or plan is None:
            return Outcome.SAVED
        if step < participant.step:  # already answered: a double click or the back button; keep the first
            saved = queries.saved_answers(session, participant.id, step)
            sent = check_screen(study, plan[step], form)
            return Outcome.KEPT if saved is not None and not sent.errors and sent.answers != saved else Outcome.SAVED
        if step > participant.step:
            return Outcome.NOT_OPEN
        screen = plan[step]
        checked = check_screen(study, screen, form)
        now = datetime.now(UTC)
        fast = fast_link and participant.kind in ("pilot", "bot")
        if screen.clips_to_watch() and study.study.require_full_view and not fast and "video" not in checked.errors:
            problem = viewing_problem(screen, participant.step_started_at, now)
            if problem:
                checked.errors["video"] = problem
        if checked.errors:
            if any(name.startswith("understand") for name in checked.errors):
                queries.count_comprehension_attempt(session, participant.id)
            return Refused(screen, checked)
        if screen.counts_comprehension(study):
            queries.count_comprehension_attempt(session, participant.id)
        queries.save_response(
            session,
            {
                "participant_id": participant.id,
                "step": step,
                "kind": screen.kind,
                "answers": checked.answers,
                "video_events": checked.video_events,
                "plays": checked.plays,
                "client_ms": checked.client_ms,
                "server_ms": int((now - as_utc(participant.step_started_at)).total_seconds() * 1000),
                "submitted_at": now,
                "details": {"viewport": checked.viewport} if checked.viewport else None,
            },
        )
        failed = screen.failed_check(checked.answers)
        queries.next_step(session, participant.id, step + 1, now, failed=failed, done=step + 1 == len(plan))
    return Outcome.SAVED
