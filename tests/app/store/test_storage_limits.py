"""What both databases must store alike: durations beyond 32 bits, and text with characters PostgreSQL refuses in a
text column (NUL). Every test runs on a SQLite file and on a real PostgreSQL server."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from fastapi.testclient import TestClient
from sqlalchemy import update

from app.store.models import Participant, Response
from tests.support.survey import FormReader, answer_for, log_in, start, stored

PILOT = {"platform": '"none"', "assignment": '"balanced"'}


def test_a_screen_left_open_for_weeks_is_saved(make_client):
    """A returning participant's screen may have been current for longer than 2**31 ms (24.8 days)."""
    client = make_client(PILOT)
    page = start(client)
    (person,) = stored(client, Participant)
    weeks_ago = datetime.now(UTC) - timedelta(days=30)
    with client.app.state.context.db.writing() as session:
        session.execute(update(Participant).where(Participant.id == person.id).values(step_started_at=weeks_ago))
    response = client.post("/study", data=answer_for(page))
    assert response.status_code == 200 and 'name="step" value="1"' in response.text
    (saved,) = stored(client, Response)
    assert saved.server_ms >= 30 * 24 * 3600 * 1000 > 2**31


def test_a_nul_in_the_exclusion_note_is_refused_with_a_message(make_client):
    client = make_client(PILOT)
    start(TestClient(client.app))
    (person,) = stored(client, Participant)
    log_in(client)
    token = FormReader(client.get(f"/admin/participants/{person.code}").text).hidden["csrf_token"]
    url = f"/admin/participants/{person.code}/exclusion"
    assert client.post(url, data={"csrf_token": token, "excluded": "1", "note": "first note"}).status_code == 200
    refused = client.post(url, data={"csrf_token": token, "excluded": "0", "note": "bad\x00note"})
    assert refused.status_code == 400 and "NUL" in refused.text
    (person,) = stored(client, Participant)
    assert person.excluded and person.exclusion_note == "first note"  # what was saved is kept


def test_a_nul_in_an_answer_is_stored_exactly(make_client):
    """Answers live in JSON columns, which hold any character escaped (PostgreSQL's json too)."""
    client = make_client(PILOT)
    page = client.post("/study", data=answer_for(start(client))).text
    typed = "before\x00after \u202e and a lone-looking \ufffd"
    response = client.post("/study", data={**answer_for(page), "justification": typed})
    assert response.status_code == 200 and 'name="step" value="2"' in response.text
    assert stored(client, Response)[-1].answers["justification"] == typed
