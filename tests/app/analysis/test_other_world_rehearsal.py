"""A world that is not the crowd, from its served pages to its bots' rehearsal of the analysis: a bundle whose world
says only `Words(agent="Car")` reads "Car" and "cars" everywhere Foil writes (pages, codebook, CSV files, glmer.R,
report) and never the crowd's words, and bots run fast through the pilot link are analysed when the researcher
includes them (the timing and viewing rules, which only make sense for people, are skipped for them)."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest

from app.analysis.bots import simulate
from app.survey.kinds import pilot_token
from app.visible import Words, World
from search.cli import main
from tests.app.analysis.test_simulate import serve
from tests.support.analysis import SCHEMES, write_bot_bundle
from tests.support.survey import start, study_text, walk

CROWD = re.compile(r"\b(robots?|crowds?|pedestrians?|humans?|bumped|a person|people)\b", re.IGNORECASE)
# participants are people in any world: in what an analysis writes, "people" is no crowd word
CROWD_IN_ANALYSIS = re.compile(r"\b(robots?|crowds?|pedestrians?|humans?|bumped|a person)\b", re.IGNORECASE)
CARS = World(domain="cars", rule="survival", words=Words(agent="Car"))


def car_study() -> str:
    """The paper study's survey, its own texts told of cars: what Foil writes is then all that could name robots."""
    text = study_text()
    for crowd, cars in (
        (r"\brobots\b", "cars"),
        (r"\bRobots\b", "Cars"),
        (r"\brobot\b", "car"),
        (r"\bRobot\b", "Car"),
        (r"\b(a crowd of people|a crowd|the crowd|people|a person|person|humans|human)\b", "traffic"),
        (r"\bbumping\b", "crashing"),
        (r"\bwalking\b", "driving"),
    ):
        text = re.sub(crowd, cars, text)
    assert not CROWD.findall(text)
    return text


@pytest.fixture(scope="module")
def car_bundle(tmp_path_factory) -> Path:
    """The analysis tests' bundle (a summary per clip), its labels Car N and its manifest's world CARS."""
    # clips longer than the server's viewing tolerance, so that a bot run fast answers sooner than they play
    root = write_bot_bundle(tmp_path_factory.mktemp("car-clips"), tmp_path_factory.mktemp("car-bundle"), seconds=3)
    manifest = json.loads((root / "manifest.json").read_text())
    for clip in manifest["clips"]:
        clip["labels"] = [label.replace("Robot", "Car") for label in clip["labels"]]
    (root / "manifest.json").write_text(json.dumps(manifest | {"world": CARS.to_manifest()}))
    return root


def shown(page: str) -> str:
    """What a page says: its text and its accessible names, without its markup (class names such as robot-key)."""
    names = re.findall(r'(?:aria-label|title|alt)="([^"]*)"', page)
    return html.unescape(re.sub(r"<[^>]+>", " ", page) + "\n" + "\n".join(names))


def said(folder: Path) -> str:
    return "\n".join(
        path.read_text() for path in sorted(folder.iterdir()) if path.suffix in (".csv", ".md", ".json", ".R", ".html")
    )


def test_a_car_worlds_pages_speak_of_cars(make_client, car_bundle, tmp_path):
    study = tmp_path / "study.toml"
    study.write_text(car_study())
    client = make_client(bundle_dir=car_bundle, study_file=study)
    pages = "\n".join(walk(client, start(client, "?workerId=W1&assignmentId=A1&hitId=H1")))
    # a refused answer's page shows the text the test's participant typed ("the robot kept its distance")
    assert CROWD.findall(re.sub(r"Answer to \w+: the robot kept its distance\.", "", shown(pages))) == []
    assert "such as Car 7" in pages and "Every car has a name" in pages and 'aria-label="Cars in the clip"' in pages
    assert "Choose one car for each place." in pages


def test_bots_rehearse_a_car_worlds_analysis_in_its_words(car_bundle, tmp_path, capsys):
    served = serve(tmp_path, car_bundle, car_study())
    url, db_url, study_file = next(served)
    try:
        from app.analysis.source import analysis_database

        db = analysis_database(db_url)
        token = pilot_token(db, "paper")
        db.dispose()
        runs = simulate(url, car_bundle, 4, noise=0.3, seed=2, pilot_token=token)
        assert all(run.completed for run in runs)
    finally:
        next(served, None)
    capsys.readouterr()
    args = ["--db", db_url, "--include", "bot", "--min-seconds", "600"]  # faster than any person could be
    assert main(["export", *args, "--out", str(tmp_path / "export")]) == 0
    exported = capsys.readouterr().out
    assert main(["report", *args, "--out", str(tmp_path / "report")]) == 0
    reported = capsys.readouterr().out
    for out in (exported, reported):
        assert "timing and viewing rules skipped for bots" in out
    assert "4 participants, 4 analysed after exclusions" in reported  # fast as they were, the bots are analysed
    for scheme in SCHEMES:
        assert re.search(rf"^{scheme}: pairwise \d+/12, ranking \d+/4$", reported, re.MULTILINE)

    written = said(tmp_path / "export") + shown(said(tmp_path / "report"))
    assert CROWD_IN_ANALYSIS.findall(written) == []
    codebook = (tmp_path / "export" / "codebook.md").read_text()
    assert "(e.g. Car 1)" in codebook and "the car label chosen" in codebook and "k cars" in codebook
    report = (tmp_path / "report" / "report.html").read_text()
    assert "which car is better" in report and "all cars in the right order" in report
    assert "timing and viewing rules skipped for bots" in report
    assert json.loads((tmp_path / "export" / "codebook.json").read_text())["exclusion_rules"]["bots"]
