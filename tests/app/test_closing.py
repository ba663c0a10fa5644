"""The closing screen: optional closing questions (demographics) and a feedback box after the last part, stored
like every other answer and exported to long.csv, wide.csv and the codebook."""

from __future__ import annotations

import csv
import json

import pytest
from fastapi.testclient import TestClient

from app.analysis.export_csv import export_study, restore
from app.store.models import Participant, Response
from app.survey.study import StudyError, load_study, parse_study
from tests.support.survey import ADMIN_PASSWORD, CLOSING, PAPER_STUDY, FormReader, answer_for, start, stored, study_text


def closing_client(make_client, required: str = "[]") -> TestClient:
    return make_client({"platform": '"none"', "assignment": '"balanced"', "contact": CLOSING.format(required=required)})


def to_closing(client: TestClient) -> str:
    """Answer every screen before the closing screen; returns the closing screen."""
    page = start(client)
    while "Before you finish" not in page:
        assert "step" in FormReader(page).hidden, page
        page = client.post("/study", data=answer_for(page)).text
    return page


def test_closing_screen_comes_last_and_every_answer_is_optional(make_client):
    client = closing_client(make_client)
    page = to_closing(client)
    (person,) = stored(client, Participant)
    assert person.plan[-1]["kind"] == "closing" and person.step == len(person.plan) - 1
    form = FormReader(page)
    assert form.radios["age_range"] == ["18-29", "30-49", "50 or older", "Prefer not to say"]
    assert form.textareas == ["feedback"]
    assert "Anything you want to tell the researchers? (optional)" in page
    assert " required" not in page.split("data-answers")[1]  # nothing on the page is required
    assert "Last screen: closing questions" in page

    done = client.post("/study", data={**form.hidden, "feedback": "  "})  # nothing answered
    assert "FOIL-" in done.text or "Thank you" in done.text
    (person,) = stored(client, Participant)
    assert person.status == "completed"
    assert stored(client, Response)[-1].kind == "closing" and stored(client, Response)[-1].answers == {}


def test_closing_answers_are_checked_stored_and_exported(make_client, tmp_path):
    client = closing_client(make_client, required='["age_range", "feedback"]')
    page = to_closing(client)
    hidden = FormReader(page).hidden
    refused = client.post("/study", data={**hidden, "robot_experience": "A lot"})
    assert refused.status_code == 422
    assert "Choose one of the answers." in refused.text and "Please write an answer." in refused.text
    assert "(optional)" in refused.text and "Your age (optional)" not in refused.text
    wrong = client.post("/study", data={**hidden, "age_range": "12", "feedback": "hi"})
    assert wrong.status_code == 422 and "Choose one of the answers." in wrong.text
    (person,) = stored(client, Participant)
    assert person.status == "started"  # nothing saved

    typed = "=Thanks, the clips were short.\nGood luck!"
    client.post("/study", data={**hidden, "age_range": "30-49", "confidence": "4", "feedback": typed})
    (person,) = stored(client, Participant)
    assert person.status == "completed"
    assert stored(client, Response)[-1].answers == {"age_range": "30-49", "confidence": 4, "feedback": typed}

    study = load_study(next(tmp_path.glob("study-*.toml")))
    export_study(client.app.state.context.db, study, tmp_path / "out")
    with open(tmp_path / "out" / "long.csv", encoding="utf-8", newline="") as handle:
        rows = [r for r in csv.DictReader(handle) if r["screen"] == "closing"]
    assert {r["question"]: (r["question_type"], restore(r["answer"]), r["value"]) for r in rows} == {
        "age_range": ("choice", "30-49", ""),
        "confidence": ("scale", "4", "4"),
        "feedback": ("text", typed, ""),
    }
    assert all(r["part"] == "" and r["correct"] == "" for r in rows)
    with open(tmp_path / "out" / "wide.csv", encoding="utf-8", newline="") as handle:
        (wide,) = list(csv.DictReader(handle))
    assert (wide["closing_age_range"], wide["closing_robot_experience"], wide["closing_confidence"]) == (
        "30-49",
        "",
        "4",
    )
    assert restore(wide["closing_feedback"]) == typed
    book = json.loads((tmp_path / "out" / "codebook.json").read_text())
    assert book["questions"]["age_range"] == {
        "type": "choice",
        "text": "Your age",
        "options": ["18-29", "30-49", "50 or older", "Prefer not to say"],
        "asked": "closing",
        "required": True,
    }
    assert book["questions"]["feedback"]["text"] == "Anything you want to tell the researchers?"
    assert book["questions"]["robot_experience"]["required"] is False
    assert "closing_feedback" in [c["name"] for c in book["files"]["wide.csv"]["columns"]]
    assert (
        "options: 18-29; 30-49; 50 or older; Prefer not to say; closing screen, required"
        in (tmp_path / "out" / "codebook.md").read_text()
    )

    log = TestClient(client.app)
    login = log.get("/admin/login")
    log.post(
        "/admin/login", data={"csrf_token": FormReader(login.text).hidden["csrf_token"], "password": ADMIN_PASSWORD}
    )
    detail = log.get(f"/admin/participants/{person.code}").text
    assert "Last screen: closing questions" in detail and "30-49" in detail


@pytest.mark.parametrize(
    ("closing", "message"),
    [
        ('[closing]\nquestions = ["nowhere"]', "closing.questions[0]: no question named 'nowhere'"),
        ('[closing]\nquestions = ["ranking"]', "a 'rank' question cannot be asked on the closing screen"),
        ('[closing]\nfeedback = "Tell us"\nrequired = ["age"]', "'age' is not asked on the closing screen"),
        ('[closing]\ntitle = "Last"', "give closing questions, a feedback question, or both"),
    ],
)
def test_closing_table_mistakes_are_named(closing, message):
    with pytest.raises(StudyError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_study(study_text(contact='""\n' + closing))


def test_choice_questions_are_refused_in_parts():
    text = study_text().replace(
        '[questions.better]\ntype = "choose"', '[questions.better]\ntype = "choice"\noptions = ["a", "b"]'
    )
    with pytest.raises(StudyError, match="a 'choice' question cannot be asked in a pairwise part"):
        parse_study(text)


def test_paper_study_has_no_closing_screen_and_the_demo_has_one():
    assert load_study(PAPER_STUDY).closing is None
    demo = load_study(PAPER_STUDY.parent / "demo.toml").closing
    assert demo is not None and demo.questions and demo.feedback and not demo.required


def test_closing_screen_sent_again_keeps_the_first_answers(make_client):
    client = closing_client(make_client)
    page = to_closing(client)
    hidden = FormReader(page).hidden
    client.post("/study", data={**hidden, "feedback": "First thoughts."})
    again = client.post("/study", data={**hidden, "feedback": "Second thoughts."})
    assert again.status_code == 200
    assert stored(client, Response)[-1].answers == {"feedback": "First thoughts."}
