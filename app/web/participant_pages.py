"""The participant's pages. State lives on the server (like oTree): `/study` always shows the participant's
current screen, so a reload, the back button or reopening the link shows the same page, and a screen can be
answered only when it is the current one.

The endpoints are plain functions, which FastAPI runs in its thread pool; they read and write through
`Database.reading()` and `writing()`, and every answer is committed before the reply.
"""

from __future__ import annotations

import random
import re
import secrets
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from math import ceil
from typing import Any, TypeVar

from fastapi import APIRouter, HTTPException, Request, Response
from fastapi.responses import HTMLResponse, RedirectResponse
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session
from starlette.datastructures import FormData

from app.store import queries
from app.store.models import Participant
from app.survey.answers import Checked, Outcome, Refused, current_with_plan, full_view_at, save_answer
from app.survey.assignment import condition_for_slot, next_slot
from app.survey.kinds import kind_from_link, pilot_token
from app.survey.plan import build_plan
from app.survey.screens import Screen, dump_plan, page_view
from app.survey.study import FEEDBACK, digits
from app.web.context import Context, ContextDep
from app.web.security import FormDep

router = APIRouter()
T = TypeVar("T")
MTURK_PREVIEW = "ASSIGNMENT_ID_NOT_AVAILABLE"
PLATFORM_PARAMS = {  # external id, platform study id, platform session id
    "prolific": ("PROLIFIC_PID", "STUDY_ID", "SESSION_ID"),
    "mturk": ("workerId", "hitId", "assignmentId"),
}
PLATFORM_NAMES = {"prolific": "Prolific", "mturk": "Amazon Mechanical Turk"}
ID_VALUE = re.compile(r"^[A-Za-z0-9_.:-]{1,128}$")
MOBILE = re.compile(r"Mobi|Android|iPhone|iPad|iPod", re.IGNORECASE)
LOST = (
    "We could not find your place in the study (cookies may be blocked or have "
    "expired). Please open the study again from the link you were given."
)


def _current_screens(
    session: Session, ctx: Context, request: Request, kept: object
) -> tuple[queries.Record, list[Screen] | None, str]:
    """The participant, their screens while they take part, and the notice for screen `kept` (a step whose first
    answers were kept when it was sent again; "" for none)."""
    participant, plan = current_with_plan(session, ctx.study, request.session.get("participant"))
    if participant is None:
        raise HTTPException(400, LOST)
    plan = plan if participant.status == "started" else None
    if plan is None or not isinstance(kept, int) or not 0 <= kept < participant.step:
        return participant, plan, ""
    saved = queries.saved_answers(session, participant.id, kept)
    return participant, plan, "" if saved is None else _kept_notice(ctx, plan[kept], saved)


def _see_current() -> RedirectResponse:
    return RedirectResponse("/study", status_code=303)


def _platform_identity(platform: str, params: Mapping[str, str]) -> dict[str, str]:
    names = PLATFORM_PARAMS[platform]
    values = [params.get(name, "") for name in names]
    # All three, or the link cannot tell its participant from someone who only knows their platform id.
    if missing := [name for name, value in zip(names, values, strict=True) if not value]:
        raise HTTPException(
            400,
            f"This link must be opened from {PLATFORM_NAMES[platform]}: it lacks "
            f"{' and '.join(missing)}. Please go back to the study's page there and use its link.",
        )
    for name, value in zip(names, values, strict=True):
        if value and not ID_VALUE.match(value):
            raise HTTPException(400, f"The link's {name} is not a valid identifier.")
    return dict(zip(queries.IDENTITY, values, strict=True))


def _by_code(session: Session, ctx: Context, code: object) -> queries.Record | None:
    if not isinstance(code, str):
        return None
    return queries.participant_by_code(session, ctx.study.study.id, code)


def _by_identity(session: Session, ctx: Context, identity: Mapping[str, str]) -> queries.Record | None:
    """The participant who started from a link with these three platform ids (see docs/survey.md, Recruiting: a
    platform id alone binds nothing)."""
    info = ctx.study.study
    return queries.participant_by_identity(session, info.id, info.platform, identity)


def _current(session: Session, ctx: Context, request: Request) -> queries.Record:
    participant = _by_code(session, ctx, request.session.get("participant"))
    if participant is None:
        raise HTTPException(400, LOST)
    return participant


def _read(find: Callable[..., T], ctx: Context, *args: Any) -> T:
    """`find(session, ctx, *args)` in a read transaction."""
    with ctx.db.reading() as session:
        return find(session, ctx, *args)


@router.get("/")
def landing(request: Request, ctx: ContextDep) -> Response:
    info = ctx.study.study
    if info.platform == "mturk" and request.query_params.get("assignmentId") == MTURK_PREVIEW:
        return ctx.render_form(request, ("consent.html", True), "consent.html", lambda: {"preview": True})
    if info.device == "desktop" and MOBILE.search(request.headers.get("user-agent", "")):
        desktop_only: Response = ctx.message(
            request,
            "Please use a computer",
            "This study needs a laptop or desktop computer. Please open the link there.",
        )
        return desktop_only
    kind, fast = "real", False
    if "pilot" in request.query_params or "bot" in request.query_params:
        kind, fast = kind_from_link(request.query_params, pilot_token(ctx.db, info.id))
        if "pilot" in request.query_params and not fast:
            raise HTTPException(
                400,
                "This preview link is not valid for this study (it may be from an older "
                "server). Copy the pilot link again from the admin overview.",
            )
    if kind == "real":  # the session holds a kind only for pilots and bots
        request.session.pop("kind", None)
        request.session.pop("fast", None)
    else:
        request.session["kind"], request.session["fast"] = kind, fast
    if info.platform != "none":
        identity = _platform_identity(info.platform, request.query_params)
        known = _read(_by_identity, ctx, identity)
        if known is None:  # the same browser, the same platform id: the link's other ids may have changed
            own = _read(_by_code, ctx, request.session.get("participant"))
            known = own if own is not None and own.external_id == identity["external_id"] else None
        request.session["identity"] = identity
    else:
        known = _read(_by_code, ctx, request.session.get("participant"))
    if known is not None:
        request.session["participant"] = known.code
        return _see_current()
    request.session.pop("participant", None)
    if info.platform == "none":  # the code consent gives: a consent sent again (its reply lost) finds its participant
        request.session.setdefault("entering", secrets.token_hex(16))
    return ctx.render_form(request, ("consent.html", False), "consent.html", lambda: {"preview": False})


def _enter(
    ctx: Context, identity: dict[str, str], agreed: bool, user_agent: str, kind: str = "real", drawn: object = None
) -> str:
    """Create the participant (or find the one a concurrent or earlier consent created: by `identity`, the
    platform's ids, or else by `drawn`, the code the consent page's session drew) and assign them; returns the code.

    Conflicts on the unique identity, code or slot make the transaction fail as a whole and the loop tries again."""
    info = ctx.study.study
    for _ in range(50):
        try:
            with ctx.db.writing() as session:
                known = _by_identity(session, ctx, identity) if identity else _by_code(session, ctx, drawn)
                if known is not None:
                    return str(known.code)
                now = datetime.now(UTC)
                code = drawn if isinstance(drawn, str) and not identity else secrets.token_hex(16)
                values: dict[str, Any] = {
                    "code": code,
                    "study": info.id,
                    "platform": info.platform,
                    "external_id": None,
                    "platform_study_id": None,
                    "platform_session_id": None,
                    "status": "started" if agreed else "declined",
                    "slot": None,
                    "condition": None,
                    "step": 0,
                    "step_started_at": now,
                    "user_agent": user_agent[:512],
                    "created_at": now,
                    "completed_at": None,
                    "excluded": False,
                    "exclusion_note": "",
                    "attention_failures": 0,
                    "kind": kind,
                    "consent_version": ctx.study.consent_version(),
                    "details": None,
                    **identity,
                }
                if agreed and info.assignment == "balanced":
                    values["slot"] = next_slot(session, study=info.id)
                    values["condition"] = condition_for_slot(
                        seed=info.seed, n_conditions=len(ctx.conditions), slot=values["slot"]
                    )
                participant_id = queries.enter_participant(session, values)
                if values["condition"] is not None:
                    queries.save_plan(session, participant_id, _new_plan(ctx, participant_id, values["condition"]))
                return code
        except IntegrityError:
            continue
    raise HTTPException(503, "The study is very busy at this moment. Please wait a few seconds and try again.")


def _new_plan(ctx: Context, participant_id: int, condition: int) -> list[dict[str, Any]]:
    rng = random.Random(f"{ctx.study.study.seed}:participant:{participant_id}")
    return dump_plan(build_plan(ctx.study, ctx.bundle, ctx.conditions[condition], rng))


def _assign_plan(ctx: Context, participant: Participant, condition: int) -> None:
    participant.condition = condition
    participant.plan = _new_plan(ctx, participant.id, condition)
    participant.step = 0
    participant.step_started_at = datetime.now(UTC)


@router.post("/consent")
def consent(request: Request, ctx: ContextDep, form: FormDep) -> RedirectResponse:
    choice = form.get("choice")
    if choice not in ("agree", "decline"):
        raise HTTPException(400, "Please choose whether you agree to take part.")
    identity: dict[str, str] = {}
    if ctx.study.study.platform != "none":
        linked = request.session.get("identity")
        if not isinstance(linked, dict) or not linked.get("external_id"):
            raise HTTPException(400, "Please open the study from the link you were given.")
        identity = linked
    kind = "real"
    if (linked_kind := request.session.get("kind")) in ("pilot", "bot"):
        kind = str(linked_kind)
    researchers = kind != "real" and request.session.get("fast") is True  # the pilot link, with its token
    if (
        not researchers
        and (wait := request.app.state.arrivals.take(request.client.host if request.client else "unknown")) > 0
    ):
        raise HTTPException(
            429,
            "Many people have just started the study from your network. Please wait "
            f"{ceil(wait)} seconds, then press the button again.",
            headers={"retry-after": str(ceil(wait))},
        )
    user_agent = request.headers.get("user-agent", "")
    code = _enter(ctx, identity, choice == "agree", user_agent, kind, request.session.get("entering"))
    request.session["participant"] = code
    request.session.pop("identity", None)
    request.session.pop("entering", None)  # the next consent in this browser, after a new landing, is someone new
    return _see_current()


def _render_screen(
    request: Request,
    ctx: Context,
    screen: Screen,
    step: int,
    *,
    errors: dict[str, str] | None = None,
    values: dict[str, list[Any]] | None = None,
    events: str = "",
    status_code: int = 200,
    notice: str = "",
    watched: bool = False,
) -> HTMLResponse:
    name = screen.template
    if not (errors or values or events or notice):  # as first shown: the same page for everyone at this step
        return ctx.render_form(
            request,
            (name, step, screen.text),
            name,
            lambda: {
                "screen": page_view(screen, ctx.study, ctx.bundle),
                "step": step,
                "errors": {},
                "values": {},
                "video_events": "",
                "watched": False,
                "notice": "",
            },
        )
    return ctx.render(
        request,
        name,
        status_code=status_code,
        screen=page_view(screen, ctx.study, ctx.bundle),
        step=step,
        errors=errors or {},
        values=values or {},
        video_events=events,
        watched=watched,
        notice=notice,
    )


def _status_page(request: Request, ctx: Context, participant: queries.Record) -> HTMLResponse:
    page: HTMLResponse
    if participant.status == "declined":
        page = ctx.message(request, "Thank you", ctx.study.texts.declined)
    elif participant.status == "returned":
        left = "You chose to stop taking part, so the study cannot be taken again from this link."
        if ctx.study.study.platform == "prolific":
            left += " Please return your submission on Prolific, if you have not done so yet."
        page = ctx.message(request, "You have left the study", left)
    else:
        page = ctx.render(request, "complete.html", completion=ctx.study.completion)
    return page


@router.get("/study")
def current_page(request: Request, ctx: ContextDep) -> HTMLResponse:
    kept = request.session.pop("kept", None) if "kept" in request.session else None
    participant, plan, notice = _read(_current_screens, ctx, request, kept)
    if participant.status != "started":
        return _status_page(request, ctx, participant)
    if participant.condition is None:
        return ctx.render(request, "choose.html", n_conditions=len(ctx.conditions), error="")
    assert plan is not None  # a participant who takes part and has a condition has a plan
    return _render_screen(request, ctx, plan[participant.step], participant.step, notice=notice)


NOTICE_ANSWER_CHARS = 60  # a saved text answer in the notice: its beginning


def _kept_notice(ctx: Context, screen: Screen, saved: dict[str, Any]) -> str:
    """What the participant is told when a screen they had already answered is sent again with other answers
    (the back button, then another choice): short, with the kept choices and the start of any text."""
    shown = []
    for name, value in saved.items():
        if name not in ctx.study.questions and name != FEEDBACK:
            continue  # comprehension and attention answers: only one is right, nothing to remind of
        text = " > ".join(value) if isinstance(value, list) else str(value)
        shown.append(text if len(text) <= NOTICE_ANSWER_CHARS else text[:NOTICE_ANSWER_CHARS] + "…")
    where = screen.progress or "that screen"
    kept = f" ({'; '.join(shown)})" if shown else ""
    return (
        f"You had already answered {where}: answers cannot be changed, so your first answers{kept} are kept. "
        "Please continue below."
    )


@router.post("/study")
def submit(request: Request, ctx: ContextDep, form: FormDep) -> Response:
    step = form.get("step")
    if not isinstance(step, str) or not digits(step) or len(step) > 6:
        raise HTTPException(400, "The form is missing its step number; reload the page and try again.")
    fast_link = request.session.get("fast") is True
    saving = save_answer(ctx.db, ctx.study, request.session.get("participant"), int(step), form, fast_link=fast_link)
    if isinstance(saving, Refused):
        return _refused(request, ctx, int(step), form, saving.screen, saving.checked)
    if saving is Outcome.UNKNOWN:
        raise HTTPException(400, LOST)
    if saving is Outcome.NOT_OPEN:
        raise HTTPException(409, "That page is not open yet. Please continue where you left off.")
    if saving is Outcome.KEPT:  # the session cookie holds only the step: the notice is built from the database
        request.session["kept"] = int(step)
    return _see_current()


def _refused(
    request: Request, ctx: Context, step: int, form: FormData, screen: Screen, checked: Checked
) -> HTMLResponse:
    """The screen again, with the participant's answers and why they were not saved."""
    values = {name: form.getlist(name) for name in form.keys() if name != "csrf_token"}
    # the clip (every reel) stays unlocked when the record shows it played to its end and the server took that
    watched = (
        "video" not in checked.errors and full_view_at(checked.video_events, len(screen.clips_to_watch())) is not None
    )
    return _render_screen(
        request,
        ctx,
        screen,
        step,
        errors=checked.errors,
        values=values,
        events=str(form.get("video_events") or "")[:20000],
        status_code=422,
        watched=watched,
    )


@router.post("/condition")
def choose_condition(request: Request, ctx: ContextDep, form: FormDep) -> Response:
    """The paper's self-selected assignment: the participant picks a number from 1 to N."""
    number = form.get("number")
    n = len(ctx.conditions)
    participant_id = _read(_current, ctx, request).id
    if not isinstance(number, str) or not digits(number) or not 1 <= int(number) <= n:
        return ctx.render(
            request, "choose.html", status_code=422, n_conditions=n, error=f"Please choose a number from 1 to {n}."
        )
    with ctx.db.writing() as session:
        participant = session.get(Participant, participant_id)
        if participant is not None and participant.status == "started" and participant.condition is None:
            _assign_plan(ctx, participant, int(number) - 1)
    return _see_current()


@router.get("/leave")
def leave_confirm(request: Request, ctx: ContextDep) -> HTMLResponse:
    _read(_current, ctx, request)
    return ctx.render(request, "leave.html")


@router.post("/leave")
def leave(request: Request, ctx: ContextDep, form: FormDep) -> RedirectResponse:
    participant_id = _read(_current, ctx, request).id
    with ctx.db.writing() as session:
        participant = session.get(Participant, participant_id)
        if participant is not None and participant.status == "started":
            participant.status = "returned"
    return _see_current()
