"""Admin pages: password from the environment, progress, per-participant view, exclusion flag, CSV."""

from __future__ import annotations

import csv
import io
import re
import zipfile

import pytest
from fastapi.testclient import TestClient

from app.store.models import Participant
from app.survey.kinds import pilot_token
from app.web.settings import ServerSettings
from tests.support.survey import FormReader, answer_for, finish, log_in, start, stored

BALANCED = {"platform": '"prolific"', "assignment": '"balanced"'}


def test_admin_is_off_without_a_password(make_client):
    client = make_client(BALANCED, admin_password=None)
    for path in ("/admin", "/admin/login", "/admin/export.csv", "/admin/report", "/admin/export.zip"):
        response = client.get(path)
        assert response.status_code == 404 and "FOIL_ADMIN_PASSWORD" in response.text


def test_short_admin_password_refuses_to_start(bundle_dir):
    with pytest.raises(ValueError, match="at least 8 characters"):
        ServerSettings(bundle_dir=bundle_dir, admin_password="short")


def test_admin_pages_need_the_password(make_client):
    client = make_client(BALANCED)
    for path in ("/admin", "/admin/export.csv", "/admin/participants/abc", "/admin/report", "/admin/export.zip"):
        response = client.get(path, follow_redirects=False)
        assert response.status_code == 303 and response.headers["location"] == "/admin/login"
    wrong = log_in(client, "not the password")
    assert wrong.status_code == 401 and "Wrong password" in wrong.text
    assert client.get("/admin", follow_redirects=False).status_code == 303
    assert log_in(client).status_code == 200
    assert client.get("/admin").status_code == 200
    page = client.get("/admin")
    client.post("/admin/logout", data={"csrf_token": FormReader(page.text).hidden["csrf_token"]})
    assert client.get("/admin", follow_redirects=False).status_code == 303


def finished_and_halfway(client) -> tuple[TestClient, str]:
    """One participant who completed the study and one who answered its first screen: the second's client and the
    page it is on."""
    finisher = TestClient(client.app)
    finish(finisher, start(finisher, "?PROLIFIC_PID=done1&STUDY_ID=s&SESSION_ID=a"))
    halfway = TestClient(client.app)
    page = start(halfway, "?PROLIFIC_PID=half2&STUDY_ID=s&SESSION_ID=b")
    return halfway, halfway.post("/study", data=answer_for(page)).text


def test_the_median_duration_leaves_bots_out_and_a_participant_page_says_its_kind(make_client):
    client = make_client(BALANCED)
    token = pilot_token(client.app.state.context.db, "paper")
    bot = TestClient(client.app)
    finish(bot, start(bot, f"?PROLIFIC_PID=bot3&STUDY_ID=s&SESSION_ID=c&pilot={token}&bot=1"))
    log_in(client)
    overview = client.get("/admin").text
    assert "Median duration of the 0 real participants who completed (pilots and bots left out)" in overview
    assert "none completed yet" in overview
    (row,) = stored(client, Participant)
    detail = client.get(f"/admin/participants/{row.code}").text
    assert row.kind == "bot" and "<dt>Kind</dt><dd>bot (left out of the analysis unless included)</dd>" in detail


def test_progress_median_participant_view_exclusion_and_csv(make_client):
    client = make_client(BALANCED)
    halfway, page = finished_and_halfway(client)
    evil = '<script>alert(1)</script>=HYPERLINK("http://x")'
    halfway.post("/study", data={**answer_for(page), "justification": evil})

    log_in(client)
    overview = client.get("/admin").text
    assert "Median duration of the 1 real participant who completed (pilots and bots left out)" in overview
    assert "2 participants." in overview
    moment = r"<td>\d{4}-\d\d-\d\dT\d\d:\d\d\+00:00</td>"  # ISO 8601 with the time zone
    assert len(re.findall(moment, overview)) == 4  # each participant's start and last activity
    assert "done1" in overview and "half2" in overview
    finished, started = stored(client, Participant)
    row = overview.split("<tbody>")[1].split("</tbody>")[0]
    assert row.count("<tr>") == 4  # one row per condition
    totals = overview.split("<tfoot>")[1].split("</tfoot>")[0]
    assert "<td>1</td><td>1</td><td>0</td><td>0</td>" in totals  # started, completed, returned, declined

    detail = client.get(f"/admin/participants/{started.code}").text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in detail and "<script>alert(1)" not in detail
    assert "half2" in detail
    assert re.search(r"<dt>Started</dt><dd>\d{4}-\d\d-\d\dT\d\d:\d\d\+00:00</dd>", detail)
    token = FormReader(detail).hidden["csrf_token"]
    assert (
        client.post(
            f"/admin/participants/{started.code}/exclusion", data={"excluded": "1", "note": "too fast"}
        ).status_code
        == 403
    )
    saved = client.post(
        f"/admin/participants/{started.code}/exclusion", data={"csrf_token": token, "excluded": "1", "note": "too fast"}
    )
    assert saved.status_code == 200
    person = stored(client, Participant)[1]
    assert person.excluded and person.exclusion_note == "too fast"
    assert (
        client.post(
            f"/admin/participants/{started.code}/exclusion", data={"csrf_token": token, "excluded": "maybe"}
        ).status_code
        == 400
    )
    assert client.get("/admin/participants/nobody").status_code == 404

    export = client.get("/admin/export.csv")
    assert export.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(export.text)))
    for row in rows:  # a code may start with "-", which the export neutralises with an apostrophe
        row["participant"] = row["participant"].removeprefix("'")
    mine = [r for r in rows if r["participant"] == finished.code]
    assert len({r["step"] for r in mine}) == len(finished.plan)
    choices = [r for r in mine if r["question"] == "better"]
    assert len(choices) == 6 and all(r["correct"] in ("0", "1") for r in choices)
    assert all(r["answer_agent"] in r["agents"].split(";") for r in choices)
    rankings = [r for r in mine if r["question"] == "ranking"]
    assert len(rankings) == 2 and all(r["answer"].count(">") == 2 for r in rankings)
    typed = [r for r in rows if r["participant"] == started.code and r["question"] == "justification"]
    assert typed[0]["answer"] == evil

    archive = client.get("/admin/export.zip")
    assert archive.headers["content-type"] == "application/zip"
    with zipfile.ZipFile(io.BytesIO(archive.content)) as zipped:
        names = sorted(name.split("/")[1] for name in zipped.namelist())
        people = list(csv.DictReader(io.StringIO(zipped.read("paper-export/participants.csv").decode())))
    assert names == ["codebook.json", "codebook.md", "glmer.R", "long.csv", "participants.csv", "wide.csv"]
    assert [(p["participant"].removeprefix("'"), p["flagged_by_admin"], p["excluded"]) for p in people] == [
        (finished.code, "0", "0"),
        (started.code, "1", "1"),
    ]

    report = client.get("/admin/report")
    assert report.status_code == 200 and "Table 1" in report.text and "<script" not in report.text
    assert "style-src 'unsafe-inline'" in report.headers["content-security-policy"]
    assert "uses the one analysed participant only" in report.text  # the other one is flagged and incomplete


def test_csv_neutralises_spreadsheet_formulas(make_client):
    client = make_client(BALANCED)
    page = start(client, "?PROLIFIC_PID=f1&STUDY_ID=s&SESSION_ID=a")
    page = client.post("/study", data=answer_for(page)).text
    client.post("/study", data={**answer_for(page), "justification": "=1+1"})
    log_in(client)
    rows = list(csv.DictReader(io.StringIO(client.get("/admin/export.csv").text)))
    assert [r["answer"] for r in rows if r["question"] == "justification"] == ["'=1+1"]


def test_participant_page_names_screens_as_the_participant_saw_them(make_client):
    client = make_client(BALANCED)
    finished_and_halfway(client)
    finished, started = stored(client, Participant)
    log_in(client)

    detail = client.get(f"/admin/participants/{finished.code}").text
    cells = [
        cell.split("</td>")[0]
        for cell in detail.split("<tbody>")[1].split("<tr>")[1:]
        for cell in [cell.split("<td>", 1)[1]]
    ]
    assert cells[0] == "Instructions"
    assert "Part 1 of 2, clip 1 of 6" in cells and "Part 1 of 2, clip 6 of 6" in cells
    assert "Part 2 of 2, round 1 of 2, clip 3 of 3" in cells and "Part 2 of 2, round 2 of 2, ranking" in cells
    assert not any("ranking 4" in cell or "pairwise" in cell for cell in cells)  # no plan indices, no kinds
    assert f"all {len(finished.plan)} answered" in detail

    current = client.get(f"/admin/participants/{started.code}").text
    assert f"2 of {len(started.plan)}: Part 1 of 2, clip 1 of 6" in current
