"""A flood of arrivals: new participants are limited per client address, at a rate that a lab whose participants
all start at once behind one address still passes, the admin overview reads one page of participants, however
many there are, and a participant's page and answer take few statements (round trips, on PostgreSQL)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import event

from app.store.models import Participant
from app.survey.kinds import pilot_token
from tests.support.survey import FormReader, log_in, stored

ANONYMOUS = {"platform": '"none"', "assignment": '"balanced"'}


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def consent(client: TestClient, address: str, query: str = ""):
    person = TestClient(client.app, client=(address, 50000), raise_server_exceptions=False)
    token = FormReader(person.get(f"/{query}").text).hidden["csrf_token"]
    return person.post("/consent", data={"csrf_token": token, "choice": "agree"}, follow_redirects=False)


def test_a_lab_behind_one_address_starts_together(make_client):
    client = make_client(ANONYMOUS)
    replies = [consent(client, "192.0.2.10").status_code for _ in range(100)]
    assert replies == [303] * 100 and len(stored(client, Participant)) == 100


def test_a_flood_of_arrivals_from_one_address_is_held_to_the_refill_rate(make_client):
    client = make_client(ANONYMOUS, arrivals_burst=5, arrivals_per_minute=30)
    clock = client.app.state.arrivals.clock = Clock()
    assert [consent(client, "198.51.100.1").status_code for _ in range(5)] == [303] * 5
    refused = consent(client, "198.51.100.1")
    assert refused.status_code == 429 and refused.headers["retry-after"] == "2"
    assert "<h1>" in refused.text and "wait 2 seconds" in refused.text
    assert refused.headers["x-content-type-options"] == "nosniff"
    assert len(stored(client, Participant)) == 5  # the refused arrival left no record
    assert consent(client, "203.0.113.5").status_code == 303  # others are not held up
    clock.now += 2
    assert consent(client, "198.51.100.1").status_code == 303  # refilled: one more
    assert consent(client, "198.51.100.1").status_code == 429
    # the researcher's pilot link (and `foil simulate` bots with it) is not held to the limit
    token = pilot_token(client.app.state.context.db, "paper")
    assert [consent(client, "198.51.100.1", f"?pilot={token}&bot=1").status_code for _ in range(8)] == [303] * 8
    assert consent(client, "198.51.100.1", "?bot=1").status_code == 429  # a bot link without the token is held


def test_addresses_of_one_ipv6_64_share_one_allowance(make_client):
    """A machine may hold every address of its /64: taking a new one per arrival gets no more arrivals than one
    address does; the next /64 is another client."""
    client = make_client(ANONYMOUS, arrivals_burst=3, arrivals_per_minute=1)
    client.app.state.arrivals.clock = Clock()
    replies = [consent(client, f"2001:db8:5:7::{n:x}").status_code for n in range(1, 5)]
    assert replies == [303, 303, 303, 429]
    assert consent(client, "2001:db8:5:8::1").status_code == 303


@pytest.mark.parametrize("status", ["", "started", "real"])
def test_the_admin_overview_loads_one_page_of_participants(make_client, status):
    client = make_client(ANONYMOUS)
    for n in range(60):
        consent(client, f"10.0.0.{n}")
    log_in(client)
    loaded = []
    listener = lambda target, _context: loaded.append(target.id)  # noqa: E731
    event.listen(Participant, "load", listener)
    try:
        first = client.get(f"/admin?status={status}")
        second = client.get(f"/admin?status={status}&page=2")
    finally:
        event.remove(Participant, "load", listener)
    assert first.status_code == second.status_code == 200
    assert len(loaded) == 60  # 50 on the first page, 10 on the second: never all of them for one page
    assert "60 participants, page 1 of 2" in first.text and "page 2 of 2" in second.text
    assert "<td>60</td><td>0</td><td>0</td><td>0</td>" in first.text.split("<tfoot>")[1]
    newest = max(stored(client, Participant), key=lambda p: p.id).code
    assert newest[:10] in first.text and newest[:10] not in second.text


def test_a_page_and_an_answer_cost_few_statements(make_client):
    """Every statement is a round trip to PostgreSQL, and under load each wait costs milliseconds (BENCHMARKS.md):
    a participant's page is one statement, an answer three (read, insert, update), besides BEGIN and COMMIT."""
    from sqlalchemy import event as events

    from tests.support.survey import answer_for, start

    client = make_client(ANONYMOUS)
    page = start(client)
    statements: list[str] = []
    engine = client.app.state.context.db.engine
    listener = lambda _c, _cursor, statement, *_rest: statements.append(statement.split()[0])  # noqa: E731
    events.listen(engine, "before_cursor_execute", listener)
    try:
        client.get("/study")
        shown = list(statements)
        statements.clear()
        client.post("/study", data=answer_for(page), follow_redirects=False)
        answered = list(statements)
    finally:
        events.remove(engine, "before_cursor_execute", listener)
    assert shown == ["SELECT"]
    assert answered == ["SELECT", "INSERT", "UPDATE"]
