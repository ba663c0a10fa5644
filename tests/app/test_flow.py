"""Whole participant sessions through the real HTTP flow, for every design and platform."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from app.models import Participant, Response
from tests.app.conftest import SECRET_NAMES, FormReader, answer_for, finish, start


def participants(client):
    with client.app.state.context.db.reading() as session:
        return list(session.scalars(select(Participant).order_by(Participant.id)))


def response_count(client) -> int:
    with client.app.state.context.db.reading() as session:
        return session.scalar(select(func.count()).select_from(Response))


def test_paper_study_whole_session(make_client):
    client = make_client({"platform": '"mturk"'})
    page = start(client, "?workerId=W1&assignmentId=A1&hitId=H1")
    assert "Pick any number from 1 to 4" in page
    seen = [page]
    for _ in range(40):
        form = FormReader(page)
        if "step" not in form.hidden and "number" not in form.radios:
            break
        if "number" in form.radios:
            page = client.post("/condition", data={"csrf_token": form.hidden["csrf_token"], "number": "3"}).text
        else:
            page = client.post("/study", data=answer_for(page)).text
        seen.append(page)
    assert "FOIL-PAPER-7Q2K" in page
    (person,) = participants(client)
    assert person.status == "completed" and person.condition == 2
    assert person.external_id == "W1" and person.platform_session_id == "A1" and person.platform_study_id == "H1"
    kinds = [screen["kind"] for screen in person.plan]
    # instructions, 6 pairwise clips, then per scheme 3 clips and a ranking
    assert kinds == ["instructions"] + ["pairwise"] * 6 + (["watch"] * 3 + ["ranking"]) * 2
    assert response_count(client) == len(person.plan)
    progress = " ".join(seen)
    assert "Part 1 of 2, clip 3 of 6" in progress and "Part 2 of 2, ranking 2 of 2" in progress
    for page in seen:  # ground truth and real names never reach the browser
        for secret in SECRET_NAMES.values():
            assert secret not in page
