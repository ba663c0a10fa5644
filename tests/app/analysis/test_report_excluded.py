"""`foil report` on a pilot whose every participant the rules exclude (bots of the pilot link):
the report says so, how many each rule met and how to look anyway; --include-excluded analyses them and the report
says at its top, in its title and in what it prints that they are included. Never the default."""

from __future__ import annotations

import pytest
from sqlalchemy import update

from app.analysis.report import render_report, tally_study
from app.store.models import Participant
from tests.app.analysis.test_report import known_answers
from tests.support.analysis import add_participant

TOLD = "All 3 participants were excluded (pilot_or_bot: 3), so nothing is analysed."
INCLUDED = "This report includes 3 of 3 participants whom the exclusion rules leave out"


@pytest.fixture
def pilot_db(survey_db, paper_study, bundle_dir):
    """Three bots of the pilot link, every answer right: the rules leave bots out."""
    _, study = paper_study
    for condition in range(3):
        add_participant(survey_db, study, bundle_dir, condition=condition, answer=known_answers(), seed=condition)
    with survey_db.writing() as session:
        session.execute(update(Participant).values(kind="bot"))
    return survey_db


def test_a_report_whose_participants_are_all_excluded_says_so_and_how_to_look_anyway(pilot_db, paper_study):
    _, study = paper_study
    data = tally_study(pilot_db, study)
    assert (data.exclusions.before, data.exclusions.after, data.exclusions.flagged) == (3, 0, 3)
    html = render_report(data)
    assert TOLD in html and "--include pilot,bot applies the other rules" in html
    assert "--include-excluded" in html and "Not fitted: no answers" in html
    assert "<title>Report: " in html and INCLUDED not in html


def test_include_excluded_analyses_them_marked_as_such(pilot_db, paper_study, tmp_path, monkeypatch, capsys):
    from search.cli import main

    path, study = paper_study
    data = tally_study(pilot_db, study, include_excluded=True)
    assert (data.exclusions.before, data.exclusions.after, data.exclusions.flagged) == (3, 3, 3)
    assert data.tally("pairwise", "all scenarios", study.design.schemes[0]).correct > 0

    monkeypatch.delenv("FOIL_BUNDLE_DIR", raising=False)
    command = ["report", "--db", pilot_db.url, "--study", str(path), "--out"]
    assert main([*command, str(tmp_path / "plain")]) == 0
    plain = capsys.readouterr().out
    assert "3 participants, 0 analysed after exclusions" in plain and TOLD in plain
    assert main([*command, str(tmp_path / "included"), "--include-excluded"]) == 0
    included = capsys.readouterr().out
    assert "3 participants, 3 analysed after exclusions" in included and INCLUDED in included
    html = (tmp_path / "included" / "report.html").read_text()
    assert "<title>Report (excluded participants included): " in html and INCLUDED in html
    assert "<h1>Excluded participants included: " in html and "no answers" not in html.split('id="exclusions"')[0]
    rows = (tmp_path / "included" / "exclusions.csv").read_text()
    assert "analysed (every participant: --include-excluded),3" in rows
