"""The methods study (studies/methods.toml) built for real on scripted agents with tiny budgets: every summary method
under one budget, HIGHLIGHTS as a pair of reels, what each clip spent, and a bundle the server takes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from app.formats import sha256_file
from app.survey.bundle import load_bundle
from search.bundle.build import build_bundle
from search.solvers.summary import verify

pytestmark = pytest.mark.slow

STUDY = Path(__file__).parents[2] / "studies" / "methods.toml"
AGENTS = {"lo": "goal", "med": "orca", "hi": "social_force"}
BUILD = """[build]
seed = 3

[build.eval]
episodes = 4
seed = 0

[build.budget]
steps = 600
clip_seconds = 6

[build.render]
speed = 6.0
hold_start = 0.2
hold_end = 0.2
event_hold = 0.2

[build.representativeness]
states = 2
pushes = 1

[build.schemes.adaptive]
solver = "mcts"
seed = 0
top_k = 3
select = "contrast"

[build.schemes.nfirst]
solver = "nfirst"
seed = 0

[build.schemes.representative]
solver = "representative"
seed = 0
settings = { states = 3, pushes = 1 }

[build.schemes.disagreements]
solver = "disagreements"
seed = 0
top_k = 2

[build.schemes.highlights]
solver = "highlights-div"
seed = 0
settings = { highlights = 2, lookahead = 2 }

[[build.sets]]
parts = ["pairwise", "ranking"]
schemes = ["adaptive", "nfirst"]
scenarios = ["paper-bl-tr", "paper-tl-br"]
agents = ["goal", "orca", "social_force"]

[[build.sets]]
parts = ["pairwise", "ranking"]
schemes = ["representative", "disagreements", "highlights"]
scenarios = ["training"]
agents = ["goal", "orca", "social_force"]

[[build.sets]]
parts = ["example"]
schemes = ["nfirst"]
scenarios = ["paper-code"]
pairs = [["goal", "social_force"]]
"""


def scripted_study() -> str:
    """studies/methods.toml's survey tables with scripted agents in place of the shipped ones, and tiny budgets."""
    text = STUDY.read_text()
    text = text[: text.index("\n[build]\n")] + "\n"
    for shipped, scripted in AGENTS.items():
        text = re.sub(rf'"{shipped}"', f'"{scripted}"', text)
    return text + BUILD


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("methods")
    study = root / "methods.toml"
    study.write_text(scripted_study())
    manifest = build_bundle(study, root / "out", log=lambda line: None, workers=2)
    return root / "out", json.loads((root / "out" / "manifest.json").read_text()), manifest


def test_every_method_has_its_clips_and_what_each_spent(built):
    out, manifest, _ = built
    schemes = {clip["scheme"] for clip in manifest["clips"]}
    assert schemes == {"adaptive", "nfirst", "representative", "disagreements", "highlights"}
    for clip in manifest["clips"]:
        spent = clip["spent"]
        assert 0 < spent["sim_steps"] <= 600 + 64 * 24 and spent["clip_seconds"] > 0  # a batch may overshoot
    for name, digest in manifest["files"].items():
        assert sha256_file(out / name) == digest, name


def test_highlights_clips_are_a_reel_per_agent_of_that_agent_alone(built):
    out, manifest, _ = built
    reels = [clip for clip in manifest["clips"] if clip["scheme"] == "highlights"]
    assert len(reels) == 3 and all("file" not in clip or not clip["file"] for clip in reels)
    for clip in reels:
        assert [reel["agent"] for reel in clip["reels"]] == clip["agents"]
        for reel in clip["reels"]:
            assert sha256_file(out / reel["file"]) == reel["sha256"] and (out / reel["poster"]).is_file()
            assert 1 <= len(reel["summaries"]) <= 2
            for path in reel["summaries"]:
                summary = json.loads((out / path).read_text())
                leader = summary["follow"]["leader"]
                assert summary["agents"][leader]["name"] == reel["agent"] == summary["solver"]["reel"]
                assert verify(out / path) == []


def test_disagreement_clips_fork_and_verify(built):
    out, manifest, _ = built
    for clip in (c for c in manifest["clips"] if c["scheme"] == "disagreements"):
        summary = json.loads((out / clip["summary"]).read_text())
        first, last = summary["window"]
        assert summary["follow"]["leader"] == 0 and first <= summary["follow"]["steps"] < last
        assert last - first <= 24  # six seconds of 0.25 s steps: h = 24
        assert verify(out / clip["summary"]) == []


def test_the_server_takes_the_bundle(built):
    out, manifest, _ = built
    bundle = load_bundle(out)
    assert set(bundle.clips) == {clip["id"] for clip in manifest["clips"]}
