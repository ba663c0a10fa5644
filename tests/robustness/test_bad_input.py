"""Property-based fuzzing of every form, the clip addresses, the platform ids and the session cookie, against the
real app on a real SQLite file: every request is answered with a page and a 4xx status or a success, never a
500; a refused answer saves nothing; an accepted one is stored exactly as sent; free text never reaches a page
unescaped.

The app exposes no OpenAPI schema (FastAPI's is switched off: there is no JSON API, only forms), so schemathesis
has nothing to read; hypothesis generates the forms instead."""

from __future__ import annotations

import json
import re

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.store.models import Participant, Response
from tests.support.survey import ADMIN_PASSWORD, WATCHED, FormReader, answer_for, start, stored

BALANCED = {"platform": '"none"', "assignment": '"balanced"'}
FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
INJECTION = [
    "<script>alert(1)</script>",
    '"><img src=x onerror=alert(1)>',
    "{{ 7*7 }}",
    "'; DROP TABLE response;--",
    '=HYPERLINK("http://x")',
    "\u202e\u0000\ud7ff",
    "💥" * 50,
    "a" * 2001,
]
# Text as a browser can send it (any code point but surrogates), plus the classic attacks.
TEXT = st.one_of(st.text(st.characters(exclude_categories=["Cs"]), max_size=300), st.sampled_from(INJECTION))
MAYBE = st.one_of(st.none(), TEXT)  # None: the field is left out
# Viewing records nested far deeper than the JSON parser's recursion limit, opened only or closed too (at most
# 19,000 characters: URL-encoded, a form of them stays under the 64 KB body limit).
DEEP = st.builds(
    lambda n, unit, closed: unit * n + ("" if not closed else "]" * n if unit == "[" else "1" + "}" * n),
    st.integers(500, 30_000),
    st.sampled_from(["[", '{"t":', '[{"type":']),
    st.booleans(),
).filter(lambda text: len(text) <= 19_000)


@pytest.fixture
def app_client(make_client):
    return make_client(BALANCED)


def newcomer(client: TestClient) -> tuple[TestClient, str]:
    """A new participant (own cookie jar) at their first clip; returns the client and the page."""
    person = TestClient(client.app, follow_redirects=True, raise_server_exceptions=False)
    page = person.post("/study", data=answer_for(start(person))).text
    return person, page


def counts(client: TestClient) -> tuple[int, list[int]]:
    return len(stored(client, Response)), [p.step for p in stored(client, Participant)]


def assert_clear_refusal(response, allowed=(400, 403, 404, 405, 409, 413, 422)) -> None:
    assert response.status_code in allowed, (response.status_code, response.text[:500])
    assert re.search(r"<h1>[^<]+</h1>", response.text), "a refusal must come as a page with a title"


def valid_clip_answer(form: dict, labels: list[str]) -> bool:
    """The server's rules, written out independently: a robot of the clip, 1-2000 characters of text that are not
    all blank, a scale point 1-9, and a clip log that says the clip ended."""
    text = form.get("justification")
    difficulty = form.get("difficulty")
    try:
        events = json.loads(form.get("video_events") or "[]")
        ended = (
            any(
                isinstance(e, dict)
                and e.get("type") == "ended"
                and isinstance(e.get("t"), int | float)
                and not isinstance(e.get("t"), bool)
                for e in events
            )
            if isinstance(events, list)
            else False
        )
    except (ValueError, RecursionError):
        ended = False
    return (
        form.get("better") in labels
        and text is not None
        and text.strip() != ""
        and len(text) <= 2000
        and difficulty is not None
        and difficulty.isdigit()
        and difficulty.isascii()
        and 1 <= int(difficulty) <= 9
        and ended
    )


@pytest.mark.slow  # generated inputs
@FUZZ
@given(
    better=st.one_of(st.sampled_from(["Robot 1", "Robot 2", "Robot 3"]), MAYBE),
    justification=MAYBE,
    difficulty=st.one_of(MAYBE, st.integers(-3, 12).map(str)),
    events=st.one_of(st.just(WATCHED), MAYBE, DEEP),
    extra=st.dictionaries(TEXT, TEXT, max_size=3),
)
def test_fuzzed_answers_are_refused_clearly_or_stored_exactly(
    app_client, better, justification, difficulty, events, extra
):
    person, page = newcomer(app_client)
    form = FormReader(page)
    labels = form.radios["better"]
    data = {**{k: v for k, v in extra.items() if k not in form.hidden}, **form.hidden}
    for name, value in [
        ("better", better),
        ("justification", justification),
        ("difficulty", difficulty),
        ("video_events", events),
    ]:
        if value is not None:
            data[name] = value
    before = counts(app_client)
    response = person.post("/study", data=data)
    if valid_clip_answer(data, labels):
        assert response.status_code == 200 and 'name="step" value="2"' in response.text, response.text[:500]
        saved = stored(app_client, Response)[-1]
        assert saved.answers == {"better": better, "justification": justification, "difficulty": int(difficulty)}
    else:
        assert_clear_refusal(response)
        assert counts(app_client) == before
        assert "<script>alert(1)</script>" not in response.text and "onerror=alert(1)>" not in response.text


FORMS = [
    "/consent",
    "/condition",
    "/study",
    "/leave",
    "/admin/login",
    "/admin/logout",
    "/admin/participants/{code}/exclusion",
]
FIELDS = [
    "csrf_token",
    "choice",
    "number",
    "step",
    "better",
    "justification",
    "difficulty",
    "ranking-1",
    "ranking-2",
    "ranking-3",
    "video_events",
    "time_on_page_ms",
    "password",
    "excluded",
    "note",
]


@pytest.mark.parametrize("depth", [3_000, 15_000])
@pytest.mark.parametrize("unit", ["[", '{"t":', '[{"type":'])
def test_deeply_nested_viewing_records_are_refused_clearly(app_client, depth, unit):
    """JSON nested deeper than the parser's recursion limit is a malformed record like any other: a 422 page."""
    person, page = newcomer(app_client)
    before = counts(app_client)
    nested = (unit * depth)[:19_000]
    response = person.post("/study", data={**answer_for(page), "video_events": nested})
    assert_clear_refusal(response, allowed=(422,))
    assert "malformed record" in response.text and counts(app_client) == before


@pytest.mark.slow  # generated inputs
@FUZZ
@given(
    path=st.sampled_from(FORMS),
    fields=st.dictionaries(st.sampled_from(FIELDS), st.lists(TEXT, max_size=2), max_size=8),
    keep_token=st.booleans(),
    deep=st.one_of(st.none(), DEEP),
)
def test_every_form_survives_random_fields(app_client, path, fields, keep_token, deep):
    person, page = newcomer(app_client)
    token = FormReader(page).hidden["csrf_token"]
    data = {name: values for name, values in fields.items() if name != "csrf_token"}
    if deep is not None:
        data["video_events"] = deep
    if keep_token:
        data["csrf_token"] = token
    code = stored(app_client, Participant)[-1].code
    before = counts(app_client)
    response = person.post(path.format(code=code), data=data)
    assert response.status_code < 500, response.text[:500]
    if response.status_code >= 400:
        assert_clear_refusal(response, allowed=(400, 401, 403, 404, 405, 409, 413, 422, 429))  # 429: login limit
    responses, steps = counts(app_client)
    assert responses == before[0]  # none of these can answer the clip without every one of its fields right
    assert steps == before[1] or path == "/study"


@FUZZ
@given(
    name=st.one_of(
        TEXT,
        st.sampled_from(
            [
                "../manifest.json",
                "..%2Fmanifest.json",
                "%2e%2e/study.toml",
                "....//....//etc/passwd",
                "%00.mp4",
                "0" * 64 + ".mp4/..",
                "/etc/passwd",
                "\\..\\manifest.json",
            ]
        ),
    )
)
def test_clip_addresses_never_leave_the_bundle(app_client, name):
    from urllib.parse import quote

    client = TestClient(app_client.app, raise_server_exceptions=False)
    for path in (
        f"/clips/{quote(name, safe='/%.')}",
        f"/clips/{quote(name, safe='')}",
        f"/static/{quote(name, safe='/%.')}",
    ):  # traversal kept as typed, and fully escaped
        response = client.get(path)
        assert response.status_code in (200, 404, 405) or 400 <= response.status_code < 500, path
        if response.status_code == 200:  # only the shipped static files
            assert path.startswith("/static/") and response.headers["content-type"].startswith(
                ("text/css", "text/javascript")
            )
        assert "foil.bundle" not in response.text and "root:" not in response.text


@FUZZ
@given(
    params=st.dictionaries(
        st.sampled_from(["PROLIFIC_PID", "STUDY_ID", "SESSION_ID", "workerId", "assignmentId", "hitId", "x"]),
        TEXT,
        max_size=4,
    ),
    cookie=st.one_of(
        st.none(),
        TEXT.map(lambda t: t.encode("utf-8", "replace").hex()[:300]),
        st.sampled_from(["eyJwYXJ0aWNpcGFudCI6ICJ4In0=.Zk1.forged", "null", "e30="]),
    ),
)
def test_forged_ids_and_cookies_are_refused_or_ignored(make_client, params, cookie):
    """Random platform ids on an MTurk link and forged session cookies: a page, never a 500, and no record
    created without consent."""
    client = make_client()  # the paper study as shipped: MTurk ids
    person = TestClient(client.app, raise_server_exceptions=False)
    if cookie is not None:
        person.cookies.set("foil_session", cookie)
    landing = person.get("/", params=params)
    assert landing.status_code in (200, 400), landing.text[:300]
    study = person.get("/study")
    assert study.status_code == 400 and "open the study again" in study.text
    assert stored(client, Participant) == []


def test_replayed_csrf_tokens_are_refused(app_client):
    """A token is good only for its own session, and a login starts a new one."""
    person, page = newcomer(app_client)
    other, _ = newcomer(app_client)
    answers = answer_for(page)
    stolen = {**answers, "csrf_token": FormReader(other.get("/study").text).hidden["csrf_token"]}
    assert_clear_refusal(person.post("/study", data=stolen), allowed=(403,))

    admin = TestClient(app_client.app, raise_server_exceptions=False)
    before_login = FormReader(admin.get("/admin/login").text).hidden["csrf_token"]
    assert (
        admin.post(
            "/admin/login", data={"csrf_token": before_login, "password": ADMIN_PASSWORD}, follow_redirects=False
        ).status_code
        == 303
    )
    code = stored(app_client, Participant)[0].code
    replay = admin.post(
        f"/admin/participants/{code}/exclusion", data={"csrf_token": before_login, "excluded": "1", "note": "replayed"}
    )
    assert_clear_refusal(replay, allowed=(403,))
    assert not stored(app_client, Participant)[0].excluded


@pytest.mark.slow  # generated inputs
@FUZZ
@given(
    body=st.binary(max_size=3000),
    content_type=st.sampled_from(
        [
            "application/x-www-form-urlencoded",
            "multipart/form-data",
            "multipart/form-data; boundary=x",
            "application/json",
            "text/plain",
            "application/x-www-form-urlencoded; charset=latin-1",
            "",
        ]
    ),
)
def test_malformed_bodies_are_refused_clearly(app_client, body, content_type):
    person, _ = newcomer(app_client)
    before = counts(app_client)
    response = person.post("/study", content=body, headers={"content-type": content_type} if content_type else {})
    assert_clear_refusal(response)
    assert counts(app_client) == before
