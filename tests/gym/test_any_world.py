"""A world Foil was never written for, through every command: the tiny track of tests/gym/test_gym_clips.py with
only its adapter and TOML files, through eval, every solver (the representative one and the field's summary methods
included), verify, render, bundle and the served survey, all by the command line as a researcher runs them."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.store.database import migrate
from app.web.main import create_app
from app.web.settings import ServerSettings
from search.cli import main
from tests.gym.test_gym_clips import TrackAdapter
from tests.support.survey import start, walk

ADAPTER = "tests.gym.test_gym_clips:TrackAdapter"
FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"


def track_study(design: str, pairs: str, build: str) -> str:
    """A study of runners on the tiny track, its pairwise part's ``pairs`` (a TOML list) asked which is better:
    the ``[design]`` table's lines and the ``[build]`` table's after its seed and evaluation."""
    return f"""
[study]
id = "track"
title = "Which runner is better?"
platform = "none"
assignment = "balanced"
seed = 1
estimated_minutes = 2

[design]
{design}

[texts]
consent = "A test study."
instructions = "Watch the clips."

[completion]
code = "TRACK"

[[parts]]
kind = "pairwise"
title = "Which is better?"
intro = "Watch each clip."
pairs = {pairs}
questions = ["better"]

[questions.better]
type = "choose"
text = "Which is better?"

[build]
seed = 1

[build.eval]
episodes = 4
seed = 0

{build}"""


STUDY = track_study(
    """schemes = ["nfirst", "representative", "disagreements", "highlights"]
scheme_factor = "within"
scenarios = ["track.toml"]

[design.scheme_scenarios]
representative = ["track-starts.toml"]""",
    f'[["{FAST}", "{SLOW}"]]',
    f"""[build.representativeness]
distribution = "track-starts.toml"
states = 4
pushes = 2

[build.render]
speed = 4.0
width = 480

[build.schemes.nfirst]
solver = "nfirst"
budget = 60
seed = 0
top_k = 1

[build.schemes.representative]
solver = "representative"
budget = 400
seed = 0
settings = {{ states = 4, pushes = 2 }}

[build.schemes.disagreements]
solver = "disagreements"
budget = 200
seed = 0
settings = {{ horizon = 4 }}

[build.schemes.highlights]
solver = "highlights-div"
budget = 300
seed = 0
settings = {{ highlights = 1, context = 3, lookahead = 2 }}

[[build.sets]]
parts = ["pairwise"]
schemes = ["nfirst", "disagreements", "highlights"]
scenarios = ["track.toml"]
agents = ["{FAST}", "{SLOW}"]

[[build.sets]]
parts = ["pairwise"]
schemes = ["representative"]
scenarios = ["track-starts.toml"]
agents = ["{FAST}", "{SLOW}"]
""",
)


@pytest.fixture
def world(tmp_path, monkeypatch):
    """A researcher's folder: a scenario, a distribution of starting states and a study file, read from the
    working directory."""
    (tmp_path / "track.toml").write_text(f'adapter = "{ADAPTER}"\nseed = 3\n')
    (tmp_path / "track-starts.toml").write_text(f'adapter = "{ADAPTER}"\n[distribution]\nseeds = [0, 100]\n')
    (tmp_path / "study.toml").write_text(STUDY)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_eval_counts_each_ending_as_the_adapter_reads_it(world, capsys):
    assert main(["eval", FAST, "--scenario", "track.toml", "--episodes", "4", "--json"]) == 0
    fast = json.loads(capsys.readouterr().out)
    assert main(["eval", SLOW, "--scenario", "track.toml", "--episodes", "4", "--json"]) == 0
    slow = json.loads(capsys.readouterr().out)
    assert (fast["collision_rate"], fast["timeout_rate"]) == (1.0, 0.0)  # runs into the wall
    assert (slow["collision_rate"], slow["timeout_rate"]) == (0.0, 1.0)  # out of time before it
    assert main(["eval", FAST, "--episodes", "4"]) == 2 and "--scenario FILE" in capsys.readouterr().err


@pytest.mark.parametrize(
    "solver", ["mcts", "nfirst", "random", "cem", "representative", "disagreements", "highlights", "highlights-div"]
)
def test_every_solver_searches_and_every_summary_verifies(world, capsys, solver):
    scenario = "track-starts.toml" if solver == "representative" else "track.toml"
    args = ["--budget", "120", "--top-k", "2", "--out", "out", "--quiet", "--reward", "horizon_steps=6"]
    if solver == "representative":  # (pushes + 1) x horizon steps a state at most: 120 fit 6 of 3 rollouts each
        args += ["--set", "pushes=2"]
    assert main(["search", "--agents", f"{FAST},{SLOW}", "--scenario", scenario, "--solver", solver, *args]) == 0
    summaries = sorted((world / "out").glob("summary-*.json"))
    assert summaries and main(["verify", *map(str, summaries)]) == 0
    if solver == "representative":
        vote = json.loads((world / "out" / "run.json").read_text())["vote"]
        assert vote["direction"] == -1  # the slow runner, which never hits the wall, looks better
        assert json.loads(summaries[0].read_text())["scenario"]["name"].startswith("track-starts#")


def test_a_study_renders_bundles_and_serves_in_the_worlds_own_words(world, capsys):
    assert main(["bundle", "study.toml", "--out", "bundle"]) == 0
    log = capsys.readouterr().out
    assert "representativeness track.toml" in log
    manifest = json.loads((world / "bundle" / "manifest.json").read_text())
    assert manifest["world"]["domain"] == "gym" and len(manifest["clips"]) == 4
    assert {c["scheme"]: c["audit"]["shows"] for c in manifest["clips"]}["representative"] == "better"
    [reels] = [c for c in manifest["clips"] if c["scheme"] == "highlights"]
    assert [reel["agent"] for reel in reels["reels"]] == reels["agents"]
    assert all(c["spent"]["sim_steps"] > 0 for c in manifest["clips"])
    summary = world / "bundle" / manifest["clips"][0]["summary"]
    assert main(["render", str(summary), "--out", "again.mp4"]) == 0 and (world / "again.mp4").stat().st_size > 0
    database = f"sqlite:///{world / 'survey.sqlite3'}"
    migrate(database)
    settings = ServerSettings(
        bundle_dir=world / "bundle", study_file=world / "bundle" / "study.toml", database_url=database
    )
    with TestClient(create_app(settings), follow_redirects=True) as client:
        seen = "\n".join(walk(client, start(client)))
    assert "Clip of two agents side by side" in seen and "FOIL" not in seen and "TRACK" in seen
    assert "Each agent is shown on its own" in seen  # the reels' screen, in the world's words
    assert not re.search(r"person|people|crowd", seen, re.IGNORECASE)


class LastingTrack(TrackAdapter):
    """The track where lasting is the task: running into the wall later is better."""

    rule = "survival"


def middling(observations):
    """Runs at half speed: reaches the wall in some starting states, runs out of time in others."""
    return np.full((len(observations), 1), 0.5)


@pytest.mark.parametrize("adapter", [ADAPTER, "tests.gym.test_any_world:LastingTrack"])
def test_the_fast_rollouts_score_every_clip_as_its_summary_does(world, adapter):
    """The Gymnasium domain reads each rollout's ending from the problem; the interface's default builds each
    rollout's summary. Both must see the same clips, by the adapter's own rule, and each pair read from three
    agents' rollouts must be the pair's own."""
    from search.core.domain import domain_for
    from tests.support.played import checked_rollouts

    (world / "starts.toml").write_text(f'adapter = "{adapter}"\n[distribution]\nseeds = [0, 100]\n')
    agents = [FAST, SLOW, "tests.gym.test_any_world:middling"]
    domain = domain_for(agents, "starts.toml")
    states = domain.draw_states("starts.toml", {}, np.random.default_rng(0), 6)
    fast = checked_rollouts(domain, agents, states, 6, 3).pair(0, 1)[0]
    assert (fast.contrast < 0).all()  # the slow runner, which never hits the wall, looks better in every rollout
