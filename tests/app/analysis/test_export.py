"""foil export: what participants answered through the real app is what the CSV files say, for every question type,
read back by pandas without options; spreadsheet formulas are neutralised; the header is fixed by the study."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from app.analysis.export_csv import export_study, neutralise
from app.store.models import Participant, Response
from app.survey.study import parse_study
from tests.support.analysis import add_participant
from tests.support.survey import ADMIN_PASSWORD, ATTENTION, FormReader, answer_for, start, study_text

# Texts a spreadsheet would run, a reader would take for missing, or that test the escape itself.
TRICKY = [
    '=HYPERLINK("http://x","y")',
    "+1+2",
    "-3",
    "@SUM(A1)",
    "\tTab first",
    "\rCarriage",
    "'quoted",
    "NA",
    'line one\nline two, with a comma and "quotes"',
    "plain words",
]


def restore(cell: str) -> str:
    """The documented reverse of the neutralisation."""
    return cell[1:] if cell.startswith("'") else cell


def take_study(client, tricky: list[str], attentive: bool, choice: int) -> None:
    page = start(client)
    texts = iter(tricky * 10)
    while True:
        form = FormReader(page)
        if "step" not in form.hidden:
            return
        data = answer_for(page, choice)
        for name in form.textareas:
            data[name] = next(texts)
        if "attention" in form.radios:
            data["attention"] = "Agree" if attentive else "Disagree"
        response = client.post("/study", data=data)
        assert response.status_code == 200, response.text
        page = response.text


@pytest.fixture
def answered(make_client, tmp_path):
    """Three participants through the real flow (one fails the attention check, one stops half-way); one
    flagged on the admin pages with a note a spreadsheet would execute."""
    path = tmp_path / "study-attention.toml"
    path.write_text(study_text(platform='"none"', assignment='"balanced"') + ATTENTION)
    clients = [make_client(study_file=path) for _ in range(3)]
    take_study(clients[0], TRICKY, attentive=True, choice=0)
    take_study(clients[1], TRICKY[3:] + TRICKY[:3], attentive=False, choice=1)
    page = start(clients[2])
    clients[2].post("/study", data=answer_for(page))  # the instructions only
    admin = clients[0]
    login = admin.get("/admin/login")
    admin.post(
        "/admin/login", data={"csrf_token": FormReader(login.text).hidden["csrf_token"], "password": ADMIN_PASSWORD}
    )
    db = admin.app.state.context.db
    with db.reading() as session:
        first = session.query(Participant).order_by(Participant.id).first()
    overview = admin.get(f"/admin/participants/{first.code}")
    admin.post(
        f"/admin/participants/{first.code}/exclusion",
        data={
            "csrf_token": FormReader(overview.text).hidden["csrf_token"],
            "excluded": "1",
            "note": "=cmd|' /C calc'!A0",
        },
    )
    study = parse_study(path.read_text())
    result = export_study(db, study, tmp_path / "export")
    with db.reading() as session:
        participants = session.query(Participant).order_by(Participant.id).all()
        responses = session.query(Response).order_by(Response.participant_id, Response.step).all()
    return result, study, participants, responses


def test_every_answer_round_trips(answered):
    result, study, participants, responses = answered
    long = pd.read_csv(result.out / "long.csv")
    plans = {p.id: p.plan for p in participants}
    codes = {p.id: neutralise(p.code) for p in participants}  # a code may start with "-"
    types_seen = set()
    expected_rows = 0
    for response in responses:
        rows = long[(long.participant == codes[response.participant_id]) & (long.step == response.step)]
        expected_rows += max(1, len(response.answers))
        screen = plans[response.participant_id][response.step]
        agent_of = {r["label"]: r["agent"] for r in screen.get("robots", [])}
        assert (rows.screen == response.kind).all() and (rows.plays == response.plays).all()
        for question, value in response.answers.items():
            (row,) = rows[rows.question == question].itertuples()
            types_seen.add(row.question_type)
            if row.question_type == "choose":
                assert row.answer == value and row.answer_agent == agent_of[value]
                assert row.correct == int(agent_of[value] == screen["better"]) and row.truth == screen["better"]
            elif row.question_type == "rank":
                assert row.answer.split(">") == value
                assert row.answer_agent.split(">") == [agent_of[label] for label in value]
                assert row.correct == int(row.answer_agent.split(">") == screen["true_order"])
            elif row.question_type == "scale":
                assert row.value == value
            elif row.question_type == "text":
                assert restore(row.answer) == value
            else:
                assert row.question_type == "attention" and row.answer == value
                assert row.correct == int(value == "Agree")
    assert types_seen == {"choose", "rank", "scale", "text", "attention"}
    assert len(long) == expected_rows == result.answers


def test_participants_schemes_are_the_conditions_in_its_order(answered):
    """`schemes` says the participant's condition as the codebook lists it, whatever order the shuffled clips of
    a part came in."""
    result, study, participants, responses = answered
    people = pd.read_csv(result.out / "participants.csv")
    book = json.loads((result.out / "codebook.json").read_text())
    of_condition = {c["number"]: ";".join(c["schemes"]) for c in book["conditions"]}
    assert list(people.schemes) == [of_condition[p.condition + 1] for p in participants]
    assert len(set(people.schemes)) == 2  # both counterbalanced orders occur


def test_wide_and_participants_files(answered):
    result, study, participants, responses = answered
    wide = pd.read_csv(result.out / "wide.csv")
    people = pd.read_csv(result.out / "participants.csv")
    assert list(wide.participant) == list(people.participant) == [neutralise(p.code) for p in participants]
    first, second, third = participants
    assert list(people.status) == ["completed", "completed", "started"]
    assert list(people.excluded) == [1, 1, 1]  # flagged; failed the check; incomplete
    assert list(people.flagged_by_admin) == [1, 0, 0] and list(people.failed_attention) == [0, 1, 0]
    assert list(people.incomplete) == [0, 0, 1]
    assert restore(people.exclusion_note[0]) == "=cmd|' /C calc'!A0"
    long = pd.read_csv(result.out / "long.csv")
    for participant, row in zip(participants, wide.itertuples(), strict=True):
        mine = long[(long.participant == neutralise(participant.code)) & long.question.notna()]
        for answer in mine.itertuples():
            screen = participant.plan[answer.step]
            if answer.question_type == "attention":
                assert getattr(row, f"attention{screen['check'] + 1}") == answer.answer
                continue
            scheme = screen["scheme"]
            if screen["kind"] == "pairwise":
                pair = next(p for p in study.parts[0].pairs if set(p) == {r["agent"] for r in screen["robots"]})
                key = f"p1_{scheme}_{pair[0]}_{pair[1]}_{answer.question}"
            else:
                key = f"p2_{scheme}_{answer.question}"
            wanted = {
                "choose": answer.answer_agent,
                "rank": answer.answer_agent,
                "scale": answer.value,
                "text": answer.answer,
            }[answer.question_type]
            assert getattr(row, key) == wanted, key
    # the header is fixed by the study: every scheme, pair and question, answered or not
    assert "p1_schemeadaptivesecret_agentlowsecret_agentmedsecret_difficulty" in wide.columns
    assert "p2_schemenfirstsecret_ranking_correct" in wide.columns


def test_no_cell_starts_a_formula(answered):
    result, *_ = answered
    for name in ("long.csv", "wide.csv", "participants.csv"):
        frame = pd.read_csv(result.out / name, dtype=str, keep_default_na=False)
        for column in frame.columns:
            for cell in frame[column]:
                assert not cell.startswith(("=", "+", "-", "@", "\t", "\r")), (name, column, cell)
    raw = (result.out / "long.csv").read_text()
    assert "'=HYPERLINK" in raw and "'+1+2" in raw and "'-3" in raw and "'@SUM" in raw and "''quoted" in raw


def test_neutralise_reverses_exactly():
    for text in TRICKY + ["", "'", "''=x", "NA ", "-"]:
        assert restore(neutralise(text)) == text
        assert not neutralise(text).startswith(("=", "+", "-", "@", "\t", "\r"))


def test_codebook_types_read_exactly(answered):
    result, *_ = answered
    book = json.loads((result.out / "codebook.json").read_text())
    long = pd.read_csv(result.out / "long.csv", **book["files"]["long.csv"]["read_csv"])
    assert str(long["value"].dtype) == "Int64" and str(long["answer"].dtype) == "string"
    assert str(long["submitted_at"].dtype).startswith("datetime64") and str(long.submitted_at.dt.tz) == "UTC"
    for name in ("wide.csv", "participants.csv"):
        frame = pd.read_csv(result.out / name, **book["files"][name]["read_csv"])
        assert list(frame.columns) == [c["name"] for c in book["files"][name]["columns"]]
    markdown = (result.out / "codebook.md").read_text()
    assert "| `easy_middle_best` | scale |" in markdown and "5 = Strongly agree" in markdown
    assert "| `correct` | Int64 |" in markdown


def test_export_of_a_hand_built_database_is_stable(survey_db, paper_study, bundle_dir, tmp_path):
    """Two exports of the same database are byte-identical, and an empty study gives headers only."""
    path, study = paper_study
    empty = export_study(survey_db, study, tmp_path / "empty")
    assert empty.participants == 0 and pd.read_csv(empty.out / "long.csv").empty
    for condition in range(4):
        add_participant(
            survey_db, study, bundle_dir, condition=condition, answer=lambda screen: answer_of(screen), seed=condition
        )
    one = export_study(survey_db, study, tmp_path / "one", batch=3)
    two = export_study(survey_db, study, tmp_path / "two", batch=500)
    for name in ("long.csv", "wide.csv", "participants.csv", "codebook.json", "codebook.md"):
        assert (one.out / name).read_bytes() == (two.out / name).read_bytes(), name
    assert one.participants == 4 and list(pd.read_csv(one.out / "wide.csv").condition) == [1, 2, 3, 4]


def answer_of(screen: dict) -> dict:
    """Valid answers to any screen of the paper study: the first robot offered, mid-scale points."""
    labels = [robot["label"] for robot in screen.get("robots", [])]
    answers = {}
    for name in screen.get("questions", []):
        answers[name] = {
            "better": labels[0] if labels else None,
            "ranking": labels,
            "justification": "it was faster",
            "explanation": "ranked by speed",
        }.get(name, 3)
    return answers


def test_bad_database_and_study_are_named(tmp_path, survey_db, paper_study):
    from app.analysis.source import analysis_database, analysis_study

    with pytest.raises(ValueError, match="no database file"):
        analysis_database(f"sqlite:///{tmp_path / 'missing.sqlite3'}")
    empty = tmp_path / "empty.sqlite3"
    empty.touch()
    with pytest.raises(ValueError, match="not a usable survey database"):
        analysis_database(f"sqlite:///{empty}")
    with pytest.raises(ValueError, match="--study FILE"):
        analysis_study(survey_db, None)


def test_the_server_stores_its_study_file(make_client):
    from app.analysis.source import analysis_study

    context = make_client({"platform": '"none"'}).app.state.context
    assert analysis_study(context.db, None) == context.study


def test_study_stored_in_the_database(survey_db, paper_study):
    from app.analysis.source import analysis_study, remember_study

    path, study = paper_study
    remember_study(survey_db, path.read_text(), study)
    assert analysis_study(survey_db, None) == study == analysis_study(survey_db, "paper")
    other = parse_study(path.read_text().replace('id = "paper"', 'id = "pilot"'))
    remember_study(survey_db, path.read_text().replace('id = "paper"', 'id = "pilot"'), other)
    remember_study(survey_db, path.read_text().replace('id = "paper"', 'id = "pilot"'), other)  # a restart
    assert analysis_study(survey_db, "pilot").study.id == "pilot"
    with pytest.raises(ValueError, match=r"stored: \['paper', 'pilot'\]"):
        analysis_study(survey_db, None)
    with pytest.raises(ValueError, match="no study file nope"):
        analysis_study(survey_db, "nope")


def test_comprehension_answers_are_in_long_and_leave_wide_as_it_is(survey_db, bundle_dir, tmp_path):
    """The instructions' comprehension answers (always the expected one: a wrong one is refused) are long.csv rows
    of the instructions screen; wide.csv has no column for them and is written as without them."""
    study = parse_study(
        study_text(platform='"none"', assignment='"balanced"')
        + """
[[comprehension]]
text = "Which robot is better?"
options = ["The first", "The one that reaches its goal without touching anyone"]
expected = "The one that reaches its goal without touching anyone"
"""
    )
    understood = {"understand1": study.comprehension[0].expected}
    add_participant(
        survey_db,
        study,
        bundle_dir,
        condition=0,
        seed=5,
        answer=lambda screen: understood if screen["kind"] == "instructions" else answer_of(screen),
    )
    result = export_study(survey_db, study, tmp_path / "out")
    long = pd.read_csv(result.out / "long.csv")
    (row,) = long[long.step == 0].itertuples()
    assert (row.screen, row.question, row.answer) == ("instructions", "understand1", understood["understand1"])
    assert (row.question_type, row.truth, row.correct) == ("comprehension", understood["understand1"], 1)
    wide = pd.read_csv(result.out / "wide.csv")
    assert not any("understand" in column for column in wide.columns) and len(wide) == 1
