"""Which participants the analysis leaves out, and why. The rules are applied the same way by the export (as
flag columns) and by the report (which drops flagged participants and counts them per reason)."""

from __future__ import annotations

import statistics
from dataclasses import dataclass

from sqlalchemy import Row, select

from app.database import Database, as_utc
from app.models import Participant

REASONS = {
    "incomplete": "did not complete the study (started, returned or declined)",
    "failed_attention": "failed at least one attention check",
    "too_fast": "completed faster than the time threshold",
    "flagged_by_admin": "flagged for exclusion on the admin pages",
}


@dataclass(frozen=True)
class ExclusionRules:
    """`min_seconds` is an absolute floor on the completion time; without it the floor is `median_fraction`
    of the median completion time (a third by default, a common rule for speeders). 0 turns the rule off."""

    min_seconds: float | None = None
    median_fraction: float = 1 / 3

    def __post_init__(self):
        if self.min_seconds is not None and self.min_seconds < 0:
            raise ValueError(f"the minimum duration must not be negative, got {self.min_seconds}")
        if not 0 <= self.median_fraction < 1:
            raise ValueError(f"the fraction of the median duration must be in [0, 1), got {self.median_fraction}")

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


def duration_s(participant: Participant | Row) -> float | None:
    if participant.completed_at is None:
        return None
    return (as_utc(participant.completed_at) - as_utc(participant.created_at)).total_seconds()


def median_duration_s(db: Database, study_id: str) -> float | None:
    """Median completion time of the study's completed participants (one float each in memory)."""
    query = select(Participant.created_at, Participant.completed_at).where(
        Participant.study == study_id, Participant.status == "completed", Participant.completed_at.is_not(None))
    with db.reading() as session:
        durations = [(as_utc(done) - as_utc(start)).total_seconds() for start, done in session.execute(query)]
    return statistics.median(durations) if durations else None


def exclusion_flags(participant: Participant | Row, threshold_s: float | None) -> dict[str, bool]:
    """One flag per reason in REASONS, plus `excluded` when any of them holds."""
    duration = duration_s(participant)
    flags = {
        "incomplete": participant.status != "completed",
        "failed_attention": participant.attention_failures > 0,
        "too_fast": threshold_s is not None and duration is not None and duration < threshold_s,
        "flagged_by_admin": bool(participant.excluded),
    }
    flags["excluded"] = any(flags.values())
    return flags
