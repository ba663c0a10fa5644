"""Whole participant sessions through the real HTTP flow, for every design and platform."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from app.store.models import Participant, Response
from tests.support.survey import SECRET_NAMES, FormReader, answer_for, finish, start, stored, walk

PROLIFIC = {
    "platform": '"prolific"',
    "assignment": '"balanced"',
    "redirect_url": '"https://app.prolific.com/submissions/complete?cc=FOIL-PAPER-7Q2K"',
}
PROLIFIC_LINK = "?PROLIFIC_PID=pid{n}&STUDY_ID=study1&SESSION_ID=session{n}"


def test_paper_study_whole_session_on_mturk(make_client):
    client = make_client({"platform": '"mturk"'})
    seen = walk(client, start(client, "?workerId=W1&assignmentId=A1&hitId=H1"))
    assert "Pick any number from 1 to 4" in seen[0]
    assert "FOIL-PAPER-7Q2K" in seen[-1] and "Paste the code into the study page you came from." in seen[-1]
    (person,) = stored(client, Participant)
    assert person.status == "completed" and person.condition == 2 and person.slot is None
    assert (person.external_id, person.platform_study_id, person.platform_session_id) == ("W1", "H1", "A1")
    kinds = [screen["kind"] for screen in person.plan]
    # instructions, 6 pairwise clips (3 pairs x 2 schemes), then per scheme its 3 clips and a ranking
    assert kinds == ["instructions"] + ["pairwise"] * 6 + (["watch"] * 3 + ["ranking"]) * 2
    pairwise = [s for s in person.plan if s["kind"] == "pairwise"]
    assert {s["scheme"] for s in pairwise} == {SECRET_NAMES["adaptive"], SECRET_NAMES["nfirst"]}
    assert len({s["scenario"] for s in pairwise}) == 1
    ranking_scenarios = {s["scenario"] for s in person.plan if s["kind"] in ("watch", "ranking")}
    assert len(ranking_scenarios) == 1 and ranking_scenarios != {pairwise[0]["scenario"]}
    responses = stored(client, Response)
    assert len(responses) == len(person.plan)
    assert all(r.server_ms >= 0 for r in responses)
    assert all(r.plays == 1 and r.client_ms == 4321 for r in responses if r.kind in ("pairwise", "watch"))
    ranking = next(r for r in responses if r.kind == "ranking")
    assert sorted(ranking.answers["ranking"]) == ["Robot 1", "Robot 2", "Robot 3"]
    assert set(ranking.answers) == {"ranking", "explanation", "difference", "easy_worst_middle", "easy_middle_best"}
    progress = " ".join(seen)
    assert "Part 1 of 2, clip 3 of 6" in progress and "Part 2 of 2, round 2 of 2, ranking" in progress
    assert "Part 2 of 2, round 1 of 2, clip 3 of 3" in progress
    for page in seen:  # ground truth and real names never reach the browser
        for secret in SECRET_NAMES.values():
            assert secret not in page


def test_balanced_prolific_sessions_and_redirect(make_client):
    client = make_client(PROLIFIC)
    for n in range(4):
        client.cookies.clear()
        last = walk(client, start(client, PROLIFIC_LINK.format(n=n)))[-1]
        assert "FOIL-PAPER-7Q2K" in last and 'href="https://app.prolific.com/submissions/complete?cc=' in last
    people = stored(client, Participant)
    assert [p.slot for p in people] == [0, 1, 2, 3]
    assert sorted(p.condition for p in people) == [0, 1, 2, 3]  # one block: every condition once
    assert all(p.status == "completed" and p.completed_at for p in people)


def test_between_subjects_design(make_client):
    client = make_client({"scheme_factor": '"between"', "assignment": '"balanced"', "platform": '"none"'})
    walk(client, start(client))
    (person,) = stored(client, Participant)
    kinds = [screen["kind"] for screen in person.plan]
    assert kinds == ["instructions"] + ["pairwise"] * 3 + ["watch"] * 3 + ["ranking"]
    assert len({s["scheme"] for s in person.plan if "scheme" in s}) == 1
    assert len(client.app.state.context.conditions) == 4  # 2 schemes x 2 scenario orders


def test_reload_shows_the_same_page_and_back_button_keeps_first_answer(make_client):
    client = make_client(PROLIFIC)
    first = start(client, PROLIFIC_LINK.format(n=1))
    assert client.get("/study").text == first  # a reload: the same page
    instructions = answer_for(first)
    client.post("/study", data=instructions)
    pairwise_page = client.get("/study").text
    assert FormReader(pairwise_page).hidden["step"] == "1"
    answer = answer_for(pairwise_page, choice=0)
    client.post("/study", data=answer)
    again = dict(answer, better=[v for v in FormReader(pairwise_page).radios["better"] if v != answer["better"]][0])
    after_back = client.post("/study", data=again)  # the back button, a changed answer, submit again
    assert after_back.status_code == 200 and FormReader(after_back.text).hidden["step"] == "2"
    saved = [r for r in stored(client, Response) if r.step == 1]
    assert len(saved) == 1 and saved[0].answers["better"] == answer["better"]


def test_coming_back_resumes_and_a_finished_participant_cannot_retake(make_client):
    client = make_client(PROLIFIC)
    page = start(client, PROLIFIC_LINK.format(n=7))
    page = client.post("/study", data=answer_for(page)).text
    page = client.post("/study", data=answer_for(page)).text
    step = FormReader(page).hidden["step"]
    other_browser = TestClient(client.app)
    resumed = other_browser.get("/" + PROLIFIC_LINK.format(n=7))
    assert FormReader(resumed.text).hidden["step"] == step
    finish(other_browser, resumed.text)
    third_browser = TestClient(client.app)
    again = third_browser.get("/" + PROLIFIC_LINK.format(n=7))
    assert "FOIL-PAPER-7Q2K" in again.text and "step" not in FormReader(again.text).hidden
    forced = third_browser.post(
        "/consent", data={"csrf_token": FormReader(again.text).hidden.get("csrf_token", ""), "choice": "agree"}
    )
    assert forced.status_code in (200, 403) and "step" not in FormReader(forced.text).hidden
    assert len(stored(client, Participant)) == 1


def test_anonymous_pilot_resumes_by_cookie(make_client):
    client = make_client({"platform": '"none"', "assignment": '"balanced"'})
    page = start(client)
    client.post("/study", data=answer_for(page))
    assert FormReader(client.get("/").text).hidden["step"] == "1"  # the link again: same record
    done = finish(client, client.get("/").text)
    assert "FOIL-PAPER-7Q2K" in done and "study page you came from" not in done  # no platform page to paste into
    stranger = TestClient(client.app)
    start(stranger)
    assert len(stored(client, Participant)) == 2


def test_mturk_preview_shows_no_consent_and_saves_nothing(make_client):
    client = make_client({"platform": '"mturk"'})
    page = client.get("/?assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE&hitId=H1")
    assert "Accept the HIT" in page.text and "/consent" not in page.text
    assert stored(client, Participant) == []


def test_platform_link_without_id_is_refused_clearly(make_client):
    client = make_client(PROLIFIC)
    page = client.get("/?STUDY_ID=x")
    assert page.status_code == 400 and "PROLIFIC_PID" in page.text
    assert client.get("/?PROLIFIC_PID=<script>").status_code == 400


def test_decline_ends_politely(make_client):
    client = make_client(PROLIFIC)
    page = client.get("/" + PROLIFIC_LINK.format(n=2))
    done = client.post("/consent", data={"csrf_token": FormReader(page.text).hidden["csrf_token"], "choice": "decline"})
    assert "You chose not to take part" in done.text
    (person,) = stored(client, Participant)
    assert person.status == "declined" and person.slot is None and person.plan is None
    assert "You chose not to take part" in client.get("/" + PROLIFIC_LINK.format(n=2)).text


def test_a_consent_sent_again_after_its_reply_was_lost_finds_its_participant(make_client):
    """Anonymous, so no platform id can tell: the consent page's session holds the code its consent gives, so the
    same consent sent again (the reply, with the cookie naming the participant, was lost) takes no second slot."""
    client = make_client({"platform": '"none"', "assignment": '"balanced"'})
    token = FormReader(client.get("/").text).hidden["csrf_token"]
    before_consent = client.cookies["foil_session"]

    def consent_whose_reply_is_lost() -> None:
        assert client.post("/consent", data={"csrf_token": token, "choice": "agree"}).status_code == 200
        client.cookies.clear()
        client.cookies.set("foil_session", before_consent)  # the browser still holds the consent page's cookie

    consent_whose_reply_is_lost()
    consent_whose_reply_is_lost()  # the browser sends the form again
    assert FormReader(client.get("/").text).hidden["csrf_token"] == token  # or the consent page is opened again
    consent_whose_reply_is_lost()
    (person,) = stored(client, Participant)
    assert person.slot is not None
    start(TestClient(client.app))  # someone else, in another browser: a participant of their own
    assert len(stored(client, Participant)) == 2


def test_leaving_marks_returned_and_keeps_answers(make_client):
    client = make_client(PROLIFIC)
    page = start(client, PROLIFIC_LINK.format(n=3))
    client.post("/study", data=answer_for(page))
    confirm = client.get("/leave")
    assert "please also return your submission on Prolific" in confirm.text  # said before stopping, too
    left = client.post("/leave", data={"csrf_token": FormReader(confirm.text).hidden["csrf_token"]})
    assert "You have left the study" in left.text and "Please return your submission on Prolific" in left.text
    (person,) = stored(client, Participant)
    assert person.status == "returned" and len(stored(client, Response)) == 1


def test_leaving_a_study_on_another_platform_speaks_of_no_prolific_submission(make_client):
    client = make_client({"platform": '"mturk"'})
    start(client, "?workerId=W4&assignmentId=A4&hitId=H4")
    confirm = client.get("/leave")
    left = client.post("/leave", data={"csrf_token": FormReader(confirm.text).hidden["csrf_token"]})
    assert "You have left the study" in left.text
    assert "Prolific" not in confirm.text and "Prolific" not in left.text


def test_desktop_only_study_turns_phones_away(make_client):
    client = make_client({"device": '"desktop"', "platform": '"none"'})
    phone = "Mozilla/5.0 (iPhone; CPU iPhone OS 17_0 like Mac OS X) Mobile/15E148"
    page = client.get("/", headers={"user-agent": phone})
    assert "laptop or desktop" in page.text and "/consent" not in page.text


def test_attention_check_is_placed_and_scored(make_client, tmp_path):
    client = make_client(
        {
            "platform": '"none"',
            "assignment": '"balanced"',
            "contact": '''""
[[attention_checks]]
part = 1
after = 2
text = "Please choose Agree."
options = ["Disagree", "Agree"]
expected = "Agree"''',
        }
    )
    page = start(client)
    seen = walk(client, page)
    (person,) = stored(client, Participant)
    kinds = [s["kind"] for s in person.plan]
    assert kinds[1:5] == ["pairwise", "pairwise", "attention", "pairwise"]
    assert any("Part 1 of 2, a check question" in p for p in seen)
    assert person.attention_failures == 1  # the bot chose the first option, "Disagree"


@pytest.mark.parametrize("synchronous", [None, "normal"])
def test_sqlite_commits_reach_the_disk_unless_normal_is_asked_for(make_client, synchronous):
    """FULL by default: an answer acknowledged to the participant survives an operating-system crash too."""
    client = make_client({"platform": '"mturk"'}, **({"sqlite_synchronous": synchronous} if synchronous else {}))
    db = client.app.state.context.db
    if db.engine.dialect.name != "sqlite":
        return
    with db.engine.connect() as connection:
        assert connection.exec_driver_sql("PRAGMA synchronous").scalar() == (1 if synchronous == "normal" else 2)
    seen = walk(client, start(client, "?workerId=W1&assignmentId=A1&hitId=H1"))
    assert "FOIL-PAPER-7Q2K" in seen[-1] and "Paste the code into the study page you came from." in seen[-1]
    (person,) = stored(client, Participant)
    assert person.status == "completed" and len(stored(client, Response)) == len(person.plan)
