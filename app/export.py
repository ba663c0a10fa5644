"""A simple long-format CSV of the answers (one row per question answered), for the admin's download.

Each row joins what the participant submitted with what their plan says was on the screen (agents behind the
labels, ground truth), so it can be scored without the bundle.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator

from sqlalchemy import select

from app.database import Database
from app.models import Participant, Response
from app.study import Study

COLUMNS = [
    "participant", "platform", "external_id", "status", "excluded", "condition", "step", "part", "kind",
    "progress", "clip", "scheme", "scenario", "robots", "question", "answer", "answer_agents", "correct",
    "time_on_page_ms", "server_ms", "plays", "submitted_at",
]
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _cell(value) -> str:
    """Text a spreadsheet would run as a formula gets a leading apostrophe."""
    text = "" if value is None else str(value)
    return "'" + text if text.startswith(FORMULA_START) else text


def _score(screen: dict, kind: str, value) -> tuple[str, str]:
    """(agents behind the answer, "1"/"0" correct or "" when there is no right answer)."""
    agent_of = {robot["label"]: robot["agent"] for robot in screen.get("robots", [])}
    if kind == "attention":
        return "", str(int(value == screen["expected"]))
    if kind == "choose":
        return agent_of[value], str(int(agent_of[value] == screen["better"]))
    if kind == "rank":
        agents = [agent_of[label] for label in value]
        truth = screen.get("true_order")
        return " > ".join(agents), "" if truth is None else str(int(agents == truth))
    return "", ""


def answer_rows(study: Study, participant: Participant, response: Response) -> list[dict]:
    """The rows of one submitted screen: one per answer, or one without a question for a screen that has none."""
    kinds = {name: question.type for name, question in study.questions.items()} | {"attention": "attention"}
    screen = participant.plan[response.step]
    common = {
        "participant": participant.code, "platform": participant.platform, "external_id": participant.external_id,
        "status": participant.status, "excluded": int(participant.excluded),
        "condition": None if participant.condition is None else participant.condition + 1,
        "step": response.step, "part": screen.get("part"), "kind": response.kind,
        "progress": screen.get("progress"), "clip": screen.get("clip") or " ".join(screen.get("clips", [])),
        "scheme": screen.get("scheme"), "scenario": screen.get("scenario"),
        "robots": "; ".join(f"{r['label']}={r['agent']}" for r in screen.get("robots", [])),
        "time_on_page_ms": response.client_ms, "server_ms": response.server_ms, "plays": response.plays,
        "submitted_at": response.submitted_at.isoformat(),
    }
    rows = []
    for question, value in (response.answers or {"": None}).items():
        agents, correct = _score(screen, kinds.get(question, ""), value)
        shown = " > ".join(value) if isinstance(value, list) else value
        rows.append(common | {"question": question, "answer": shown, "answer_agents": agents, "correct": correct})
    return rows


def csv_lines(db: Database, study: Study) -> Iterator[str]:
    """The CSV, a line at a time, reading the database in batches so large studies stream in constant memory."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS)

    def flush() -> str:
        text = buffer.getvalue()
        buffer.seek(0)
        buffer.truncate()
        return text

    writer.writeheader()
    yield flush()
    query = (
        select(Participant, Response).join(Response, Response.participant_id == Participant.id)
        .where(Participant.study == study.study.id).order_by(Participant.id, Response.step)
        .execution_options(yield_per=200)
    )
    with db.reading() as session:
        for participant, response in session.execute(query):
            for row in answer_rows(study, participant, response):
                writer.writerow({key: _cell(value) for key, value in row.items()})
            yield flush()
