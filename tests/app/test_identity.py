"""A platform id is not a password: it resumes a participant only together with the same platform study and
session ids (Prolific's STUDY_ID and SESSION_ID, MTurk's hitId and assignmentId), or with the participant's own
signed cookie. Anyone else gets the pages a new id gets, consent and its reply included, which say nothing about
whether the id took part: they start a record of their own and cannot answer, leave or otherwise touch the
participant's record, nor keep its owner out by arriving first."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from app.store.models import Participant, Response
from tests.support.survey import FormReader, answer_for, start, stored

PLATFORMS = {
    "prolific": (
        {"platform": '"prolific"', "assignment": '"balanced"'},
        "?PROLIFIC_PID={id}&STUDY_ID={study}&SESSION_ID={session}",
        "?PROLIFIC_PID={id}",
    ),
    "mturk": (
        {"platform": '"mturk"', "assignment": '"balanced"'},
        "?workerId={id}&hitId={study}&assignmentId={session}",
        "?workerId={id}",
    ),
}


def neutral(text: str) -> str:
    """A page without what differs between any two visitors (the session's CSRF token)."""
    return re.sub(r'name="csrf_token" value="[^"]*"', "", text)


@pytest.fixture(params=sorted(PLATFORMS))
def platform(request, make_client):
    changes, full, bare = PLATFORMS[request.param]
    client = make_client(changes)
    victim = TestClient(client.app)
    page = start(victim, full.format(id="VICTIM1", study="STUDY1", session="SESSION1"))
    victim.post("/study", data=answer_for(page))  # the victim is at their second screen
    return client, victim, full, bare


def stranger(client: TestClient) -> TestClient:
    return TestClient(client.app, follow_redirects=False, raise_server_exceptions=False)


def test_the_bare_platform_id_neither_resumes_nor_tells_whether_it_took_part(platform):
    client, victim, full, bare = platform
    known = stranger(client).get("/" + bare.format(id="VICTIM1"))
    unknown = stranger(client).get("/" + bare.format(id="NOBODY1"))
    assert known.status_code == unknown.status_code == 400
    assert "location" not in known.headers and neutral(known.text) == neutral(unknown.text)
    assert "STUDY_ID" in known.text or "hitId" in known.text  # it says what the link lacks


def consent_reply(client: TestClient, link: str) -> tuple[TestClient, object]:
    """A stranger's consent from `link`: their client and the consent's reply (not followed)."""
    person = stranger(client)
    token = FormReader(person.get(link).text).hidden["csrf_token"]
    return person, person.post("/consent", data={"csrf_token": token, "choice": "agree"})


def test_other_study_or_session_ids_do_not_take_the_participant_over(platform):
    client, victim, full, bare = platform
    victims = [(p.id, p.step, p.status) for p in stored(client, Participant)]
    responses = [(r.participant_id, r.step, r.answers) for r in stored(client, Response)]
    for n, (study, session) in enumerate([("STUDY1", "GUESSED"), ("GUESSED", "SESSION1"), ("OTHER", "OTHER")]):
        attacker = stranger(client)
        known = attacker.get("/" + full.format(id="VICTIM1", study=study, session=session))
        unknown = stranger(client).get("/" + full.format(id="NOBODY1", study=study, session=session))
        # the same consent page as any new id: no redirect into the victim's record
        assert known.status_code == unknown.status_code == 200 and "location" not in known.headers
        assert neutral(known.text) == neutral(unknown.text)
        # and the same reply to consent: a place of one's own, at the first screen
        attacker, agreed = consent_reply(client, "/" + full.format(id="VICTIM1", study=study, session=session))
        _, new = consent_reply(client, "/" + full.format(id=f"NOBODY{n}", study=study, session=session))
        assert agreed.status_code == new.status_code == 303
        assert agreed.headers["location"] == new.headers["location"] == "/study"
        first = attacker.get("/study")
        assert first.status_code == 200 and FormReader(first.text).hidden["step"] == "0"
        token = FormReader(first.text).hidden["csrf_token"]
        assert attacker.post("/leave", data={"csrf_token": token}).status_code == 303
    # the victim's record and answers are untouched; the attempts are records of their own, under the same id
    assert [(p.id, p.step, p.status) for p in stored(client, Participant)][:1] == victims
    assert [(r.participant_id, r.step, r.answers) for r in stored(client, Response)] == responses
    assert sum(p.external_id == "VICTIM1" for p in stored(client, Participant)) == 4


def test_an_id_used_first_by_someone_else_does_not_keep_its_owner_out(platform):
    client, victim, full, bare = platform
    squatter, _ = consent_reply(client, "/" + full.format(id="OWNER1", study="STUDY1", session="GUESSED"))
    owner = TestClient(client.app)
    page = start(owner, full.format(id="OWNER1", study="STUDY1", session="SESSION9"))
    assert FormReader(page).hidden["step"] == "0"
    records = [p for p in stored(client, Participant) if p.external_id == "OWNER1"]
    assert [p.platform_session_id for p in records] == ["GUESSED", "SESSION9"]


def test_the_participant_resumes_with_their_own_ids_or_their_own_cookie(platform):
    client, victim, full, bare = platform
    elsewhere = TestClient(client.app)  # another browser, the link from the platform again
    page = elsewhere.get("/" + full.format(id="VICTIM1", study="STUDY1", session="SESSION1"))
    assert FormReader(page.text).hidden["step"] == "1"
    again = victim.get("/" + full.format(id="VICTIM1", study="STUDY1", session="SESSION1"))
    assert FormReader(again.text).hidden["step"] == "1"
    assert len(stored(client, Participant)) == 1
