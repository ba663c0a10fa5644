"""Server-side validation, idempotent resubmits, out-of-order protection, CSRF and size limits."""

from __future__ import annotations

import threading

import pytest
from starlette.datastructures import FormData

from app.store.models import Participant, Response
from app.survey.answers import Outcome, Refused, save_answer
from tests.support.survey import FormReader, answer_for, start, stored

BALANCED = {"platform": '"none"', "assignment": '"balanced"'}


def at_first_clip(client) -> str:
    page = start(client)
    return client.post("/study", data=answer_for(page)).text


def at_first_ranking(client) -> str:
    page = at_first_clip(client)
    while FormReader(page).selects == {}:
        page = client.post("/study", data=answer_for(page)).text
    return page


def assert_rejected(client, data: dict, message: str) -> None:
    before = len(stored(client, Response))
    step = stored(client, Participant)[0].step
    response = client.post("/study", data=data)
    assert response.status_code == 422, response.text
    assert message in response.text
    assert len(stored(client, Response)) == before and stored(client, Participant)[0].step == step


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("better", None, "Choose one of the names shown."),
        ("better", "Robot 9", "That name is not in this clip."),
        ("justification", None, "Please write an answer."),
        ("justification", "   \n ", "Please write an answer."),
        ("justification", "x" * 2001, "Please keep this under 2000 characters"),
        ("difficulty", None, "Choose one point on the scale."),
        ("difficulty", "0", "whole number from 1 to 9"),
        ("difficulty", "10", "whole number from 1 to 9"),
        ("difficulty", "4.5", "whole number from 1 to 9"),
        ("video_events", "[]", "Please watch the clip to the end"),
        ("video_events", '[{"type": "ended"}]', "malformed record"),
        ("video_events", "not json", "malformed record"),
    ],
)
def test_every_invalid_pairwise_answer_is_rejected_and_nothing_saved(make_client, field, value, message):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    bad = {k: v for k, v in good.items() if k != field} | ({} if value is None else {field: value})
    assert_rejected(client, bad, message)
    assert client.post("/study", data=good).status_code == 200  # and the valid answer still goes through
    assert len(stored(client, Response)) == 2


@pytest.mark.parametrize(
    "change, message",
    [
        ({"ranking-2": None}, "Put a name in every place"),
        ({"ranking-2": "same-as-1"}, "has a name twice"),
        ({"ranking-3": "Robot 7"}, "not in this study"),
    ],
)
def test_invalid_rankings_are_rejected(make_client, change, message):
    client = make_client(BALANCED)
    good = answer_for(at_first_ranking(client))
    bad = dict(good)
    for key, value in change.items():
        if value is None:
            del bad[key]
        else:
            bad[key] = good["ranking-1"] if value == "same-as-1" else value
    assert_rejected(client, bad, message)


def test_error_page_keeps_typed_answers_and_the_unlocked_clip(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    typed = "I liked <b>Robot 1</b> & its path"
    page = client.post("/study", data={**good, "justification": typed, "difficulty": "99"}).text
    assert "&lt;b&gt;Robot 1&lt;/b&gt; &amp; its path" in page and "<b>Robot 1</b>" not in page
    form = FormReader(page)
    assert not form.disabled_answers and "data-watched" in page
    assert 'role="alert"' in page


def test_free_text_is_stored_exactly_as_typed(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    typed = "  <script>alert('x')</script>\n=SUM(A1)  émoji 🤖 "
    client.post("/study", data={**good, "justification": typed})
    assert stored(client, Response)[-1].answers["justification"] == typed


def test_double_submit_is_idempotent(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    first, second = client.post("/study", data=good), client.post("/study", data=good)
    assert first.status_code == second.status_code == 200 and first.text == second.text
    assert [r.step for r in stored(client, Response)] == [0, 1]
    assert stored(client, Participant)[0].step == 2


def test_concurrent_double_submit_saves_once(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    codes = []

    def post():
        codes.append(client.post("/study", data=good).status_code)

    threads = [threading.Thread(target=post) for _ in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert codes == [200] * 6
    assert [r.step for r in stored(client, Response)] == [0, 1]


def test_answering_ahead_is_refused(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    response = client.post("/study", data={**good, "step": "5"})
    assert response.status_code == 409 and "not open yet" in response.text
    assert len(stored(client, Response)) == 1
    assert client.post("/study", data={**good, "step": "x1"}).status_code == 400


def test_self_selected_number_must_be_in_range(make_client):
    client = make_client({"platform": '"none"'})
    page = start(client)
    token = FormReader(page).hidden["csrf_token"]
    for bad in ("0", "5", "two", ""):
        response = client.post("/condition", data={"csrf_token": token, "number": bad})
        assert response.status_code == 422 and "from 1 to 4" in response.text
    assert stored(client, Participant)[0].condition is None
    client.post("/condition", data={"csrf_token": token, "number": "4"})
    assert stored(client, Participant)[0].condition == 3


@pytest.mark.parametrize("token", [None, "forged", "other-session"])
def test_forms_without_the_sessions_csrf_token_are_refused(make_client, token):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    if token == "other-session":
        from fastapi.testclient import TestClient

        good["csrf_token"] = FormReader(TestClient(client.app).get("/").text).hidden["csrf_token"]
    elif token is None:
        del good["csrf_token"]
    else:
        good["csrf_token"] = token
    response = client.post("/study", data=good)
    assert response.status_code == 403 and "did not come from this site" in response.text
    assert len(stored(client, Response)) == 1
    consent = client.post("/consent", data={"choice": "agree"})
    assert consent.status_code == 403


def test_oversized_requests_are_refused(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    response = client.post("/study", data={**good, "justification": "x" * 70_000})
    assert response.status_code == 413 and "at most" in response.text
    chunked = client.post(
        "/study",
        content=iter([b"a=" + b"x" * 40_000, b"x" * 40_000]),
        headers={"content-type": "application/x-www-form-urlencoded"},
    )
    assert chunked.status_code == 413
    assert len(stored(client, Response)) == 1


def test_unknown_participant_gets_a_clear_message(make_client):
    client = make_client(BALANCED)
    page = client.get("/study")
    assert page.status_code == 400 and "open the study again" in page.text


def test_malformed_requests_get_clear_4xx_pages(make_client):
    client = make_client(BALANCED)
    good = answer_for(at_first_clip(client))
    upload = client.post("/study", data=good, files={"f": ("a.txt", b"x")})
    assert upload.status_code == 400 and "Too many files" in upload.text
    crowded = client.post("/study", data={**good, **{f"x{i}": "1" for i in range(80)}})
    assert crowded.status_code == 400 and "Too many fields" in crowded.text
    unknown = client.get("/no/such/page")
    assert unknown.status_code == 404 and "<h1>Page not found</h1>" in unknown.text
    assert len(stored(client, Response)) == 1


def test_saving_an_answer_says_what_came_of_it_and_commits_before_it_returns(make_client):
    client = make_client(BALANCED)
    ctx = client.app.state.context
    first = at_first_clip(client)  # the instructions answered: step 1, the first clip
    code = stored(client, Participant)[0].code

    def save(step: int, data: dict, who: object = code):
        return save_answer(ctx.db, ctx.study, who, step, FormData(list(data.items())), fast_link=False)

    answers = answer_for(first)
    assert save(1, answers, who="someone else") is Outcome.UNKNOWN
    assert save(2, answers) is Outcome.NOT_OPEN
    refused = save(1, {**answers, "video_events": "not json"})
    assert isinstance(refused, Refused) and refused.screen.kind == "pairwise"
    assert set(refused.checked.errors) == {"video"} and refused.checked.answers["better"] == answers["better"]
    assert len(stored(client, Response)) == 1  # the instructions' only

    assert save(1, answers) is Outcome.SAVED
    saved = stored(client, Response)  # read in a transaction of its own: committed
    assert [r.step for r in saved] == [0, 1] and saved[1].answers["better"] == answers["better"]
    assert stored(client, Participant)[0].step == 2

    assert save(1, answers) is Outcome.SAVED  # the same answers again: nothing to keep or say
    assert save(1, answer_for(first, choice=1)) is Outcome.KEPT  # other answers: the first are kept
    assert stored(client, Response)[1].answers == saved[1].answers and stored(client, Participant)[0].step == 2


def test_each_kind_of_question_checks_its_own_answer():
    """What each kind of question takes from a submitted form, and the message shown beside its field otherwise."""
    from app.survey.screens import OneOf
    from app.survey.study import ChoiceQuestion, ChooseQuestion, RankQuestion, ScaleQuestion, TextQuestion

    form = {"q": "b", "t": "ab", "s": "3", "r-1": "Robot 2", "r-2": "Robot 1"}
    read, labels = form.get, ["Robot 1", "Robot 2"]
    not_right = "That is not right. Read the instructions above again, then choose another answer."
    assert ChoiceQuestion(type="choice", text="?", options=["a", "b"]).check("q", read, labels) == ("b", None)
    assert ChoiceQuestion(type="choice", text="?", options=["a", "c"]).check("q", read, labels) == (
        None,
        "Choose one of the answers.",
    )
    assert OneOf(["a", "b"], expected="b").check("q", read, labels) == ("b", None)
    assert OneOf(["a", "b"], expected="a").check("q", read, labels) == (None, not_right)
    assert OneOf(["a", "c"], expected="a").check("q", read, labels) == (None, "Choose one of the answers.")
    assert TextQuestion(type="text", text="?", min_length=3).check("t", read, labels) == (
        None,
        "Please write at least 3 characters.",
    )
    assert TextQuestion(type="text", text="?", min_length=2).check("t", read, labels) == ("ab", None)
    assert ScaleQuestion(type="scale", text="?", points=5, anchors=("low", "high")).check("s", read, labels) == (
        3,
        None,
    )
    assert RankQuestion(type="rank", text="?").check("r", read, labels) == (["Robot 2", "Robot 1"], None)
    assert ChooseQuestion(type="choose", text="?").check("r-1", read, labels) == ("Robot 2", None)
