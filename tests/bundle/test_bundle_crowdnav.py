"""A bundle comparing an imported CrowdNav_DSRNN agent with a scripted one: both evaluated and searched in the
world its config describes, and the manifest says which checkpoint and which world."""

from __future__ import annotations

import json

import pytest

from app.formats import sha256_file
from app.survey.bundle import load_bundle
from search.bundle.build import build_bundle
from search.cli import main
from tests.support.crowdnav import HUMANS, SCENARIO, write_model
from tests.support.survey import survey_tables

pytestmark = pytest.mark.slow

STUDY = (
    survey_tables()
    + """
[build]
seed = 3

[build.eval]
episodes = 4
seed = 0

[build.render]
speed = 6.0

[build.schemes.nfirst]
solver = "nfirst"
budget = 200
seed = 1

[[build.sets]]
parts = ["pairwise"]
schemes = ["nfirst"]
scenarios = ["{scenario}"]
pairs = [["{checkpoint}", "goal"]]
"""
)


def test_a_bundle_records_the_checkpoint_and_the_world_each_agent_was_compared_in(tmp_path):
    checkpoint = str(write_model(tmp_path / "model"))
    scenario = tmp_path / "three.toml"
    scenario.write_text(SCENARIO)
    study = tmp_path / "study.toml"
    study.write_text(STUDY.format(scenario=scenario, checkpoint=checkpoint))
    out = tmp_path / "out"
    manifest = build_bundle(study, out, log=lambda line: None).model_dump(mode="json")
    imported, scripted = manifest["sources"][checkpoint], manifest["sources"]["goal"]
    assert imported["kind"] == "crowdnav_dsrnn" and imported["checkpoint"] == checkpoint
    assert imported["sha256"] == sha256_file(checkpoint)
    assert imported["config"] == str(tmp_path / "model" / "configs" / "config.py")
    assert imported["trained_world"]["human_num"] == HUMANS
    assert scripted["kind"] == "scripted"
    for source in (imported, scripted):  # both compared in the imported agent's world
        assert source["world"]["goal_change_chance"] == 0.25 and source["world"]["human_v_pref"] == 1.0
    assert manifest["agents"]["goal"]["time_limit"] == 49.0
    # the scenario's representativeness is measured in that world too (the imported agent takes its 3 humans)
    assert [report["scenario"] for report in manifest["representativeness"]] == [str(scenario)]
    [clip] = manifest["clips"]
    summary = out / clip["summary"]
    assert json.loads(summary.read_text())["scenario"]["world"]["randomize_attributes"] is True
    assert main(["verify", str(summary)]) == 0
    assert set(load_bundle(out).clips) == {clip["id"]}
