"""Database tables. Every change here comes with an Alembic revision in migrations/versions/."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    ForeignKey,
    Integer,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.ext.associationproxy import AssociationProxy, association_proxy
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

# Stable constraint names, so migrations can refer to them on SQLite (batch mode) and PostgreSQL alike.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)


class ServerSetting(Base):
    """Values the server generates once and every worker shares (the cookie signing key)."""

    __tablename__ = "server_setting"
    key: Mapped[str] = mapped_column(String(64), primary_key=True)
    value: Mapped[str] = mapped_column(Text)


class Participant(Base):
    """One person taking one study. `step` indexes `plan`, the screens they see (a ParticipantPlan)."""

    __tablename__ = "participant"
    __table_args__ = (
        # One record per platform identity (a link's three ids): coming back resumes it, concurrent first arrivals
        # cannot duplicate it. A platform id with other study or session ids is another record (docs/survey.md).
        UniqueConstraint(
            "study",
            "platform",
            "external_id",
            "platform_study_id",
            "platform_session_id",
            name="uq_participant_identity",
        ),
        # One arrival per slot: the balanced assignment's counter, safe across processes.
        UniqueConstraint("study", "slot", name="uq_participant_slot"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    code: Mapped[str] = mapped_column(String(32), unique=True)  # random public id kept in the session cookie
    study: Mapped[str] = mapped_column(String(64))
    platform: Mapped[str] = mapped_column(String(16))  # prolific | mturk | none
    external_id: Mapped[str | None] = mapped_column(String(128))  # PROLIFIC_PID / workerId; none when anonymous
    platform_study_id: Mapped[str | None] = mapped_column(String(128))  # STUDY_ID / hitId
    platform_session_id: Mapped[str | None] = mapped_column(String(128))  # SESSION_ID / assignmentId
    status: Mapped[str] = mapped_column(String(16), default="started")  # started|completed|returned|declined
    slot: Mapped[int | None] = mapped_column(Integer)  # arrival number for balanced assignment
    condition: Mapped[int | None] = mapped_column(Integer)  # 0-based index into the study's conditions
    step: Mapped[int] = mapped_column(Integer, default=0)
    step_started_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    user_agent: Mapped[str] = mapped_column(String(512), default="")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    completed_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    excluded: Mapped[bool] = mapped_column(Boolean, default=False)
    exclusion_note: Mapped[str] = mapped_column(Text, default="")
    attention_failures: Mapped[int] = mapped_column(Integer, default=0)
    kind: Mapped[str] = mapped_column(String(8), default="real", server_default="real")  # real | pilot | bot
    consent_version: Mapped[str] = mapped_column(String(64), default="", server_default="")  # consent text shown
    details: Mapped[dict[str, Any] | None] = mapped_column(JSON)  # comprehension attempts, viewport, ...

    responses: Mapped[list[Response]] = relationship(back_populates="participant", order_by="Response.step")
    plan_row: Mapped[ParticipantPlan | None] = relationship(
        lazy="selectin", cascade="all, delete-orphan", passive_deletes=True
    )
    plan: AssociationProxy[list[dict[str, Any]] | None] = association_proxy(
        "plan_row", "plan", creator=lambda plan: ParticipantPlan(plan=plan)
    )


class ParticipantPlan(Base):
    """The screens a participant sees, built once at assignment and never changed. Apart from the participant's
    row, which every answer updates: SQLite rewrites a row's whole record, and a plan is several kilobytes."""

    __tablename__ = "participant_plan"

    participant_id: Mapped[int] = mapped_column(ForeignKey("participant.id", ondelete="CASCADE"), primary_key=True)
    plan: Mapped[list[dict[str, Any]]] = mapped_column(JSON)


class Response(Base):
    """What a participant submitted on one screen; one row per (participant, step) makes resubmits harmless."""

    __tablename__ = "response"
    # Also the index of a participant's responses (its leading column).
    __table_args__ = (UniqueConstraint("participant_id", "step", name="uq_response_step"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participant.id", ondelete="CASCADE"))
    step: Mapped[int] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(16))  # instructions | pairwise | watch | ranking | attention
    answers: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # question name -> value as submitted
    video_events: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list)  # [{"type": "play", "t": ms}, ...]
    plays: Mapped[int] = mapped_column(Integer, default=0)
    # 64-bit: a screen left open for weeks (a participant who comes back through their link) overflows 32 bits
    client_ms: Mapped[int | None] = mapped_column(BigInteger)  # time on page measured by the browser
    server_ms: Mapped[int] = mapped_column(BigInteger)  # from the screen becoming current to this submission
    submitted_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    # what the browser reported besides the answers (viewport)
    details: Mapped[dict[str, Any] | None] = mapped_column(JSON)

    participant: Mapped[Participant] = relationship(back_populates="responses")
