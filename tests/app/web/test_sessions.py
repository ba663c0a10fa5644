"""The signed session cookie and the reading of forms: the cookie keeps the format of Starlette's
SessionMiddleware (itsdangerous's TimestampSigner), forged, altered or expired cookies start an empty session, and
forms over the limits are refused."""

from __future__ import annotations

import base64
import json
import time

import itsdangerous
import pytest

from tests.support.survey import FormReader, start

SECRET = "a secret for the session cookie tests"


def signed(session: dict, *, secret: str = SECRET, at: float | None = None) -> str:
    """A session cookie as Starlette's SessionMiddleware writes it, signed at time `at` (default now)."""

    class Signer(itsdangerous.TimestampSigner):
        def get_timestamp(self) -> int:
            return int(at if at is not None else time.time())

    return Signer(secret).sign(base64.b64encode(json.dumps(session).encode())).decode()


def read(cookie: str, *, max_age: int) -> dict:
    data = itsdangerous.TimestampSigner(SECRET).unsign(cookie.encode(), max_age=max_age)
    return json.loads(base64.b64decode(data))


@pytest.fixture
def client(make_client):
    return make_client({"platform": '"none"'}, secret_key=SECRET)


def consent_with(client, cookie: str | None, token: str):
    client.cookies.clear()
    if cookie is not None:
        client.cookies.set("foil_session", cookie)
    return client.post("/consent", data={"csrf_token": token, "choice": "agree"})


def test_the_cookie_is_the_format_starlette_and_itsdangerous_read(client):
    page = client.get("/")
    token = FormReader(page.text).hidden["csrf_token"]
    cookie = client.cookies["foil_session"]
    session = read(cookie, max_age=7 * 24 * 3600)
    assert session.keys() == {"csrf", "entering"} and session["csrf"] == token  # and the code consent will give
    assert "max-age=604800" in page.headers["set-cookie"].lower() and "path=/" in page.headers["set-cookie"].lower()
    # and a cookie written by Starlette's middleware with the same secret is a session here
    assert consent_with(client, signed({"csrf": "token-from-before"}), "token-from-before").status_code == 200


@pytest.mark.parametrize("forged", ["wrong secret", "altered", "expired", "from the future", "garbage"])
def test_forged_altered_or_expired_cookies_start_an_empty_session(client, forged):
    good = signed({"csrf": "the-token"})
    cookie = {
        "wrong secret": signed({"csrf": "the-token"}, secret="another secret"),
        "altered": signed({"csrf": "other-token"}).rsplit(".", 1)[0] + "." + good.rsplit(".", 1)[1],
        "expired": signed({"csrf": "the-token"}, at=time.time() - 7 * 24 * 3600 - 60),
        "from the future": signed({"csrf": "the-token"}, at=time.time() + 3600),
        "garbage": "not.a.cookie",
    }[forged]
    response = consent_with(client, cookie, "the-token")
    assert response.status_code == 403 and "did not come from this site" in response.text
    assert consent_with(client, good, "the-token").status_code == 200


def test_the_cookie_is_sent_only_when_the_session_changes(client):
    start(client)
    again = client.get("/study")
    assert again.status_code == 200 and "set-cookie" not in again.headers


def test_forms_over_the_limits_are_refused(client):
    token = FormReader(client.get("/").text).hidden["csrf_token"]
    many = {f"field{k}": "x" for k in range(70)} | {"csrf_token": token, "choice": "agree"}
    assert client.post("/consent", data=many).status_code == 400
    huge = {"csrf_token": token, "choice": "agree", "note": "x" * (33 * 1024)}
    assert client.post("/consent", data=huge).status_code == 400
    assert client.post("/consent", data={"csrf_token": token, "choice": "agree"}).status_code == 200
