"""Server-side validation of a submitted screen. Nothing is saved unless every field is valid."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from starlette.datastructures import FormData

from app.survey.screens import Asking, Attention, Closing, Instructions, Screen, WithRobots, shows_clip
from app.survey.study import FEEDBACK, ChoiceQuestion, ChooseQuestion, RankQuestion, ScaleQuestion, Study, TextQuestion

# Clip events the page records: playback, seeks (`seek`: allowed, after a first full viewing; `seek_blocked`: a
# seek forward on a first viewing, undone), playback rate changes (`ratechange`, its value in `v`), the tab being
# hidden or shown again, and `reload` (the page was reloaded; the events before it come from the earlier load).
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


@dataclass
class Checked:
    answers: dict = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)  # form field -> message shown next to it
    video_events: list[dict] = field(default_factory=list)
    client_ms: int | None = None

    @property
    def plays(self) -> int:
        return sum(1 for event in self.video_events if event["type"] == "play")


def digits(value: str) -> bool:
    """Whether `value` is a whole number in ASCII digits: str.isdigit alone also takes '²', which int() refuses."""
    return value.isascii() and value.isdigit()


def _one(form: FormData, name: str) -> str | None:
    """The field's value; None when it is missing, repeated or a file."""
    values = form.getlist(name)
    return values[0] if len(values) == 1 and isinstance(values[0], str) else None


def _unanswered(form: FormData, name: str) -> bool:
    """Whether an optional field was left empty (missing, or only whitespace): then nothing is stored for it."""
    values = form.getlist(name)
    return not values or (len(values) == 1 and isinstance(values[0], str) and not values[0].strip())


def _check_question(name: str, question, screen: Screen, form: FormData, out: Checked) -> None:
    labels = [robot.label for robot in screen.robots] if isinstance(screen, WithRobots) else []
    if isinstance(question, ChoiceQuestion):
        value = _one(form, name)
        if value not in question.options:
            out.errors[name] = "Choose one of the answers."
        else:
            out.answers[name] = value
    elif isinstance(question, ChooseQuestion):
        value = _one(form, name)
        if value not in labels:
            out.errors[name] = "Choose one of the robots." if not value else "That robot is not in this clip."
        else:
            out.answers[name] = value
    elif isinstance(question, TextQuestion):
        value = _one(form, name) or ""
        if len(value.strip()) < question.min_length:
            out.errors[name] = (
                "Please write an answer."
                if question.min_length == 1
                else (f"Please write at least {question.min_length} characters.")
            )
        elif len(value) > question.max_length:
            out.errors[name] = f"Please keep this under {question.max_length} characters (you wrote {len(value)})."
        else:
            out.answers[name] = value
    elif isinstance(question, ScaleQuestion):
        value = _one(form, name)
        if not value:
            out.errors[name] = "Choose one point on the scale."
        elif not digits(value) or not 1 <= int(value) <= question.points:
            out.errors[name] = f"The answer must be a whole number from 1 to {question.points}."
        else:
            out.answers[name] = int(value)
    elif isinstance(question, RankQuestion):
        ranking = [_one(form, f"{name}-{place}") for place in range(1, len(labels) + 1)]
        if any(not value for value in ranking):
            out.errors[name] = "Put a robot in every place of the ranking."
        elif any(value not in labels for value in ranking):
            out.errors[name] = "The ranking names a robot that is not in this study."
        elif len(set(ranking)) != len(ranking):
            out.errors[name] = "Each robot can take only one place: the ranking has a robot twice."
        else:
            out.answers[name] = ranking


def _video_events(raw: str | None) -> list[dict] | None:
    """The browser's log of clip events, as [{"type": "play", "t": ms}, ...]; None when malformed."""
    if not raw:
        return []
    try:
        events = json.loads(raw)
    except (ValueError, RecursionError):  # RecursionError: nested deeper than the parser's limit
        return None
    if not isinstance(events, list) or len(events) > MAX_VIDEO_EVENTS:
        return None
    clean = []
    for event in events:
        if not isinstance(event, dict) or event.get("type") not in VIDEO_EVENT_TYPES:
            return None
        t = event.get("t")
        if not isinstance(t, int | float) or isinstance(t, bool) or not 0 <= t < 1e9:
            return None
        item = {"type": event["type"], "t": int(t)}
        v = event.get("v")
        if isinstance(v, int | float) and not isinstance(v, bool) and -1e6 < v < 1e6:
            item["v"] = round(float(v), 3)
        clean.append(item)
    return clean


def check_screen(study: Study, screen: Screen, form: FormData) -> Checked:
    out = Checked()
    required = study.closing.required if isinstance(screen, Closing) and study.closing else None
    for name in screen.questions if isinstance(screen, Asking) else []:
        if required is not None and name not in required and _unanswered(form, name):
            continue  # a closing question left unanswered: allowed unless the study requires it
        _check_question(name, study.questions[name], screen, form, out)
    if (
        isinstance(screen, Closing)
        and screen.feedback
        and not (FEEDBACK not in (required or []) and _unanswered(form, FEEDBACK))
    ):
        _check_question(FEEDBACK, TextQuestion(type="text", text="feedback"), screen, form, out)
    if isinstance(screen, Instructions):
        for number, check in enumerate(study.comprehension, start=1):
            value = _one(form, f"understand{number}")
            if value not in check.options:
                out.errors[f"understand{number}"] = "Choose one of the answers."
            elif value != check.expected:
                out.errors[f"understand{number}"] = (
                    "That is not right. Read the instructions above again, then choose another answer."
                )
            else:
                out.answers[f"understand{number}"] = value
    if isinstance(screen, Attention):
        value = _one(form, "attention")
        if value not in screen.options:
            out.errors["attention"] = "Choose one of the answers."
        else:
            out.answers["attention"] = value
    events = _video_events(_one(form, "video_events"))
    if events is None:
        out.errors["video"] = "The page sent a malformed record of the clip's playback; reload the page."
    elif shows_clip(screen) and study.study.require_full_view and not any(e["type"] == "ended" for e in events):
        out.errors["video"] = "Please watch the clip to the end before going on."
    out.video_events = events or []
    client_ms = _one(form, "time_on_page_ms") or ""
    out.client_ms = int(client_ms) if digits(client_ms) and len(client_ms) < 10 else None
    return out
