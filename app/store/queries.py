"""The SQL the survey's pages run, one function per question asked of the database, named by what it does.

A participant's requests run Core statements in a Session: loading ORM objects and flushing them cost several times
what the statements do. The INSERTs name every column. The admin pages, read rarely, load ORM objects.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from datetime import datetime
from typing import Any

from sqlalchemy import Row, bindparam, func, insert, select, update
from sqlalchemy.orm import Session

from app.store.models import Base, Participant, ParticipantPlan, Response

TABLES = Base.metadata.tables
PARTICIPANT, RESPONSE = TABLES[Participant.__tablename__], TABLES[Response.__tablename__]
PLANS = TABLES[ParticipantPlan.__tablename__]
Record = Row[*tuple[Any, ...]]  # a row of columns read by name, as attributes
IDENTITY = ("external_id", "platform_study_id", "platform_session_id")  # the ids a platform's link carries
_COLUMNS = PARTICIPANT.c["id", "code", "status", "condition", "step", "step_started_at", "kind", "external_id"]
_SHOWN = select(*_COLUMNS).where(PARTICIPANT.c.study == bindparam("study"))
_BY_CODE = _SHOWN.where(PARTICIPANT.c.code == bindparam("code"))
# The participant and their plan in one statement: every page and answer needs both, and on PostgreSQL each
# statement is a round trip to the server.
_WITH_PLAN = (
    select(*_COLUMNS, PLANS.c.plan)
    .select_from(PARTICIPANT.outerjoin(PLANS, PLANS.c.participant_id == PARTICIPANT.c.id))
    .where(PARTICIPANT.c.study == bindparam("study"), PARTICIPANT.c.code == bindparam("code"))
)
_BY_IDENTITY = _SHOWN.where(
    PARTICIPANT.c.platform == bindparam("platform"), *(PARTICIPANT.c[name] == bindparam(name) for name in IDENTITY)
)
_ENTER = (
    insert(PARTICIPANT)
    .values({name: bindparam(name) for name in PARTICIPANT.c.keys() if name != "id"})
    .returning(PARTICIPANT.c.id)
)
_SAVE_PLAN = insert(PLANS).values(participant_id=bindparam("participant"), plan=bindparam("plan"))
_SAVE_RESPONSE = insert(RESPONSE).values({name: bindparam(name) for name in RESPONSE.c.keys() if name != "id"})
_SAVED_ANSWERS = select(RESPONSE.c.answers).where(
    RESPONSE.c.participant_id == bindparam("participant"), RESPONSE.c.step == bindparam("step")
)
_NEXT_STEP = (
    update(PARTICIPANT)
    .where(PARTICIPANT.c.id == bindparam("participant"))
    .values(
        step=bindparam("to_step"),
        step_started_at=bindparam("now"),
        status=bindparam("to_status"),
        completed_at=bindparam("completed"),
        attention_failures=PARTICIPANT.c.attention_failures + bindparam("failed"),
    )
)
_DETAILS = select(PARTICIPANT.c.details).where(PARTICIPANT.c.id == bindparam("participant"))
_SAVE_DETAILS = (
    update(PARTICIPANT).where(PARTICIPANT.c.id == bindparam("participant")).values(details=bindparam("details"))
)


def participant_by_code(session: Session, study: str, code: str) -> Record | None:
    """The participant of `study` with this code (their session cookie's), without their plan."""
    return session.execute(_BY_CODE, {"study": study, "code": code}).first()


def participant_with_plan(session: Session, study: str, code: str) -> Record | None:
    """The participant of `study` with this code and their stored plan (`plan` None before assignment)."""
    return session.execute(_WITH_PLAN, {"study": study, "code": code}).first()


def participant_by_identity(session: Session, study: str, platform: str, identity: Mapping[str, str]) -> Record | None:
    """The participant who started from a link with these three platform ids (`IDENTITY`)."""
    return session.execute(_BY_IDENTITY, {"study": study, "platform": platform, **identity}).first()


def enter_participant(session: Session, values: Mapping[str, Any]) -> int:
    """Insert a participant (`values` names every column but the id); returns their id."""
    participant_id: int = session.scalar(_ENTER, dict(values))
    return participant_id


def save_plan(session: Session, participant_id: int, plan: list[dict[str, Any]]) -> None:
    session.execute(_SAVE_PLAN, {"participant": participant_id, "plan": plan})


def saved_answers(session: Session, participant_id: int, step: int) -> dict[str, Any] | None:
    """The answers saved for screen `step` of the participant; None when it has none."""
    answers: dict[str, Any] | None = session.scalar(_SAVED_ANSWERS, {"participant": participant_id, "step": step})
    return answers


def save_response(session: Session, values: Mapping[str, Any]) -> None:
    """Insert one screen's response (`values` names every column but the id)."""
    session.execute(_SAVE_RESPONSE, dict(values))


def next_step(session: Session, participant_id: int, step: int, now: datetime, *, failed: bool, done: bool) -> None:
    """Make screen `step` the participant's current one from `now`, the completion page when `done`; `failed`
    counts a failed attention check."""
    session.execute(
        _NEXT_STEP,
        {
            "participant": participant_id,
            "to_step": step,
            "now": now,
            "failed": int(failed),
            "to_status": "completed" if done else "started",
            "completed": now if done else None,
        },
    )


def count_comprehension_attempt(session: Session, participant_id: int) -> None:
    """One more attempt at the comprehension questions in the participant's details."""
    details = dict(session.scalar(_DETAILS, {"participant": participant_id}) or {})
    details["comprehension_attempts"] = details.get("comprehension_attempts", 0) + 1
    session.execute(_SAVE_DETAILS, {"participant": participant_id, "details": details})


def counts_by_condition_and_status(session: Session, study: str) -> Counter[tuple[int | None, str]]:
    """How many participants of `study` each (condition, status) has, counted by the database."""
    counted = session.execute(
        select(Participant.condition, Participant.status, func.count())
        .where(Participant.study == study)
        .group_by(Participant.condition, Participant.status)
    )
    return Counter({(condition, status): n for condition, status, n in counted})


def completion_times(session: Session, study: str) -> list[tuple[datetime, datetime]]:
    """(created, completed) of every real participant of `study` who completed it (pilots and bots left out)."""
    rows = session.execute(
        select(Participant.created_at, Participant.completed_at).where(
            Participant.study == study,
            Participant.status == "completed",
            Participant.completed_at.is_not(None),
            Participant.kind == "real",
        )
    )
    return [(created, completed) for created, completed in rows if completed is not None]


def _listed(study: str, status: str) -> Any:
    """The participants of `study` with this status or kind; all of them for ""."""
    shown = Participant.study == study
    return shown & ((Participant.status == status) | (Participant.kind == status)) if status else shown


def count_listed(session: Session, study: str, status: str) -> int:
    """How many participants `listed_participants` pages through."""
    return session.scalar(select(func.count()).select_from(Participant).where(_listed(study, status))) or 0


def listed_participants(session: Session, study: str, status: str, limit: int, offset: int) -> list[Participant]:
    """One page of the participants of `study` with this status or kind ("": all), newest first."""
    return list(
        session.scalars(
            select(Participant)
            .where(_listed(study, status))
            .order_by(Participant.id.desc())
            .limit(limit)
            .offset(offset)
        )
    )


def participant_and_responses(session: Session, study: str, code: str) -> tuple[Record, list[Record]] | None:
    """The participant of `study` with this code, with their plan, and their responses in step order."""
    participant = session.execute(
        select(PARTICIPANT, PLANS.c.plan)
        .outerjoin(PLANS, PLANS.c.participant_id == PARTICIPANT.c.id)
        .where(PARTICIPANT.c.study == study, PARTICIPANT.c.code == code)
    ).first()
    if participant is None:
        return None
    responses = session.execute(
        select(RESPONSE).where(RESPONSE.c.participant_id == participant.id).order_by(RESPONSE.c.step)
    )
    return participant, list(responses)


def find_participant(session: Session, study: str, code: str) -> Participant | None:
    """The participant of `study` with this code, as an ORM object (its responses load when read)."""
    return session.scalar(select(Participant).where(Participant.study == study, Participant.code == code))
