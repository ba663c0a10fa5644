"""Admin sessions end: logging out, or a restart with another FOIL_ADMIN_PASSWORD, invalidates every admin cookie
signed before, wherever it was captured. Password guessing is limited per client address and overall, with delays
that grow with every further failure, and every attempt is logged."""

from __future__ import annotations

import logging

import pytest
from fastapi.testclient import TestClient

from app.web.main import create_app
from app.web.settings import ServerSettings
from tests.support.survey import ADMIN_PASSWORD, FormReader, log_in

PILOT = {"platform": '"none"'}


class Clock:
    """Stands in for time.monotonic in the login throttle, so a test can let minutes pass at once."""

    def __init__(self):
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def admin_page(client: TestClient, cookie: str) -> int:
    other = TestClient(client.app, follow_redirects=False)
    other.cookies.set("foil_session", cookie)
    return other.get("/admin").status_code


def test_logout_invalidates_every_earlier_admin_cookie(make_client):
    client = make_client(PILOT)
    assert log_in(client).status_code == 200
    captured = client.cookies["foil_session"]
    second_browser = TestClient(client.app)
    assert log_in(second_browser).status_code == 200
    assert admin_page(client, captured) == 200
    token = FormReader(client.get("/admin").text).hidden["csrf_token"]
    assert client.post("/admin/logout", data={"csrf_token": token}).status_code == 200
    assert admin_page(client, captured) == 303  # to the login page
    assert second_browser.get("/admin", follow_redirects=False).status_code == 303
    assert log_in(client).status_code == 200 and client.get("/admin").status_code == 200  # a new login works


def test_a_changed_password_invalidates_earlier_admin_cookies(make_client, tmp_path, bundle_dir, database_url):
    client = make_client(PILOT)
    assert log_in(client).status_code == 200
    captured = client.cookies["foil_session"]
    settings = client.app.state.context.settings
    restarted = create_app(
        ServerSettings(
            bundle_dir=bundle_dir,
            study_file=settings.study_file,
            database_url=database_url,
            admin_password="a different admin password",
        )
    )
    try:
        after = TestClient(restarted, follow_redirects=False)
        after.cookies.set("foil_session", captured)  # the same cookie key (kept in the database)
        assert after.get("/admin").status_code == 303
        assert log_in(TestClient(restarted), "a different admin password").status_code == 200
    finally:
        restarted.state.context.db.dispose()


@pytest.mark.slow  # waits out the delays
def test_password_guessing_is_slowed_per_client_with_growing_delays(make_client, caplog):
    client = make_client(PILOT)
    clock = client.app.state.login_throttle.clock = Clock()
    guesser = TestClient(client.app, client=("198.51.100.7", 40000))
    token = FormReader(guesser.get("/admin/login").text).hidden["csrf_token"]
    caplog.set_level(logging.INFO, logger="foil.admin")
    statuses, waits = [], []
    for n in range(500):  # one connection, one token, as fast as it goes
        reply = guesser.post("/admin/login", data={"csrf_token": token, "password": f"guess {n}"})
        statuses.append(reply.status_code)
        if reply.status_code == 429:
            waits.append(int(reply.headers["retry-after"]))
            assert "Too many" in reply.text
    assert statuses[:5] == [401] * 5 and set(statuses[5:]) == {429}  # the password is no longer even checked
    # the right password is refused too while the delay runs
    right = guesser.post("/admin/login", data={"csrf_token": token, "password": ADMIN_PASSWORD})
    assert right.status_code == 429
    # every attempt is logged, with the client's address
    attempts = [r for r in caplog.records if r.name == "foil.admin" and "198.51.100.7" in r.getMessage()]
    assert len(attempts) == 501
    # others are not held up by one client's guessing
    assert log_in(TestClient(client.app, client=("203.0.113.9", 40000))).status_code == 200
    # after the delay, one more wrong password: the next delay is longer
    clock.now += waits[-1] + 1
    assert guesser.post("/admin/login", data={"csrf_token": token, "password": "again"}).status_code == 401
    longer = guesser.post("/admin/login", data={"csrf_token": token, "password": "again"})
    assert longer.status_code == 429 and int(longer.headers["retry-after"]) > waits[0]
    clock.now += 24 * 3600
    assert log_in(guesser).status_code == 200  # a day later: the right password works again


@pytest.mark.slow  # waits out the delays
def test_password_guessing_from_many_addresses_is_slowed_overall(make_client):
    client = make_client(PILOT)
    client.app.state.login_throttle.clock = Clock()
    refused = 0
    for n in range(300):  # a botnet: every address tries twice
        guesser = TestClient(client.app, client=(f"10.0.{n // 250}.{n % 250}", 40000))
        token = FormReader(guesser.get("/admin/login").text).hidden["csrf_token"]
        for attempt in range(2):
            reply = guesser.post("/admin/login", data={"csrf_token": token, "password": f"guess {n} {attempt}"})
            refused += reply.status_code == 429
    assert refused >= 250  # every address's second guess was never checked
    # The researcher, from an address that has not failed, is never locked out by the others' guessing.
    researcher = TestClient(client.app, client=("192.0.2.1", 40000))
    assert log_in(researcher).status_code == 200
    # A new address that guesses wrong gets its one guess checked, then waits for the overall delay.
    late = TestClient(client.app, client=("192.0.2.2", 40000))
    token = FormReader(late.get("/admin/login").text).hidden["csrf_token"]
    assert late.post("/admin/login", data={"csrf_token": token, "password": "late guess"}).status_code == 401
    assert late.post("/admin/login", data={"csrf_token": token, "password": ADMIN_PASSWORD}).status_code == 429
