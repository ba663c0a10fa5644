"""The participant's pages. State lives on the server (like oTree): `/study` always shows the participant's
current screen, so a reload, the back button or reopening the link shows the same page, and a screen can be
answered only when it is the current one.

The endpoints are plain functions, which FastAPI runs in its thread pool; they read and write through
`Database.reading()` and `writing()`, and every answer is committed before the reply.
"""

from __future__ import annotations

import json
import random
import re
import secrets
from datetime import UTC, datetime
from math import ceil

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import RedirectResponse
from sqlalchemy import Row, bindparam, insert, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session
from starlette.datastructures import FormData

from app.store.database import as_utc
from app.store.models import Participant, ParticipantPlan, Response
from app.survey.answers import Checked, check_screen, digits
from app.survey.assignment import condition_for_slot, next_slot
from app.survey.clip_length import clip_shape
from app.survey.kinds import kind_from_link, pilot_token
from app.survey.plan import build_plan
from app.survey.screens import (
    Asking,
    Attention,
    Closing,
    InPart,
    Instructions,
    Pairwise,
    Ranking,
    Round,
    Screen,
    Shape,
    Watch,
    WithRobots,
    dump_plan,
    parse_plan,
    shows_clip,
)
from app.survey.study import FEEDBACK, TextQuestion
from app.visible import VisibleClip
from app.web.context import Context, ContextDep
from app.web.security import FormDep

# Every request of a participant runs these Core statements in a Session: loading ORM objects and flushing them
# cost several times what the statements do. The INSERTs name every column.
router = APIRouter()
IDENTITY = ("external_id", "platform_study_id", "platform_session_id")  # the ids a platform's link carries
PARTICIPANT, RESPONSE, PLANS = Participant.__table__, Response.__table__, ParticipantPlan.__table__
_COLUMNS = PARTICIPANT.c["id", "code", "status", "condition", "step", "step_started_at", "kind", "external_id"]
_SHOWN = select(*_COLUMNS).where(PARTICIPANT.c.study == bindparam("study"))
BY_CODE = _SHOWN.where(PARTICIPANT.c.code == bindparam("code"))
# The participant and their plan in one statement: every page and answer needs both, and on PostgreSQL each
# statement is a round trip to the server.
WITH_PLAN = (
    select(*_COLUMNS, PLANS.c.plan)
    .select_from(PARTICIPANT.outerjoin(PLANS, PLANS.c.participant_id == PARTICIPANT.c.id))
    .where(PARTICIPANT.c.study == bindparam("study"), PARTICIPANT.c.code == bindparam("code"))
)
BY_IDENTITY = _SHOWN.where(
    PARTICIPANT.c.platform == bindparam("platform"), *(PARTICIPANT.c[name] == bindparam(name) for name in IDENTITY)
)
SAVE_RESPONSE = insert(RESPONSE).values({name: bindparam(name) for name in RESPONSE.c.keys() if name != "id"})
ENTER = (
    insert(PARTICIPANT)
    .values({name: bindparam(name) for name in PARTICIPANT.c.keys() if name != "id"})
    .returning(PARTICIPANT.c.id)
)
SAVE_PLAN = insert(PLANS).values(participant_id=bindparam("participant"), plan=bindparam("plan"))
NEXT_STEP = (
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

MTURK_PREVIEW = "ASSIGNMENT_ID_NOT_AVAILABLE"
PLATFORM_PARAMS = {  # external id, platform study id, platform session id
    "prolific": ("PROLIFIC_PID", "STUDY_ID", "SESSION_ID"),
    "mturk": ("workerId", "hitId", "assignmentId"),
}
PLATFORM_NAMES = {"prolific": "Prolific", "mturk": "Amazon Mechanical Turk"}
ID_VALUE = re.compile(r"^[A-Za-z0-9_.:-]{1,128}$")
MOBILE = re.compile(r"Mobi|Android|iPhone|iPad|iPod", re.IGNORECASE)
VIEWPORT = re.compile(r"^[0-9]{2,5}x[0-9]{2,5}$")
# How much sooner than the clip's playing time (since the screen became current, by the server's clock) its
# answers are still accepted: clock granularity and the browser's own rounding, not a way to skip.
VIEW_TOLERANCE_MS = 1000


def _current_plan(session: Session, ctx: Context, request: Request) -> tuple[Row, list[Screen] | None]:
    """The current participant and their screens (None before a condition is assigned)."""
    participant = _current(session, ctx, request, WITH_PLAN)
    return participant, None if participant.plan is None else parse_plan(participant.plan)


def _current_screens(session: Session, ctx: Context, request: Request, kept) -> tuple[Row, list[Screen] | None, str]:
    """The participant, their screens while they take part, and the notice for screen `kept` (a step whose first
    answers were kept when it was sent again; "" for none)."""
    participant, plan = _current_plan(session, ctx, request)
    plan = plan if participant.status == "started" else None
    if plan is None or not isinstance(kept, int) or not 0 <= kept < participant.step:
        return participant, plan, ""
    saved = session.scalar(SAVED_ANSWERS, {"participant": participant.id, "step": kept})
    return participant, plan, "" if saved is None else _kept_notice(ctx, plan[kept], saved)


def _see_current() -> RedirectResponse:
    return RedirectResponse("/study", status_code=303)


def _platform_identity(platform: str, params) -> dict:
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
    return dict(zip(IDENTITY, values, strict=True))


def _by_code(session: Session, ctx: Context, code, query=BY_CODE) -> Row | None:
    if not isinstance(code, str):
        return None
    return session.execute(query, {"study": ctx.study.study.id, "code": code}).first()


def _by_identity(session: Session, ctx: Context, identity: dict) -> Row | None:
    """The participant who started from a link with these three platform ids (see docs/survey.md, Recruiting: a
    platform id alone binds nothing)."""
    info = ctx.study.study
    return session.execute(BY_IDENTITY, {"study": info.id, "platform": info.platform, **identity}).first()


def _current(session: Session, ctx: Context, request: Request, query=BY_CODE) -> Row:
    participant = _by_code(session, ctx, request.session.get("participant"), query)
    if participant is None:
        raise HTTPException(
            400,
            "We could not find your place in the study (cookies may be blocked or have "
            "expired). Please open the study again from the link you were given.",
        )
    return participant


def _read(find, ctx: Context, *args):
    """`find(session, ctx, *args)` in a read transaction."""
    with ctx.db.reading() as session:
        return find(session, ctx, *args)


@router.get("/")
def landing(request: Request, ctx: ContextDep):
    info = ctx.study.study
    if info.platform == "mturk" and request.query_params.get("assignmentId") == MTURK_PREVIEW:
        return ctx.render_form(request, ("consent.html", True), "consent.html", lambda: {"preview": True})
    if info.device == "desktop" and MOBILE.search(request.headers.get("user-agent", "")):
        return ctx.message(
            request,
            "Please use a computer",
            "This study needs a laptop or desktop computer. Please open the link there.",
        )
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
    return ctx.render_form(request, ("consent.html", False), "consent.html", lambda: {"preview": False})


def _enter(ctx: Context, identity: dict, agreed: bool, user_agent: str, kind: str = "real") -> str:
    """Create the participant (or find the one a concurrent request created) and assign them; returns the code.

    Conflicts on the unique identity or slot make the transaction fail as a whole and the loop tries again."""
    info = ctx.study.study
    for _ in range(50):
        try:
            with ctx.db.writing() as session:
                if identity and (known := _by_identity(session, ctx, identity)) is not None:
                    return known.code
                now = datetime.now(UTC)
                values = {
                    "code": secrets.token_hex(16),
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
                participant_id = session.scalar(ENTER, values)
                if values["condition"] is not None:
                    session.execute(
                        SAVE_PLAN,
                        {"participant": participant_id, "plan": _new_plan(ctx, participant_id, values["condition"])},
                    )
                return values["code"]
        except IntegrityError:
            continue
    raise HTTPException(503, "The study is very busy at this moment. Please wait a few seconds and try again.")


def _new_plan(ctx: Context, participant_id: int, condition: int) -> list[dict]:
    rng = random.Random(f"{ctx.study.study.seed}:participant:{participant_id}")
    return dump_plan(build_plan(ctx.study, ctx.bundle, ctx.conditions[condition], rng))


def _assign_plan(ctx: Context, participant: Participant) -> None:
    participant.plan = _new_plan(ctx, participant.id, participant.condition)
    participant.step = 0
    participant.step_started_at = datetime.now(UTC)


@router.post("/consent")
def consent(request: Request, ctx: ContextDep, form: FormDep):
    choice = form.get("choice")
    if choice not in ("agree", "decline"):
        raise HTTPException(400, "Please choose whether you agree to take part.")
    identity = {}
    if ctx.study.study.platform != "none":
        identity = request.session.get("identity")
        if not isinstance(identity, dict) or not identity.get("external_id"):
            raise HTTPException(400, "Please open the study from the link you were given.")
    kind = request.session.get("kind") if request.session.get("kind") in ("pilot", "bot") else "real"
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
    code = _enter(ctx, identity, choice == "agree", request.headers.get("user-agent", ""), kind)
    request.session["participant"] = code
    request.session.pop("identity", None)
    return _see_current()


def _clip_view(sha: str, shape: Shape | Pairwise | Watch | Attention) -> dict:
    """A clip's address and box; `shape` is anything with its `clip_ms`, `width` and `height` (a clip screen)."""
    return {
        "url": f"/clips/{sha}.mp4",
        "width": shape.width or 720,
        "height": shape.height or 880,
        "seconds": round((shape.clip_ms or 0) / 1000, 1),
    }


def _outcomes(ctx: Context, sha: str) -> list[str]:
    """How each robot of a clip visibly ends, in words by its label (what the clip itself shows, from its
    summary.json; nothing when the bundle has none): written beside a ranking round's clips."""
    clip = next((clip for clip in ctx.bundle.clips.values() if clip.sha256.lower() == sha), None)
    if clip is None or not clip.summary:
        return []
    try:
        summary = json.loads((ctx.bundle.root / clip.summary).read_text(encoding="utf-8"))
        shown = VisibleClip.of_summary(summary, clip.agents, clip.labels)
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        return []
    return [shown.describe(label) for label in clip.labels]


def screen_view(ctx: Context, screen: Screen) -> dict:
    """What a page may know about a screen: labels and the clip's address, never agent names or ground truth."""
    study = ctx.study
    robots = screen.robots if isinstance(screen, WithRobots) else []
    view = {
        "kind": screen.kind,
        "progress": screen.progress,
        "position": screen.position,
        "labels": [robot.label for robot in robots],
        "questions": [(name, study.questions[name]) for name in screen.questions] if isinstance(screen, Asking) else [],
        "block": screen.block if isinstance(screen, Round) else None,
        "round_start": isinstance(screen, Watch) and screen.round_start,
        "optional": [],
    }
    if isinstance(screen, InPart):
        part = study.parts[screen.part - 1]
        view["part_title"], view["part_intro"], view["part_kind"] = part.title, part.intro, part.kind
    if shows_clip(screen):
        view["clip"] = _clip_view(screen.media, screen)
        view["clip_url"] = view["clip"]["url"]
    match screen:
        case Ranking() if screen.media_list:
            shapes = screen.shapes or [Shape()] * len(screen.media_list)
            view["round_clips"] = [
                _clip_view(sha, shape) | {"outcomes": _outcomes(ctx, sha)}
                for sha, shape in zip(screen.media_list, shapes, strict=True)
            ]
        case Attention():
            check = study.attention_checks[screen.check]
            view["attention_text"], view["options"] = check.text, screen.options
        case Closing() if study.closing is not None:
            closing = study.closing
            view["part_title"], view["part_intro"] = closing.title, closing.intro
            view["optional"] = [name for name in closing.asks() if name not in closing.required]
            if screen.feedback and closing.feedback:
                view["feedback"] = TextQuestion(type="text", text=closing.feedback, rows=4)
        case Instructions() if study.example is not None:
            example = ctx.bundle.matching(study.example.scheme, study.example.scenario, study.example.agents)[0]
            sha = example.sha256.lower()
            shape = clip_shape(ctx.bundle.paths[sha])
            view["clip"] = _clip_view(sha, Shape(clip_ms=shape.ms, width=shape.width, height=shape.height))
            view["clip_url"] = view["clip"]["url"]
    return view


def _render_screen(
    request: Request,
    ctx: Context,
    screen: Screen,
    step: int,
    *,
    errors=None,
    values=None,
    events: str = "",
    status_code: int = 200,
    notice: str = "",
    watched: bool | None = None,
):
    name = "instructions.html" if isinstance(screen, Instructions) else "screen.html"
    if not (errors or values or events or notice):  # as first shown: the same page for everyone at this step
        return ctx.render_form(
            request,
            (name, step, screen.text),
            name,
            lambda: {
                "screen": screen_view(ctx, screen),
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
        screen=screen_view(ctx, screen),
        step=step,
        errors=errors or {},
        values=values or {},
        video_events=events,
        watched=('"ended"' in events) if watched is None else watched,
        notice=notice,
    )


def _status_page(request: Request, ctx: Context, participant: Row):
    texts = ctx.study.texts
    if participant.status == "declined":
        return ctx.message(request, "Thank you", texts.declined)
    if participant.status == "returned":
        return ctx.message(
            request,
            "You have left the study",
            "You chose to stop taking part, so the study cannot be taken again from this link. "
            "If you came from Prolific, please return your submission there.",
        )
    return ctx.render(request, "complete.html", completion=ctx.study.completion)


@router.get("/study")
def current_page(request: Request, ctx: ContextDep):
    kept = request.session.pop("kept", None) if "kept" in request.session else None
    participant, plan, notice = _read(_current_screens, ctx, request, kept)
    if participant.status != "started":
        return _status_page(request, ctx, participant)
    if participant.condition is None:
        return ctx.render(request, "choose.html", n_conditions=len(ctx.conditions), error="")
    return _render_screen(request, ctx, plan[participant.step], participant.step, notice=notice)


DETAILS = select(PARTICIPANT.c.details).where(PARTICIPANT.c.id == bindparam("participant"))
SAVE_DETAILS = (
    update(PARTICIPANT).where(PARTICIPANT.c.id == bindparam("participant")).values(details=bindparam("details"))
)
SAVED_ANSWERS = select(RESPONSE.c.answers).where(
    RESPONSE.c.participant_id == bindparam("participant"), RESPONSE.c.step == bindparam("step")
)


NOTICE_ANSWER_CHARS = 60  # a saved text answer in the notice: its beginning


def _kept_notice(ctx: Context, screen: Screen, saved: dict) -> str:
    """What the participant is told when a screen they had already answered is sent again with other answers
    (the back button, then another choice): short, with the kept choices and the start of any text."""
    shown = []
    for name, value in saved.items():
        if name not in ctx.study.questions and name != FEEDBACK:
            continue  # comprehension and attention answers: only one is right, nothing to remind of
        value = " > ".join(value) if isinstance(value, list) else str(value)
        shown.append(value if len(value) <= NOTICE_ANSWER_CHARS else value[:NOTICE_ANSWER_CHARS] + "…")
    where = screen.progress or "that screen"
    kept = f" ({'; '.join(shown)})" if shown else ""
    return (
        f"You had already answered {where}: answers cannot be changed, so your first answers{kept} are kept. "
        "Please continue below."
    )


def _viewing_problem(screen: Pairwise | Watch | Attention, started_at: datetime, now: datetime) -> str | None:
    """Why the server cannot accept a clip's answers yet: the screen has not been open as long as the clip plays
    (by the server's own clock, since the screen became current), so the clip cannot have been watched."""
    need = screen.clip_ms
    if not need:
        return None
    open_ms = (now - as_utc(started_at)).total_seconds() * 1000
    if open_ms + VIEW_TOLERANCE_MS >= need:
        return None
    return (
        f"The clip plays for {need / 1000:.0f} seconds, but this page has been open for only "
        f"{open_ms / 1000:.0f} seconds, so it cannot have been watched to the end at normal speed. Nothing was "
        "saved. Please play the clip from the start to the end, then answer again."
    )


KEPT = "kept"  # what `_save` says when a screen answered before was sent again with other answers


def _save(ctx: Context, request: Request, step: int, form: FormData) -> tuple[Screen, Checked] | str | None:
    """Save the answers to screen `step`: None when saved or nothing is left to save, KEPT when the screen had been
    answered before with other answers (the first are kept), else the screen to show again and why."""
    try:
        return _save_once(ctx, request, step, form)
    except IntegrityError:
        # A concurrent submission saved this screen first (PostgreSQL; SQLite's writers take turns): this one is
        # now a resubmit, answered as one.
        return _save_once(ctx, request, step, form)


def _save_once(ctx: Context, request: Request, step: int, form: FormData) -> tuple[Screen, Checked] | str | None:
    with ctx.db.writing() as session:
        participant, plan = _current_plan(session, ctx, request)
        if participant.status != "started" or plan is None:
            return None
        if step < participant.step:  # already answered: a double click or the back button; keep the first
            saved = session.scalar(SAVED_ANSWERS, {"participant": participant.id, "step": step})
            sent = check_screen(ctx.study, plan[step], form)
            return KEPT if saved is not None and not sent.errors and sent.answers != saved else None
        if step > participant.step:
            raise HTTPException(409, "That page is not open yet. Please continue where you left off.")
        screen = plan[step]
        checked = check_screen(ctx.study, screen, form)
        now = datetime.now(UTC)
        fast = request.session.get("fast") is True and participant.kind in ("pilot", "bot")
        if shows_clip(screen) and ctx.study.study.require_full_view and not fast and "video" not in checked.errors:
            problem = _viewing_problem(screen, participant.step_started_at, now)
            if problem:
                checked.errors["video"] = problem
        if checked.errors:
            if any(name.startswith("understand") for name in checked.errors):
                details = dict(session.scalar(DETAILS, {"participant": participant.id}) or {})
                details["comprehension_attempts"] = details.get("comprehension_attempts", 0) + 1
                session.execute(SAVE_DETAILS, {"participant": participant.id, "details": details})
            return screen, checked
        if isinstance(screen, Instructions) and ctx.study.comprehension:
            details = dict(session.scalar(DETAILS, {"participant": participant.id}) or {})
            details["comprehension_attempts"] = details.get("comprehension_attempts", 0) + 1
            session.execute(SAVE_DETAILS, {"participant": participant.id, "details": details})
        viewport = _one_value(form, "viewport")
        session.execute(
            SAVE_RESPONSE,
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
                "details": {"viewport": viewport} if viewport and VIEWPORT.match(viewport) else None,
            },
        )
        done = step + 1 == len(plan)
        failed = isinstance(screen, Attention) and checked.answers["attention"] != screen.expected
        session.execute(
            NEXT_STEP,
            {
                "participant": participant.id,
                "to_step": step + 1,
                "now": now,
                "failed": int(failed),
                "to_status": "completed" if done else "started",
                "completed": now if done else None,
            },
        )
    return None


def _one_value(form: FormData, name: str) -> str:
    value = form.get(name)
    return value if isinstance(value, str) else ""


@router.post("/study")
def submit(request: Request, ctx: ContextDep, form: FormDep):
    step = form.get("step")
    if not isinstance(step, str) or not digits(step) or len(step) > 6:
        raise HTTPException(400, "The form is missing its step number; reload the page and try again.")
    refused = _save(ctx, request, int(step), form)
    if refused is None:
        return _see_current()
    if refused == KEPT:  # the session cookie holds only the step: the notice is built from the database
        request.session["kept"] = int(step)
        return _see_current()
    screen, checked = refused
    values = {name: form.getlist(name) for name in form.keys() if name != "csrf_token"}
    return _render_screen(
        request,
        ctx,
        screen,
        int(step),
        errors=checked.errors,
        values=values,
        events=str(form.get("video_events") or "")[:20000],
        status_code=422,
        watched=False if "video" in checked.errors else None,
    )


@router.post("/condition")
def choose_condition(request: Request, ctx: ContextDep, form: FormDep):
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
        if participant.status == "started" and participant.condition is None:
            participant.condition = int(number) - 1
            _assign_plan(ctx, participant)
    return _see_current()


@router.get("/leave")
def leave_confirm(request: Request, ctx: ContextDep):
    _read(_current, ctx, request)
    return ctx.render(request, "leave.html")


@router.post("/leave")
def leave(request: Request, ctx: ContextDep, form: FormDep):
    participant_id = _read(_current, ctx, request).id
    with ctx.db.writing() as session:
        participant = session.get(Participant, participant_id)
        if participant.status == "started":
            participant.status = "returned"
    return _see_current()
