"""The study's data as typed rows: one per answer (long), one per participant (wide), read from the database in
batches of participants so that any study streams through in constant memory.

A row joins what a participant submitted with what their plan says was on the screen: the real agents behind
the on-screen labels and the ground truth, so answers can be scored without the bundle. Question types, scale
points and texts come from the study definition, which the database itself does not hold.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, cast

from sqlalchemy import Row, select

from app.analysis.exclusions import duration_s, viewing_problems
from app.store.database import Database, as_utc
from app.store.models import Participant, ParticipantPlan, Response
from app.survey.assignment import Condition
from app.survey.screens import (
    Attention,
    Closing,
    InPart,
    Option,
    Pairwise,
    Ranking,
    Round,
    Screen,
    Watch,
    WithOptions,
    parse_plan,
    shows_clip,
)
from app.survey.study import FEEDBACK, NO_DIFFERENCE, PairwisePart, Study

LIST_SEPARATOR = ";"  # between the agents (or labels) of a screen
ORDER_SEPARATOR = ">"  # between the places of a ranking, best first


@dataclass(frozen=True)
class Column:
    name: str
    dtype: str  # string | Int64 | Float64 | datetime: what pandas should read it as
    description: str


@dataclass
class ParticipantRecord:
    participant: Row[Any]  # the participant table's columns and the plan, as attributes
    responses: list[Row[Any]]  # the response table's columns, ordered by step
    plan: list[Screen] = field(init=False)  # the participant's plan, parsed once

    def __post_init__(self) -> None:
        self.plan = parse_plan(self.participant.plan or [])


def participant_records(db: Database, study_id: str, batch: int = 500) -> Iterator[ParticipantRecord]:
    """Every participant of the study with their responses, in id order; at most `batch` in memory at a time.

    Pages by participant id (keyset), so each batch is one query for participants and one for their responses.
    Reads plain rows rather than ORM objects: the export is read-only and this is several times faster."""
    people, answers, plans = Participant.__table__, Response.__table__, ParticipantPlan.__table__
    last_id = 0
    while True:
        with db.reading() as session:
            participants = session.execute(
                select(people, plans.c.plan)
                .outerjoin(plans, plans.c.participant_id == people.c.id)
                .where(people.c.study == study_id, people.c.id > last_id)
                .order_by(people.c.id)
                .limit(batch)
            ).all()
            if not participants:
                return
            responses: dict[int, list[Row[Any]]] = {p.id: [] for p in participants}
            query = (
                select(answers)
                .where(answers.c.participant_id.in_(list(responses)))
                .order_by(answers.c.participant_id, answers.c.step)
            )
            for response in session.execute(query):
                responses[response.participant_id].append(response)
        for participant in participants:
            yield ParticipantRecord(participant, responses[participant.id])
        last_id = participants[-1].id


def iso_utc(moment: datetime | None) -> str | None:
    """ISO 8601 in UTC with a Z, to the millisecond: what pandas, R and spreadsheets all parse."""
    if moment is None:
        return None
    return as_utc(moment).astimezone(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


# Long format ---------------------------------------------------------------------------------------------------

LONG_COLUMNS = [
    Column("study", "string", "study id (the [study] id of the study file)"),
    Column("participant", "string", "participant code, the same in every file"),
    Column("condition", "Int64", "condition number, 1-based (see `conditions` in the codebook)"),
    Column("step", "Int64", "index of the screen in the participant's plan (0 is the instructions)"),
    Column("part", "Int64", "part of the study, 1-based; empty for the instructions"),
    Column(
        "screen",
        "string",
        "kind of screen: instructions, pairwise, watch, ranking, attention or closing (the "
        "closing questions and feedback box after the last part)",
    ),
    Column("trial", "Int64", "position of the screen within its part, 1-based, in the order it was shown"),
    Column("block", "Int64", "in a ranking part: which of the participant's ranking blocks (1 = first shown)"),
    Column("clip", "string", "clip id in the bundle; on a ranking screen, the clips of its block"),
    Column("scheme", "string", "scheme that generated the clip (e.g. adaptive, nfirst)"),
    Column("scenario", "string", "scenario of the clip"),
    Column(
        "agents",
        "string",
        f"real agents on the screen, '{LIST_SEPARATOR}'-separated, in the order the {{agents}} were offered as answers",
    ),
    Column("labels", "string", "their on-screen labels (e.g. {Agent} 1), in the same order as `agents`"),
    Column(
        "question",
        "string",
        "question name from the study file; 'attention' for an attention check; "
        f"'{FEEDBACK}' for the closing feedback box; empty on a screen without questions",
    ),
    Column(
        "question_type",
        "string",
        "choose, text, scale, rank, choice, attention or comprehension (a check "
        "question of the instructions); empty without a question",
    ),
    Column(
        "answer",
        "string",
        "what was submitted: the {agent} label chosen, the option chosen, the text, the scale "
        f"point, or the ranking's labels best first joined by '{ORDER_SEPARATOR}'; an "
        "optional closing question left unanswered has no row",
    ),
    Column("answer_agent", "string", "the real agent behind a chosen label; for a ranking, the agents best first"),
    Column("value", "Int64", "the scale point (1 to the number of points) for a scale question"),
    Column(
        "truth",
        "string",
        "the right answer: the better agent, the true order best first, or the expected "
        "attention-check option; empty when there is none",
    ),
    Column("correct", "Int64", "1 when the answer equals `truth`, 0 when not, empty when there is no right answer"),
    Column("time_on_page_ms", "Int64", "time on the page measured by the browser, in ms"),
    Column("server_ms", "Int64", "time from the screen becoming current to its submission, measured by the server"),
    Column(
        "plays",
        "Int64",
        "how often the clip was started (1 = watched once, no replay; a pair of reels: each reel's starts added up), "
        "across reloads",
    ),
    Column(
        "clip_ms",
        "Int64",
        "the clip's playing time in ms (from its file; a pair of reels: both together); time_on_screen_ms should "
        "exceed it",
    ),
    Column("time_on_screen_ms", "Int64", "time the screen was current before it was answered (server clock, ms)"),
    Column("seeks", "Int64", "seeks within the clip (allowed once it had been watched to the end)"),
    Column("seeks_blocked", "Int64", "seeks forward on the first viewing, undone by the page"),
    Column("rate_changes", "Int64", "playback rate changes (undone by the page on a first viewing)"),
    Column("hidden_ms", "Int64", "time the tab was hidden while the screen was open (browser clock, ms)"),
    Column("reloads", "Int64", "reloads of the screen (the events before them were kept)"),
    Column(
        "skipped_viewing",
        "Int64",
        "1 when answered sooner than the clip plays, sped up before its end, never played, or its record ends it "
        "before it plays",
    ),
    Column("viewport", "string", "the browser window's size when the screen was sent, WIDTHxHEIGHT in CSS px"),
    Column("submitted_at", "datetime", "when the screen was submitted (UTC)"),
]


# long.csv's columns of a study of updates (`[design] updates`), after the others; other studies' files have none
UPDATE_COLUMNS = [
    Column("later", "string", "on an update pair: its later version (the agent); empty on other screens"),
    Column(
        "update",
        "string",
        "on an update pair: what the ground truth says of the update: better, worse or equal (the truth cannot "
        "tell the two apart, or the study holds them to be a control)",
    ),
    Column("later_first", "Int64", "on an update pair: 1 when the later version was offered first, 0 when second"),
    Column(
        "called",
        "string",
        f"a compare answer on an update pair: later or earlier (the version it calls better) or {NO_DIFFERENCE}",
    ),
]


def long_columns(study: Study) -> list[Column]:
    """long.csv's columns: a study of updates has UPDATE_COLUMNS besides."""
    return LONG_COLUMNS + (UPDATE_COLUMNS if study.design.updates else [])


def _options(screen: Screen | None) -> list[Option]:
    return [] if screen is None else screen.offered()


def _scored(question_type: str, value: Any, screen: Screen | None) -> dict[str, Any]:
    """answer, answer_agent, value, truth and correct of one submitted value."""
    agent_of = {option.label: option.agent for option in _options(screen)}
    if question_type == "choose":
        agent = agent_of.get(value)
        better = screen.better if isinstance(screen, Pairwise | Watch) else None
        return {
            "answer": value,
            "answer_agent": agent,
            "truth": better,
            "correct": None if agent is None else int(agent == better),
        }
    if question_type == "compare":
        return _compared(value, agent_of, screen)
    if question_type == "rank":
        agents = [agent_of.get(label) for label in value]
        truth = screen.true_order if isinstance(screen, Ranking) else None
        return {
            "answer": ORDER_SEPARATOR.join(value),
            "answer_agent": None if None in agents else ORDER_SEPARATOR.join(cast(list[str], agents)),
            "truth": None if truth is None else ORDER_SEPARATOR.join(truth),
            "correct": None if truth is None or None in agents else int(agents == truth),
        }
    if question_type == "scale":
        return {"answer": str(value), "value": int(value)}
    if question_type == "attention" and isinstance(screen, Attention):
        return {"answer": value, "truth": screen.expected, "correct": int(value == screen.expected)}
    return {"answer": value if isinstance(value, str) else str(value)}


def _compared(value: Any, agent_of: dict[str, str], screen: Screen | None) -> dict[str, Any]:
    """A compare answer scored: right when it names the better agent or, on an equal pair, no difference; on an
    update pair also which version it calls better."""
    agent = NO_DIFFERENCE if value == NO_DIFFERENCE else agent_of.get(value)
    if not isinstance(screen, Pairwise):
        return {"answer": value, "answer_agent": agent}
    truth = NO_DIFFERENCE if screen.equal else screen.better
    scored = {
        "answer": value,
        "answer_agent": agent,
        "truth": truth,
        "correct": None if agent is None else int(agent == truth),
    }
    if screen.later is not None:
        version = {option.agent: "earlier" for option in screen.robots} | {screen.later: "later"}
        scored |= {
            "later": screen.later,
            "update": screen.update(),
            "later_first": int(screen.robots[0].agent == screen.later),
            "called": version.get(agent or "", NO_DIFFERENCE if agent else None),
        }
    return scored


def _clips(screen: Screen | None) -> str | None:
    """The screen's clip id; a ranking's, the clips of its round."""
    return None if screen is None else LIST_SEPARATOR.join(screen.clip_names()) or None


def _trials(plan: list[Screen]) -> list[int | None]:
    """Each screen's 1-based position within its part."""
    seen: dict[int, int] = {}
    out: list[int | None] = []
    for screen in plan:
        if isinstance(screen, InPart):
            seen[screen.part] = seen.get(screen.part, 0) + 1
            out.append(seen[screen.part])
        else:
            out.append(None)
    return out


def long_rows(study: Study, record: ParticipantRecord) -> Iterator[dict[str, Any]]:
    """One row per answered question; a screen without questions gives one row with an empty question."""
    participant = record.participant
    plan = record.plan
    trials = _trials(plan)
    types = {name: question.type for name, question in study.questions.items()} | {"attention": "attention"}
    types[FEEDBACK] = types.get(FEEDBACK, "text")
    checks = {f"understand{n}": check for n, check in enumerate(study.comprehension, start=1)}
    types |= dict.fromkeys(checks, "comprehension")
    for response in record.responses:
        screen = plan[response.step] if response.step < len(plan) else None
        options = _options(screen)
        scheme, scenario = (screen.scheme, screen.scenario) if isinstance(screen, WithOptions) else (None, None)
        common = {
            "study": participant.study,
            "participant": participant.code,
            "condition": None if participant.condition is None else participant.condition + 1,
            "step": response.step,
            "part": screen.part if isinstance(screen, InPart) else None,
            "screen": response.kind,
            "trial": trials[response.step] if response.step < len(trials) else None,
            "block": screen.block if isinstance(screen, Round) else None,
            "clip": _clips(screen),
            "scheme": scheme,
            "scenario": scenario,
            "agents": LIST_SEPARATOR.join(option.agent for option in options) or None,
            "labels": LIST_SEPARATOR.join(option.label for option in options) or None,
            "time_on_page_ms": response.client_ms,
            "server_ms": response.server_ms,
            "plays": response.plays,
            "submitted_at": iso_utc(response.submitted_at),
            "viewport": (getattr(response, "details", None) or {}).get("viewport"),
        }
        if screen is not None and shows_clip(screen):
            viewing = viewing_problems(response, screen)
            common |= {
                "clip_ms": viewing["clip_ms"],
                "time_on_screen_ms": response.server_ms,
                "seeks": viewing["seeks"],
                "seeks_blocked": viewing["seeks_blocked"],
                "rate_changes": viewing["rate_changes"],
                "hidden_ms": viewing["hidden_ms"],
                "reloads": viewing["reloads"],
                "skipped_viewing": int(viewing["skipped"]),
            }
        answers = response.answers or {}
        if not answers:
            yield common
        for question, value in answers.items():
            question_type = types.get(question, "unknown")
            scored = _scored(question_type, value, screen)
            if question in checks:  # only a right answer is ever saved; the truth says which it was
                scored |= {"truth": checks[question].expected, "correct": int(value == checks[question].expected)}
            yield common | {"question": question, "question_type": question_type} | scored


# Participants ------------------------------------------------------------------------------------------------

PARTICIPANT_COLUMNS = [
    Column("study", "string", "study id"),
    Column("participant", "string", "participant code, the same in every file"),
    Column("platform", "string", "recruitment platform: prolific, mturk or none"),
    Column("kind", "string", "real, pilot (the admin's preview link) or bot (foil simulate)"),
    Column("consent_version", "string", "version of the consent text the participant agreed to"),
    Column("external_id", "string", "PROLIFIC_PID or MTurk workerId; empty when anonymous"),
    Column("platform_study_id", "string", "Prolific STUDY_ID or MTurk hitId"),
    Column("platform_session_id", "string", "Prolific SESSION_ID or MTurk assignmentId"),
    Column("status", "string", "started, completed, returned (left the study) or declined (no consent)"),
    Column("condition", "Int64", "condition number, 1-based; empty before assignment"),
    Column(
        "schemes",
        "string",
        "the schemes of the participant's condition, in the condition's order (the "
        "codebook's `conditions`; with clips shuffled within a part they are mixed, blocked "
        f"they come in this order), '{LIST_SEPARATOR}'-separated; empty before assignment",
    ),
    Column("scenarios", "string", f"scenario of each part, part 1 first, '{LIST_SEPARATOR}'-separated"),
    Column("slot", "Int64", "arrival number used by balanced assignment; empty when self-selected"),
    Column("created_at", "datetime", "consent given (UTC)"),
    Column("completed_at", "datetime", "last screen submitted (UTC); empty when not completed"),
    Column("duration_s", "Float64", "completed_at - created_at, in seconds"),
    Column("screens", "Int64", "screens in the participant's plan"),
    Column("screens_answered", "Int64", "screens submitted"),
    Column("attention_failures", "Int64", "attention checks answered wrongly"),
    Column("exclusion_note", "string", "the admin's note on the exclusion flag"),
    Column("pilot_or_bot", "Int64", "1 for a pilot or bot (left out of the analysis unless included)"),
    Column("incomplete", "Int64", "1 when the participant did not complete the study"),
    Column("failed_attention", "Int64", "1 when at least one attention check was failed"),
    Column("too_fast", "Int64", "1 when completed faster than the threshold (see `exclusion_rules`)"),
    Column("flagged_by_admin", "Int64", "1 when flagged for exclusion on the admin pages"),
    Column(
        "skipped_viewing",
        "Int64",
        "1 when any clip was answered sooner than it plays, sped up before its end, never played, or its record "
        "ends it before it plays",
    ),
    Column("excluded", "Int64", "1 when any exclusion rule applies: the report leaves the participant out"),
    Column("user_agent", "string", "the browser's User-Agent at consent"),
]


def part_scenarios(plan: list[Screen]) -> list[str]:
    by_part = {screen.part: screen.scenario for screen in plan if isinstance(screen, WithOptions)}
    return [by_part[part] for part in sorted(by_part)]


def participant_row(record: ParticipantRecord, flags: dict[str, bool], conditions: list[Condition]) -> dict[str, Any]:
    p = record.participant
    plan = record.plan
    duration = duration_s(p)
    return {
        "study": p.study,
        "participant": p.code,
        "platform": p.platform,
        "external_id": p.external_id,
        "kind": getattr(p, "kind", None) or "real",
        "consent_version": getattr(p, "consent_version", None) or None,
        "platform_study_id": p.platform_study_id,
        "platform_session_id": p.platform_session_id,
        "status": p.status,
        "condition": None if p.condition is None else p.condition + 1,
        "schemes": None if p.condition is None else LIST_SEPARATOR.join(conditions[p.condition].schemes),
        "scenarios": LIST_SEPARATOR.join(part_scenarios(plan)) or None,
        "slot": p.slot,
        "created_at": iso_utc(p.created_at),
        "completed_at": iso_utc(p.completed_at),
        "duration_s": None if duration is None else round(duration, 3),
        "screens": len(plan),
        "screens_answered": len(record.responses),
        "attention_failures": p.attention_failures,
        "exclusion_note": p.exclusion_note or None,
        "user_agent": p.user_agent or None,
        **{name: int(flag) for name, flag in flags.items()},
    }


# Wide format -------------------------------------------------------------------------------------------------

WIDE_LEAD = ["study", "participant", "condition", "status", "excluded", "duration_s"]


@functools.cache
def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_").lower() or "x"


def _answer_columns(question: str, kind: str, prefix: str, what: str) -> list[Column]:
    dtype = {"scale": "Int64"}.get(kind, "string")
    meaning = {
        "choose": "the agent chosen",
        "compare": f"the agent chosen as better, or {NO_DIFFERENCE}",
        "rank": f"the agents ranked, best first, joined by '{ORDER_SEPARATOR}'",
        "scale": "the scale point",
        "text": "the text written",
        "choice": "the option chosen",
    }[kind]
    columns = [Column(f"{prefix}_{question}", dtype, f"{what}, question {question}: {meaning}")]
    if kind in ("choose", "compare", "rank"):
        columns.append(Column(f"{prefix}_{question}_correct", "Int64", f"{what}, question {question}: 1 if right"))
    return columns


class WideLayout:
    """The wide file's columns, fixed by the study definition alone (so every export of a study has the same
    header), and where each answer goes: pairwise answers by part, scheme and pair; ranking answers by part
    and scheme; attention checks by number. Screen order and labels, which vary per participant, are not in
    the names."""

    def __init__(self, study: Study) -> None:
        self.columns: list[Column] = [c for c in PARTICIPANT_COLUMNS if c.name in WIDE_LEAD]
        self.columns.sort(key=lambda c: WIDE_LEAD.index(c.name))
        self._pairs: dict[tuple[int, frozenset[str]], str] = {}
        for p, part in enumerate(study.parts, start=1):
            self.columns.append(Column(f"p{p}_scenario", "string", f"part {p}: its scenario for this participant"))
            for scheme in study.design.schemes:
                if isinstance(part, PairwisePart):
                    for a, b in part.pairs:
                        self._pairs[(p, frozenset((a, b)))] = f"{_slug(a)}_{_slug(b)}"
                        for name in part.questions:
                            self.columns += _answer_columns(
                                name,
                                study.questions[name].type,
                                f"p{p}_{_slug(scheme)}_{_slug(a)}_{_slug(b)}",
                                f"part {p}, scheme {scheme}, clip of {a} and {b}",
                            )
                else:
                    what = f"part {p}, scheme {scheme}, ranking of {', '.join(part.agents)}"
                    for name in part.questions:
                        self.columns += _answer_columns(name, study.questions[name].type, f"p{p}_{_slug(scheme)}", what)
        for c in range(1, len(study.attention_checks) + 1):
            self.columns.append(Column(f"attention{c}", "string", f"attention check {c}: the option chosen"))
            self.columns.append(Column(f"attention{c}_passed", "Int64", f"attention check {c}: 1 if it was right"))
        if study.closing is not None:
            what = "closing screen (empty when not answered)"
            for name in study.closing.questions:
                self.columns += _answer_columns(name, study.questions[name].type, "closing", what)
            if study.closing.feedback:
                self.columns += _answer_columns(FEEDBACK, "text", "closing", what)
        names = [c.name for c in self.columns]
        if len(set(names)) != len(names):
            clashes = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"scheme, agent or question names give clashing column names {clashes}; rename them")
        self.names = set(names)

    def row(self, record: ParticipantRecord, long: list[dict[str, Any]], flags: dict[str, bool]) -> dict[str, Any]:
        p = record.participant
        duration = duration_s(p)
        row = {
            "study": p.study,
            "participant": p.code,
            "condition": None if p.condition is None else p.condition + 1,
            "status": p.status,
            "excluded": int(flags["excluded"]),
            "duration_s": None if duration is None else round(duration, 3),
        }
        for part, scenario in enumerate(part_scenarios(record.plan), start=1):
            row[f"p{part}_scenario"] = scenario
        for answer in long:
            if not answer.get("question"):
                continue
            screen = record.plan[answer["step"]]
            match screen:
                case Attention() if answer["question_type"] == "attention":
                    prefix = f"attention{screen.check + 1}"
                    row[prefix], row[f"{prefix}_passed"] = answer["answer"], answer["correct"]
                    continue
                case Closing():
                    key = f"closing_{answer['question']}"
                    if key in self.names:  # a closing screen the study file no longer asks is left out
                        row[key] = answer["value" if answer["question_type"] == "scale" else "answer"]
                    continue
                case Pairwise():
                    pair = self._pairs.get((screen.part, frozenset(r.agent for r in screen.robots)), "?")
                    prefix = f"p{screen.part}_{_slug(screen.scheme)}_{pair}"
                case Watch() | Ranking():
                    prefix = f"p{screen.part}_{_slug(screen.scheme)}"
                case _:  # the instructions' comprehension answers: no column (a wrong answer is never saved)
                    continue
            key = f"{prefix}_{answer['question']}"
            if key not in self.names:
                raise ValueError(
                    f"participant {p.code} answered {answer['question']!r} on a {screen.kind} screen "
                    f"of scheme {screen.scheme!r} that the study file does not define: is it the "
                    "study file the survey was served with?"
                )
            value_key = {
                "choose": "answer_agent",
                "compare": "answer_agent",
                "rank": "answer_agent",
                "scale": "value",
            }.get(answer["question_type"], "answer")
            row[key] = answer[value_key]
            if f"{key}_correct" in self.names:
                row[f"{key}_correct"] = answer["correct"]
        return row
