"""Which participants the analysis leaves out, and why. The rules are applied the same way by the export (as
flag columns) and by the report (which drops flagged participants and counts them per reason)."""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Row, select

from app.store.database import Database, as_utc
from app.store.models import Participant, Response
from app.survey.answers import (  # the server's own check, applied again
    VIEW_TOLERANCE_MS,
    clips_played,
    ended_before_played,
    full_view_at,
)
from app.survey.screens import Attention, Pairwise, Screen, Watch, shows_clip, watching_ms

REASONS = {
    "pilot_or_bot": "a pilot (preview link) or a bot (`foil simulate`), not a real participant",
    "incomplete": "did not complete the study (started, returned or declined)",
    "failed_attention": "failed at least one attention check",
    "too_fast": "completed faster than the time threshold",
    "flagged_by_admin": "flagged for exclusion on the admin pages",
    "skipped_viewing": (
        "answered a clip sooner than it plays, sped it up before it first ended, never played it, or sent a record "
        "of it that ends before it plays"
    ),
}
# The rules that judge how a person took the study (its time, its clips' viewing): a bot answers as fast as the pilot
# link lets it, so where bots are analysed (a rehearsal of the analysis) these rules are skipped for them.
PEOPLE_ONLY = ("too_fast", "skipped_viewing")
BOTS_NOTE = "timing and viewing rules skipped for bots"


@dataclass(frozen=True)
class ExclusionRules:
    """`min_seconds` is an absolute floor on the completion time; without it the floor is `median_fraction`
    of the median completion time (a third by default, a common rule for speeders). 0 turns the rule off."""

    min_seconds: float | None = None
    median_fraction: float = 1 / 3
    include_kinds: tuple[str, ...] = ()  # "pilot", "bot": analyse them too (left out by default)

    def __post_init__(self) -> None:
        if self.min_seconds is not None and not 0 <= self.min_seconds < math.inf:
            raise ValueError(
                f"the minimum duration must be a finite number of seconds, 0 or more, got {self.min_seconds}"
            )
        if not 0 <= self.median_fraction < 1:
            raise ValueError(f"the fraction of the median duration must be in [0, 1), got {self.median_fraction}")
        unknown = set(self.include_kinds) - {"pilot", "bot"}
        if unknown:
            raise ValueError(f"participant kinds to include are 'pilot' and 'bot', got {sorted(unknown)}")

    @property
    def kinds(self) -> tuple[str, ...]:
        """The participant kinds analysed: real participants, and the kinds included on request."""
        return ("real", *self.include_kinds)

    @property
    def bots_note(self) -> str:
        """What the analysis of bots leaves out (`PEOPLE_ONLY`), where bots are analysed; empty otherwise."""
        return BOTS_NOTE if "bot" in self.include_kinds else ""

    def threshold_s(self, median_s: float | None) -> float | None:
        """The completion time under which a participant counts as too fast; None when the rule is off."""
        if self.min_seconds is not None:
            return self.min_seconds or None
        if median_s is None or self.median_fraction == 0:
            return None
        return self.median_fraction * median_s

    def describe(self, median_s: float | None) -> str:
        threshold = self.threshold_s(median_s)
        if threshold is None:
            return "no time threshold"
        if self.min_seconds is not None:
            return f"completion under {threshold:.1f} s"
        return f"completion under {self.median_fraction:.3g} of the median ({median_s:.1f} s), i.e. {threshold:.1f} s"


def duration_s(participant: Participant | Row[Any]) -> float | None:
    completed_at = participant.completed_at
    if completed_at is None:
        return None
    return (as_utc(completed_at) - as_utc(participant.created_at)).total_seconds()


def median_duration_s(db: Database, study_id: str) -> float | None:
    """Median completion time of the study's completed real participants (pilots and bots, analysed or not,
    would drag the "too fast" threshold down), one float each in memory."""
    query = select(Participant.created_at, Participant.completed_at).where(
        Participant.study == study_id,
        Participant.status == "completed",
        Participant.completed_at.is_not(None),
        Participant.kind == "real",
    )
    with db.reading() as session:
        durations = [
            (as_utc(done) - as_utc(start)).total_seconds() for start, done in session.execute(query) if done is not None
        ]
    return statistics.median(durations) if durations else None


def viewing_problems(response: Response | Row[Any], screen: Pairwise | Watch | Attention) -> dict[str, Any]:
    """How a clip screen was watched, from its response and the plan's screen: the clip's length (a pair of reels:
    theirs together), time on screen (server), plays, seeks, blocked seeks, rate changes, time with the tab hidden;
    `skipped` when the screen was answered sooner than the clip plays (by the server's clock), with playback
    faster than normal before the clip (every reel) first ended, with a clip (a reel) never played, or with a
    record that ends a clip before it played (by the page's stamps, which no page writes: the server refuses it
    where full views are required, but a study that does not, or answers stored before, may hold one)."""
    events = response.video_events or []
    clip_ms = watching_ms(screen)
    hidden_ms, hidden_at = 0, None
    for event in events:
        if event["type"] == "hidden":
            hidden_at = event["t"]
        elif event["type"] in ("visible", "reload") and hidden_at is not None:
            hidden_ms += max(0, event["t"] - hidden_at) if event["type"] == "visible" else 0
            hidden_at = None
    clips = len(screen.clips_to_watch())
    first_end = full_view_at(events, clips)
    before_end = events if first_end is None else events[:first_end]
    sped = any(e["type"] == "ratechange" and e.get("v", 1) > 1.01 for e in before_end)
    too_soon = bool(clip_ms and response.server_ms + VIEW_TOLERANCE_MS < clip_ms)
    unplayed = clips_played(events, clips) < clips or ended_before_played(events, clips)
    skipped = bool(shows_clip(screen) and (sped or too_soon or unplayed))
    return {
        "clip_ms": clip_ms,
        "seeks": sum(e["type"] == "seek" for e in events),
        "seeks_blocked": sum(e["type"] == "seek_blocked" for e in events),
        "rate_changes": sum(e["type"] == "ratechange" for e in events),
        "hidden_ms": hidden_ms,
        "reloads": sum(e["type"] == "reload" for e in events),
        "skipped": skipped,
    }


def exclusion_flags(
    participant: Participant | Row[Any],
    threshold_s: float | None,
    responses: list[Response] | list[Row[Any]] | None = None,
    rules: ExclusionRules | None = None,
    plan: list[Screen] | None = None,
) -> dict[str, bool]:
    """One flag per reason in REASONS, plus `excluded` when any of them holds. `responses` with the
    participant's `plan` give the viewing flag; without them it is not set. A bot is never flagged by the rules
    that judge how a person took the study (`PEOPLE_ONLY`): analysed, it rehearses the analysis as it answered."""
    duration = duration_s(participant)
    kinds = (rules or ExclusionRules()).kinds
    person = (getattr(participant, "kind", None) or "real") != "bot"
    plan = plan or []
    skipped = person and any(
        viewing_problems(r, screen)["skipped"]
        for r in responses or []
        if r.step < len(plan) and shows_clip(screen := plan[r.step])
    )
    flags = {
        "pilot_or_bot": (getattr(participant, "kind", None) or "real") not in kinds,
        "incomplete": participant.status != "completed",
        "failed_attention": participant.attention_failures > 0,
        "too_fast": person and threshold_s is not None and duration is not None and duration < threshold_s,
        "flagged_by_admin": bool(participant.excluded),
        "skipped_viewing": skipped,
    }
    flags["excluded"] = any(flags.values())
    return flags
