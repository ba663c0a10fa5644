"""Clips: served by hash with Range (206) support and long-lived caching; nothing else can be reached."""

from __future__ import annotations

import re

import pytest


@pytest.fixture
def client_and_clip(make_client):
    client = make_client({"platform": '"none"'})
    path = next(iter(client.app.state.context.bundle.paths.values()))
    sha = next(iter(client.app.state.context.bundle.paths))
    return client, f"/clips/{sha}.mp4", path.read_bytes()


def test_whole_clip_with_caching_headers(client_and_clip):
    client, url, data = client_and_clip
    response = client.get(url)
    assert response.status_code == 200 and response.content == data
    assert response.headers["content-type"] == "video/mp4" and response.headers["accept-ranges"] == "bytes"
    assert "immutable" in response.headers["cache-control"] and "max-age=31536000" in response.headers["cache-control"]
    again = client.get(url, headers={"if-none-match": response.headers["etag"]})
    assert again.status_code == 304 and again.content == b""
    assert client.head(url).status_code == 200


def test_range_requests_get_206(client_and_clip):
    client, url, data = client_and_clip
    part = client.get(url, headers={"range": "bytes=0-1"})  # what Safari asks first
    assert part.status_code == 206 and part.content == data[:2]
    assert part.headers["content-range"] == f"bytes 0-1/{len(data)}"
    tail = client.get(url, headers={"range": "bytes=100-"})
    assert tail.status_code == 206 and tail.content == data[100:]
    assert client.get(url, headers={"range": f"bytes={len(data) + 10}-"}).status_code == 416


@pytest.mark.parametrize("kept_bytes", [0, 1 << 20], ids=["from the file", "kept in memory"])
def test_ranges_are_the_same_from_memory_and_from_the_file(client_and_clip, kept_bytes):
    client, url, data = client_and_clip
    client.app.state.context.kept_clips.limit = kept_bytes
    for asked, first, last in [
        ("0-1023", 0, 1023),
        ("0-", 0, len(data) - 1),
        ("100-199", 100, 199),
        (f"10-{len(data) + 50}", 10, len(data) - 1),
    ]:
        part = client.get(url, headers={"range": f"bytes={asked}"})
        assert part.status_code == 206 and part.content == data[first : last + 1]
        assert part.headers["content-range"] == f"bytes {first}-{last}/{len(data)}"
    assert client.get(url, headers={"range": f"bytes={len(data)}-"}).status_code == 416
    assert bool(client.app.state.context.kept_clips.clips) == bool(kept_bytes)


def test_clips_carry_no_session(client_and_clip):
    client, url, _ = client_and_clip
    client.get("/")  # a participant with a session cookie
    response = client.get(url, headers={"range": "bytes=0-9"})
    assert "set-cookie" not in response.headers and "cookie" not in response.headers.get("vary", "").lower()


@pytest.mark.parametrize(
    "path",
    [
        "/clips/../manifest.json",
        "/clips/..%2Fmanifest.json",
        "/clips/%2e%2e%2fmanifest.json",
        "/clips/" + "0" * 64 + ".mp4",
        "/clips/manifest.json",
        "/clips/000.mp4",
        "/static/../app/web/settings.py",
        "/static/%2e%2e/app/web/settings.py",
    ],
)
def test_nothing_outside_the_listed_clips_is_served(client_and_clip, path):
    client, _, _ = client_and_clip
    response = client.get(path)
    assert response.status_code == 404
    assert "format" not in response.text and "SecretStr" not in response.text


def test_pages_carry_security_headers(client_and_clip):
    client, _, _ = client_and_clip
    headers = client.get("/").headers
    assert headers["x-content-type-options"] == "nosniff" and headers["x-frame-options"] == "DENY"
    assert "frame-ancestors 'none'" in headers["content-security-policy"]
    assert headers["referrer-policy"] == "no-referrer" and headers["cache-control"] == "no-store"
    cookie = headers["set-cookie"]
    assert "httponly" in cookie.lower() and "samesite=lax" in cookie.lower() and "secure" not in cookie.lower()


def test_secure_cookie_option(make_client):
    client = make_client({"platform": '"none"'}, cookie_secure=True, cookie_samesite="none")
    cookie = client.get("/").headers["set-cookie"].lower()
    assert "secure" in cookie and "samesite=none" in cookie


def test_clip_pages_are_gated_and_playable_inline(make_client):
    from tests.support.survey import answer_for, start

    client = make_client({"platform": '"none"', "assignment": '"balanced"'})
    page = client.post("/study", data=answer_for(start(client))).text
    assert re.search(r"<video [^>]*playsinline", page) and "data-play" in page
    assert re.search(r"<fieldset class=\"answers\" data-answers\s+disabled", page)
    assert 'data-timeout="20.0"' in page
