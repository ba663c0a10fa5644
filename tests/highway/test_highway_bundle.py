"""The highway study: studies/highway.toml plans and checks against the server, and a tiny highway bundle builds
(evaluations, searches, clips, manifest, gallery) and serves."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from search.bundle.build import build_bundle
from search.bundle.searches import plan_clips, search_inputs, search_job
from search.bundle.spec import load_build
from tests.support.survey import planned_bundle

ROOT = Path(__file__).resolve().parents[2]
STUDY = ROOT / "studies" / "highway.toml"


def test_the_highway_study_plans_highway_searches_the_server_accepts():
    from app.survey.bundle import check_study_against_bundle
    from app.survey.study import load_study

    spec, _ = load_build(STUDY)
    jobs = plan_clips(spec)
    inputs = [search_inputs(search_job(job)) for job in jobs]
    assert {i["scenario"]["domain"] for i in inputs} == {"gym"}
    assert all(len(agent["sha256"]) == 64 for i in inputs for agent in i["agents"])  # the shipped files' checksums
    check_study_against_bundle(load_study(STUDY), planned_bundle(jobs, ROOT))


@pytest.mark.parametrize("name", ["highway.toml", "methods-highway.toml"])
def test_a_highway_studys_instructions_say_what_a_car_that_lasts_reads_on_its_clips(name):
    """The instructions name a car that lasted the drive as its clips' status line and legend do ("drove through"),
    not in words of their own."""
    from app.survey.study import load_study
    from search.highway.adapter import HighwayAdapter

    instructions = load_study(ROOT / "studies" / name).texts.instructions
    assert f'"{HighwayAdapter.status_words["success"]}"' in instructions
    assert "drives through" not in instructions


def test_a_highway_study_mixing_worlds_is_refused_at_its_line(tmp_path):
    from search.bundle.spec import BuildError

    study = tmp_path / "study.toml"
    study.write_text(STUDY.read_text().replace('pairs = [["highway-lo", "highway-hi"]]', 'pairs = [["lo", "hi"]]'))
    with pytest.raises(BuildError, match="cannot mix worlds"):
        build_bundle(study, tmp_path / "out", log=lambda line: None)


@pytest.mark.slow
def test_a_tiny_highway_bundle_builds_and_serves(tmp_path):
    from app.store.database import migrate
    from app.web.main import create_app
    from app.web.settings import ServerSettings

    text = STUDY.read_text().replace("budget = 600", "budget = 40").replace("episodes = 100", "episodes = 3")
    text = text.replace("budget = 5_000", "budget = 200").replace("states = 64", "states = 2")
    # one fixed scenario of the two, and part one alone on the example's two cars: every scheme's clip of one pair
    # (4 clips with the example's, where three cars and the ranking part made 13 the same way)
    text = text.replace('scenarios = ["highway-dense", "highway-four-lanes"]', 'scenarios = ["highway-dense"]')
    text = text.replace('["highway-traffic", "highway-traffic"]', '["highway-traffic"]')
    text, ranking = re.subn(r'\[\[parts\]\]\nkind = "ranking"\n.*?\n\n', "", text, flags=re.DOTALL)
    text = re.sub(r"pairs = \[\[.*\]\]\n", 'pairs = [["highway-lo", "highway-hi"]]\n', text, count=1)
    text = text.replace('parts = ["pairwise", "ranking"]', 'parts = ["pairwise"]')
    text = text.replace('agents = ["highway-lo", "highway-med", "highway-hi"]', 'agents = ["highway-lo", "highway-hi"]')
    text = text.replace(
        "[build.eval]",
        "[build.render]\nspeed = 20.0\nfps = 20\nhold_start = 0.2\nhold_end = 0.2\nevent_hold = 0.2\nwidth = 320\n\n"
        "[build.eval]",
    )
    assert ranking == 1
    study = tmp_path / "highway.toml"
    study.write_text(text)
    log = []
    manifest = build_bundle(study, tmp_path / "bundle", log=log.append)
    out = tmp_path / "bundle"
    assert len(manifest.clips) == 4 and set(manifest.agents) == {"highway-lo", "highway-hi"}
    assert {clip.scheme for clip in manifest.clips} == {"adaptive", "nfirst", "representative"}
    for clip in manifest.clips:
        assert (out / clip.file).is_file() and (out / clip.poster).is_file() and clip.audit is not None
        assert json.loads((out / clip.summary).read_text())["scenario"]["domain"] == "gym"
    assert manifest.world is not None and manifest.world["rule"] == "survival"
    assert any(line.startswith("representativeness highway-dense") for line in log)
    assert "highway-hi" in (out / "index.html").read_text()
    database = f"sqlite:///{tmp_path / 'survey.sqlite3'}"
    migrate(database)
    app = create_app(
        ServerSettings(
            bundle_dir=out, study_file=out / "study.toml", database_url=database, admin_password="a-long-admin-password"
        )
    )
    try:
        page = TestClient(app, follow_redirects=True).get("/")
        assert page.status_code == 200 and "Which self-driving car handles the highway better?" in page.text
    finally:
        app.state.context.db.dispose()
