"""Admin pages: progress per condition and status, median duration, one participant's answers and the exclusion
flag (the report and downloads are in app.web.analysis_pages). They exist only when FOIL_ADMIN_PASSWORD is set;
`disabled_router` says so otherwise."""

from __future__ import annotations

import hmac
import logging
import secrets
import statistics
from math import ceil
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request, Response
from fastapi.responses import HTMLResponse, RedirectResponse
from sqlalchemy.orm import Session

from app.analysis.answer_table import ParticipantRecord, long_rows
from app.store import queries
from app.store.database import as_utc
from app.store.models import Participant
from app.survey.screens import Screen
from app.web.context import Context, ContextDep
from app.web.security import FormDep, LoginThrottle, admin_mark, is_admin, unstorable

router = APIRouter(prefix="/admin")
disabled_router = APIRouter()
STATUSES = ["started", "completed", "returned", "declined"]
log = logging.getLogger("foil.admin")


class LoginRequired(Exception):
    """Raised by `admin_only`; app.web.main turns it into a redirect to the login page."""


def _password(ctx: Context) -> str:
    """The admin password; without one no session is an admin's (these pages are not served then)."""
    if ctx.settings.admin_password is None:
        raise LoginRequired
    return ctx.settings.admin_password.get_secret_value()


def admin_only(request: Request) -> None:
    """Only for a session logged in since the last logout, with the current password (`security.admin_mark`)."""
    mark = request.session.get("admin")
    if not isinstance(mark, str):
        raise LoginRequired
    ctx: Context = request.app.state.context
    with ctx.db.reading() as session:
        if not is_admin(session, _password(ctx), mark):
            raise LoginRequired


Admin = Depends(admin_only)


@disabled_router.api_route("/admin{rest:path}", methods=["GET", "POST"])
def admin_disabled(request: Request, ctx: ContextDep) -> HTMLResponse:
    page: HTMLResponse = ctx.message(
        request,
        "Admin pages are off",
        "Set FOIL_ADMIN_PASSWORD (8 characters or more) and restart the server to use them.",
        status_code=404,
    )
    return page


@router.get("/login")
def login_page(request: Request, ctx: ContextDep) -> HTMLResponse:
    return ctx.render(request, "admin/login.html", error="")


@router.post("/login")
def login(request: Request, ctx: ContextDep, form: FormDep) -> Response:
    throttle: LoginThrottle = request.app.state.login_throttle
    client = request.client.host if request.client else "unknown"
    if (wait := throttle.wait_s(client)) > 0:
        log.warning(
            "admin login from %s refused without checking: too many wrong passwords, %.0f s to wait", client, wait
        )
        refused = ctx.render(
            request,
            "admin/login.html",
            status_code=429,
            error=f"Too many wrong passwords. Try again in {ceil(wait)} seconds.",
        )
        refused.headers["retry-after"] = str(ceil(wait))
        return refused
    typed = form.get("password")
    expected = _password(ctx)
    if not isinstance(typed, str) or not hmac.compare_digest(typed.encode(), expected.encode()):
        log.warning("admin login from %s: wrong password (%d in a row)", client, throttle.failed(client))
        return ctx.render(request, "admin/login.html", status_code=401, error="Wrong password.")
    throttle.succeeded(client)
    log.info("admin login from %s", client)
    with ctx.db.writing() as session:
        request.session["admin"] = admin_mark(session, expected)
    request.session["csrf"] = secrets.token_urlsafe(32)  # a new token once logged in
    return RedirectResponse("/admin", status_code=303)


@router.post("/logout", dependencies=[Admin])
def logout(request: Request, ctx: ContextDep, form: FormDep) -> RedirectResponse:
    with ctx.db.writing() as session:  # a new version of the admin sessions: every admin cookie so far ends
        admin_mark(session, _password(ctx), renew=True)
    request.session.pop("admin", None)
    log.info("admin logout from %s: every admin session ended", request.client.host if request.client else "?")
    return RedirectResponse("/admin/login", status_code=303)


def _overview(ctx: Context, session: Session) -> dict[str, Any]:
    """Counts per condition and status, and the median duration, computed without loading the participants."""
    counts = queries.counts_by_condition_and_status(session, ctx.study.study.id)
    rows: list[tuple[int | str, str, list[int]]] = [
        (c.index + 1, c.describe(ctx.study), [counts[(c.index, s)] for s in STATUSES]) for c in ctx.conditions
    ]
    unassigned = [counts[(None, s)] for s in STATUSES]
    if any(unassigned):
        rows.append(("-", "not assigned yet", unassigned))
    durations = [
        (as_utc(completed) - as_utc(created)).total_seconds()
        for created, completed in queries.completion_times(session, ctx.study.study.id)
    ]
    return {
        "rows": rows,
        "totals": [sum(row[2][i] for row in rows) for i in range(len(STATUSES))],
        "median_minutes": statistics.median(durations) / 60 if durations else None,
        "n_completed": len(durations),
    }


PAGE_SIZE = 50
NO_SUCH_PARTICIPANT = "No participant with that code."


@router.get("", dependencies=[Admin])
def overview(request: Request, ctx: ContextDep, status: str = "", page: int = 1) -> HTMLResponse:
    """The progress table and one page of the participants list, newest first (`status`: a status or a kind)."""
    from app.survey.kinds import pilot_token

    study = ctx.study.study.id
    with ctx.db.reading() as session:
        n_shown = queries.count_listed(session, study, status)
        pages = max(1, -(-n_shown // PAGE_SIZE))
        page = min(max(1, page), pages)
        listed = queries.listed_participants(session, study, status, PAGE_SIZE, (page - 1) * PAGE_SIZE)
        summary = _overview(ctx, session)
    pilot = f"{str(request.base_url).rstrip('/')}/?pilot={pilot_token(ctx.db, ctx.study.study.id)}"
    return ctx.render(
        request,
        "admin/overview.html",
        statuses=STATUSES,
        shown=listed,
        status=status,
        page=page,
        pages=pages,
        n_shown=n_shown,
        pilot_link=pilot,
        **summary,
    )


def _participant(session: Session, ctx: Context, code: str) -> Participant:
    participant = queries.find_participant(session, ctx.study.study.id, code)
    if participant is None:
        raise HTTPException(404, NO_SUCH_PARTICIPANT)
    return participant


def shown_as(plan: list[Screen], step: int) -> str:
    """A screen named as its participant saw it: the line above it ("Part 1 of 2, clip 3 of 6"; in a ranking part
    "Part 2 of 2, round 1 of 2, ranking"), not its index in the plan."""
    if step >= len(plan):
        return "finished"
    screen = plan[step]
    return screen.progress or screen.admin_name()


@router.get("/participants/{code}", dependencies=[Admin])
def participant_page(code: str, request: Request, ctx: ContextDep) -> HTMLResponse:
    with ctx.db.reading() as session:
        found = queries.participant_and_responses(session, ctx.study.study.id, code)
    if found is None:
        raise HTTPException(404, NO_SUCH_PARTICIPANT)
    participant, responses = found
    record = ParticipantRecord(participant, responses)
    rows = list(long_rows(ctx.study, record))
    plan = record.plan
    for row in rows:
        row["shown_as"] = shown_as(plan, row["step"])
    condition = None if participant.condition is None else ctx.conditions[participant.condition]
    return ctx.render(
        request,
        "admin/participant.html",
        participant=participant,
        rows=rows,
        condition=condition.describe(ctx.study) if condition else "not assigned yet",
        steps=len(plan),
        current=shown_as(plan, participant.step) if plan else "",
    )


@router.post("/participants/{code}/exclusion", dependencies=[Admin])
def set_exclusion(code: str, request: Request, ctx: ContextDep, form: FormDep) -> RedirectResponse:
    excluded = form.get("excluded")
    note = form.get("note") or ""
    if excluded not in ("0", "1") or not isinstance(note, str) or len(note) > 2000:
        raise HTTPException(400, "Send excluded as 0 or 1 and a note of at most 2000 characters.")
    if (problem := unstorable(note)) is not None:
        raise HTTPException(
            400,
            f"The note contains {problem}, which cannot be saved: remove it and send the note "
            "again (nothing was changed).",
        )
    with ctx.db.writing() as session:
        participant = _participant(session, ctx, code)
        participant.excluded, participant.exclusion_note = excluded == "1", note
    return RedirectResponse(f"/admin/participants/{code}", status_code=303)
