"""Transport limits and replies: header size and count limits, requests that arrive too slowly cut off, a client
that leaves mid-request logged in one line, security headers on every reply (413 and 500 too), no reply built
from the Host header, and numbers in query strings checked. The server tests run `foil serve` itself."""

from __future__ import annotations

import socket
import time

import httpx
import pytest
from fastapi.testclient import TestClient

from tests.support.live_server import LiveServer
from tests.support.survey import FormReader, answer_for, log_in, study_text

PILOT = {"platform": '"none"'}
ONE_DATABASE = pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)  # nothing here is per database
SECURITY_HEADERS = (
    "content-security-policy",
    "x-content-type-options",
    "referrer-policy",
    "cache-control",
    "permissions-policy",
    "cross-origin-opener-policy",
    "x-frame-options",
)


def has_security_headers(headers) -> bool:
    return all(name in headers for name in SECURITY_HEADERS) and headers["x-content-type-options"] == "nosniff"


@ONE_DATABASE
def test_413_and_500_replies_carry_the_security_headers(make_client):
    client = make_client(PILOT)
    too_large = client.post(
        "/consent", content=b"x" * (65 * 1024), headers={"content-type": "application/x-www-form-urlencoded"}
    )
    assert too_large.status_code == 413 and has_security_headers(too_large.headers)

    def broken():
        raise RuntimeError("a bug")

    client.app.add_api_route("/broken", broken)  # a fault anywhere in the app
    failed = TestClient(client.app, raise_server_exceptions=False).get("/broken")
    assert failed.status_code == 500 and has_security_headers(failed.headers) and "a bug" not in failed.text


@ONE_DATABASE
def test_no_reply_takes_the_host_header(make_client):
    client = make_client(PILOT)
    for path in ("/admin/", "/study/", "/admin/login/"):
        reply = client.get(path, headers={"host": "evil.example"}, follow_redirects=False)
        assert "evil.example" not in reply.headers.get("location", "") and "evil.example" not in reply.text
    guarded = make_client(PILOT, allowed_hosts=["survey.example.org"])
    assert guarded.get("/", headers={"host": "evil.example"}).status_code == 400
    assert guarded.get("/", headers={"host": "survey.example.org"}).status_code == 200


@ONE_DATABASE
@pytest.mark.parametrize(
    "query",
    [
        "min_seconds=nan",
        "min_seconds=inf",
        "min_seconds=-1",
        "min_seconds=1e400",
        "median_fraction=nan",
        "median_fraction=-inf",
        "median_fraction=1.5",
        "min_seconds=ten",
    ],
)
def test_numbers_in_query_strings_are_finite_and_in_range(make_client, query):
    client = make_client(PILOT)
    log_in(client)
    for path in ("/admin/report", "/admin/export.zip"):
        reply = client.get(f"{path}?{query}")
        assert reply.status_code == 400 and query.split("=")[0] in reply.text, (path, reply.text[:300])
    assert client.get("/admin/report?min_seconds=90&median_fraction=0.25").status_code == 200


@pytest.fixture
def server(tmp_path, bundle_dir):
    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    live = LiveServer(
        bundle=bundle_dir,
        study=study,
        database_url=f"sqlite:///{tmp_path / 'survey.sqlite3'}",
        workdir=tmp_path,
        env={"FOIL_REQUEST_TIMEOUT_S": "1", "FOIL_ACCESS_LOG": "0"},
    )
    with live:
        yield live


def raw(server: LiveServer, request: bytes, *, wait_s: float = 30) -> bytes:
    """Send `request` on a new connection and read until the server closes it."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=wait_s) as sock:
        sock.sendall(request)
        received = b""
        while chunk := sock.recv(65536):
            received += chunk
        return received


def head_of(reply: bytes) -> httpx.Headers:
    """The header fields of a raw HTTP reply."""
    lines = reply.split(b"\r\n\r\n", 1)[0].decode("latin-1").split("\r\n")[1:]
    return httpx.Headers([line.split(": ", 1) for line in lines])


@pytest.mark.slow  # a live server
def test_header_size_and_count_limits(server):
    big = b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * (4 * 1024 * 1024) + b"\r\n\r\n"
    reply = raw(server, big)
    assert reply.startswith(b"HTTP/1.1 431 ") and has_security_headers(head_of(reply))
    many = b"GET / HTTP/1.1\r\nHost: x\r\n" + b"".join(b"X-%d: 1\r\n" % n for n in range(200)) + b"\r\n"
    assert raw(server, many).startswith(b"HTTP/1.1 431 ")
    assert httpx.get(server.url + "/", headers={"x-normal": "a" * 2000}).status_code == 200


@pytest.mark.slow  # a live server
def test_slow_and_silent_clients_are_cut_off(server):
    sockets = []
    for n in range(100):  # half send part of a request line and stop, half send nothing at all
        sock = socket.create_connection(("127.0.0.1", server.port), timeout=30)
        if n % 2:
            sock.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nX-Slow: ")
        sockets.append(sock)
    try:
        for sock in sockets:  # each is closed by the server (with a 408 reply); recv would wait 30 s otherwise
            received = b""
            while chunk := sock.recv(65536):
                received += chunk
            assert received == b"" or (
                received.startswith(b"HTTP/1.1 408 ") and has_security_headers(head_of(received))
            )
    finally:
        for sock in sockets:
            sock.close()
    assert httpx.get(server.url + "/").status_code == 200  # and the server is still there for everyone else


@pytest.mark.slow  # a live server
def test_a_client_that_leaves_mid_request_is_one_line_in_the_log(server):
    landing = httpx.get(server.url + "/")
    cookie = landing.headers["set-cookie"].split(";")[0]
    head = (
        b"POST /consent HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-www-form-urlencoded\r\n"
        b"Content-Length: 1000\r\nCookie: " + cookie.encode() + b"\r\n\r\ncsrf_token=abc"
    )
    for _ in range(3):
        raw(server, head)  # the body never comes: the server gives up after its timeout
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and server.log.read_text().count("did not send the body") < 3:
        time.sleep(0.2)
    log = server.log.read_text()
    assert log.count("did not send the body of POST /consent") == 3
    assert "Traceback" not in log and "ClientDisconnect" not in log


@pytest.mark.slow  # a live server
def test_requests_the_http_parser_refuses_get_the_security_headers(server):
    for request in (
        b"NOT HTTP AT ALL\r\n\r\n",
        b"GET / HTTP/1.1\r\nHost: x\r\nContent-Length: -5\r\n\r\n",
        b"GET /\x00 HTTP/1.1\r\nHost: x\r\n\r\n",
    ):
        reply = raw(server, request)
        assert reply.startswith(b"HTTP/1.1 400 ") and has_security_headers(head_of(reply)), reply[:300]


@pytest.mark.slow  # a live server
def test_a_deeply_nested_viewing_record_neither_fails_nor_drops_the_connection(server):
    participant = httpx.Client(base_url=server.url, follow_redirects=True)
    page = participant.get("/").text
    page = participant.post(
        "/consent", data={"csrf_token": FormReader(page).hidden["csrf_token"], "choice": "agree"}
    ).text
    page = participant.post(
        "/condition", data={"csrf_token": FormReader(page).hidden["csrf_token"], "number": "1"}
    ).text
    page = participant.post("/study", data=answer_for(page)).text  # the instructions: now at the first clip
    for depth in (3_000, 15_000):
        reply = participant.post("/study", data={**answer_for(page), "video_events": "[" * depth})
        assert reply.status_code == 422 and "malformed record" in reply.text
    assert "Traceback" not in server.log.read_text()
