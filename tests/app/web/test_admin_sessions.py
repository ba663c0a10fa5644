"""Admin sessions end: logging out, or a restart with another FOIL_ADMIN_PASSWORD, invalidates every admin cookie
signed before, wherever it was captured. Password guessing is limited per client address and overall, with delays
that grow with every further failure, and every attempt is logged."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient
from httpx import Response
from uvicorn.middleware.proxy_headers import ProxyHeadersMiddleware

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
    researcher = TestClient(client.app, client=("192.0.2.1", 40000))
    assert log_in(researcher).status_code == 200  # before the guessing starts
    refused = 0
    for n in range(300):  # a botnet: every address tries twice
        guesser = TestClient(client.app, client=(f"10.0.{n // 250}.{n % 250}", 40000))
        token = FormReader(guesser.get("/admin/login").text).hidden["csrf_token"]
        for attempt in range(2):
            reply = guesser.post("/admin/login", data={"csrf_token": token, "password": f"guess {n} {attempt}"})
            refused += reply.status_code == 429
    assert refused == 600 - 100  # once 100 had been checked, no guess was
    # The researcher, from an address that has logged in before, is not locked out by the others' guessing.
    assert log_in(researcher).status_code == 200
    # A new address waits for the overall delay like the others: its guess is not checked.
    late = TestClient(client.app, client=("192.0.2.2", 40000))
    refused_late = log_in(late, "late guess")
    assert refused_late.status_code == 429 and int(refused_late.headers["retry-after"]) > 0


def forwarded_guesses(client: TestClient) -> Callable[..., Response]:
    """A password guess from any address, as `foil serve` sees it behind the reverse proxy on its machine: the
    proxy names the client in X-Forwarded-For, which uvicorn (proxy_headers, trusting 127.0.0.1 by default) makes
    the request's client address."""
    # uvicorn types an ASGI app its own way, Starlette its own
    behind_proxy: Any = ProxyHeadersMiddleware(client.app, trusted_hosts="127.0.0.1")  # type: ignore[arg-type]
    proxy = TestClient(behind_proxy, client=("127.0.0.1", 40000))
    token = FormReader(proxy.get("/admin/login").text).hidden["csrf_token"]

    def guess(address: str, password: str = "a guess") -> Response:
        return proxy.post(
            "/admin/login",
            data={"csrf_token": token, "password": password},
            headers={"x-forwarded-for": address},
            follow_redirects=False,
        )

    return guess


def ipv4(n: int) -> str:
    return f"10.{n // 65536}.{n // 256 % 256}.{n % 256}"


def test_a_pool_of_forwarded_addresses_gets_no_more_guesses_checked_than_the_overall_limit(make_client):
    client = make_client(PILOT, login_free_attempts_overall=20)
    clock = client.app.state.login_throttle.clock = Clock()
    assert log_in(TestClient(client.app, client=("192.0.2.1", 40000))).status_code == 200  # the researcher, earlier
    guess = forwarded_guesses(client)
    statuses = []
    for n in range(200):  # a new address for every guess, 10 guesses a second
        statuses.append(guess(ipv4(n)).status_code)
        clock.now += 0.1
    checked = statuses.count(401)
    assert statuses[:20] == [401] * 20 and checked <= 25 and statuses.count(429) == 200 - checked
    assert guess("192.0.2.2", ADMIN_PASSWORD).status_code == 429  # a new address waits too, whatever it sends
    assert guess("192.0.2.1", ADMIN_PASSWORD).status_code == 303  # the researcher's address logs in


def test_the_addresses_of_one_ipv6_network_are_one_client(make_client):
    client = make_client(PILOT)
    client.app.state.login_throttle.clock = Clock()
    guess = forwarded_guesses(client)
    statuses = [guess(f"2001:db8:5:7::{n:x}").status_code for n in range(1, 9)]  # one /64: one subscriber
    assert statuses == [401] * 5 + [429] * 3
    assert guess("2001:db8:5:8::1").status_code == 401  # the next /64 is another client


def test_a_full_table_of_clients_never_forgets_a_delayed_one(make_client):
    client = make_client(PILOT, login_free_attempts_overall=10**9)  # the per-client limit alone
    throttle = client.app.state.login_throttle
    clock = throttle.clock = Clock()
    pool = [ipv4(n) for n in range(throttle.MAX_CLIENTS)]
    for address in pool:  # every client of a full table delayed, as the login page counts wrong passwords
        for _ in range(throttle.free_per_client):
            throttle.failed(address)
    guess = forwarded_guesses(client)
    new = ipv4(throttle.MAX_CLIENTS)
    assert guess(new).status_code == 429  # a new client waits for room rather than pushing a delayed one out
    assert guess(pool[0]).status_code == 429  # the longest unseen is still remembered, still delayed
    clock.now += throttle.delay_s + 1  # their delays are over: the longest unseen makes room
    assert guess(new).status_code == 401
    assert len(throttle.clients) == throttle.MAX_CLIENTS and pool[0] not in throttle.clients
