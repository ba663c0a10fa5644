"""A world from a package of its own (tests/plugin/lineworld: carts on a line in gusts of wind, no Gymnasium
environment, with a summary method of its own), installed by pip into a folder of its own and found through its
``foil.domains`` and ``foil.solvers`` entry points alone, taken through every command as a researcher runs them:
eval, search with Foil's solvers and its own, verify, render, bundle and the served survey, in the world's own
words."""

from __future__ import annotations

import importlib
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import search.solvers.solver as solver_registry
from app.store.database import migrate
from app.web.main import create_app
from app.web.settings import ServerSettings
from search.cli import main
from search.core.domain import domain_for, domains
from tests.support.survey import start, walk

PACKAGE = Path(__file__).parent / "lineworld"
PAIR = "line-hasty,line-careful"
STUDY = """
[study]
id = "carts"
title = "Which cart is better?"
platform = "none"
assignment = "balanced"
seed = 1
estimated_minutes = 2

[design]
schemes = ["nfirst"]
scheme_factor = "within"
scenarios = ["line-short"]

[texts]
consent = "A test study."
instructions = "Watch the clips."

[completion]
code = "CARTS"

[[parts]]
kind = "pairwise"
title = "Which is better?"
intro = "Watch each clip."
pairs = [["line-hasty", "line-careful"]]
questions = ["better"]

[questions.better]
type = "choose"
text = "Which is better?"

[build]
seed = 1
world = "line"

[build.eval]
episodes = 4
seed = 0

[build.render]
speed = 4.0
width = 320

[build.schemes.nfirst]
solver = "nfirst"
budget = 60
seed = 0
top_k = 1

[[build.sets]]
parts = ["pairwise"]
schemes = ["nfirst"]
scenarios = ["line-short"]
agents = ["line-hasty", "line-careful"]
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The package installed by pip, from a copy of its source (pip builds there), into a folder of its own."""
    source = tmp_path_factory.mktemp("source") / "lineworld"
    shutil.copytree(PACKAGE, source)
    target = tmp_path_factory.mktemp("site")
    command = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation"]
    subprocess.run([*command, "--target", str(target), str(source)], check=True)
    return target


@pytest.fixture
def world(site, tmp_path, monkeypatch):
    """A researcher's folder with the plugin on the path; the installed worlds are read afresh on both sides, and
    the plugin's modules and the solvers they register are gone afterwards, as in a process without it."""
    monkeypatch.setattr(solver_registry, "SOLVERS", dict(solver_registry.solvers()))
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.chdir(tmp_path)
    domains.cache_clear()
    yield tmp_path
    domains.cache_clear()
    for name in [name for name in sys.modules if name.split(".")[0] == "lineworld"]:
        del sys.modules[name]


def test_the_plugin_is_found_by_its_names_its_files_and_its_key(world):
    assert domain_for(["line-hasty", "line-careful"], "line-short").name == "line"
    (world / "long.toml").write_text("[line]\ngoal = 6.0\n")
    assert domain_for(["line-hasty", "line-careful"], "long.toml").name == "line"  # by its content
    (world / "both.toml").write_text("[line]\ngoal = 6.0\n[robot]\nstart = [0.0, 0.0]\ngoal = [1.0, 1.0]\n")
    with pytest.raises(ValueError, match='add world = "crowd" or world = "line" to the scenario file'):
        domain_for([], "both.toml")
    (world / "both.toml").write_text('world = "line"\n[line]\ngoal = 6.0\n[robot]\nstart = [0.0, 0.0]\n')
    assert domain_for(["line-hasty", "line-careful"], "both.toml").name == "line"
    with pytest.raises(ValueError, match=r"cannot mix worlds: line-hasty \(line\), hi \(crowd\)"):
        domain_for(["line-hasty", "hi"])


def test_eval_and_train(world, capsys):
    results = {}
    for agent in ("line-hasty", "line-careful"):
        assert main(["eval", agent, "--scenario", "line-short", "--episodes", "20", "--json"]) == 0
        results[agent] = json.loads(capsys.readouterr().out)
    assert results["line-hasty"]["collision_rate"] > 0 and results["line-careful"]["collision_rate"] == 0
    assert main(["eval", "line-hasty", "--scenario", "line-short", "--time-limit", "3"]) == 2
    assert "in the line world an episode ends" in capsys.readouterr().err
    (world / "train.toml").write_text('world = "line"\n')
    assert main(["train", "--config", "train.toml", "--out", "run"]) == 2
    assert "the line world has no trainer of its own" in capsys.readouterr().err


@pytest.mark.parametrize("solver", ["mcts", "nfirst", "line-sweep"])  # Foil's own and the plugin's
def test_search_verify_and_render(world, capsys, solver):
    args = ["--budget", "120", "--top-k", "2", "--out", "out", "--quiet", "--solver", solver]
    assert main(["search", "--agents", PAIR, "--scenario", "line-short", *args]) == 0
    summaries = sorted((world / "out").glob("summary-*.json"))
    assert summaries and main(["verify", *map(str, summaries)]) == 0
    best = json.loads(summaries[0].read_text())
    assert len({o["event"] for o in best["outcomes"]}) == 2  # the search found the carts ending differently
    assert main(["render", str(summaries[0]), "--out", "clip.mp4", "--speed", "4", "--width", "320"]) == 0
    assert (world / "clip.mp4").stat().st_size > 0 and (world / "clip.poster.png").is_file()


CROWD_WORDS = re.compile(r"\b(robots?|crowds?|pedestrians?|humans?|bumped|a person|people)\b", re.IGNORECASE)


def test_a_study_bundles_and_serves_in_the_worlds_own_words(world, capsys):
    (world / "study.toml").write_text(STUDY)
    assert main(["bundle", "study.toml", "--out", "bundle"]) == 0
    manifest = json.loads((world / "bundle" / "manifest.json").read_text())
    assert manifest["world"]["domain"] == "line" and len(manifest["clips"]) == 1
    gallery, log = (world / "bundle" / "index.html").read_text(), capsys.readouterr()
    for written in (gallery, json.dumps(manifest["world"]), log.out, log.err):
        assert CROWD_WORDS.findall(written) == []
    assert "which cart tipped over, which reached the flag and when" in gallery
    database = f"sqlite:///{world / 'survey.sqlite3'}"
    migrate(database)
    settings = ServerSettings(
        bundle_dir=world / "bundle", study_file=world / "bundle" / "study.toml", database_url=database
    )
    with TestClient(create_app(settings), follow_redirects=True) as client:
        seen = "\n".join(walk(client, start(client)))
    assert "Clip of two carts on a line" in seen and "CARTS" in seen
    assert not re.search(r"person|people|crowd", seen, re.IGNORECASE)


def test_the_world_writes_ten_methods_and_foil_the_rest(world, capsys):
    from search.core.domain import Domain

    LineDomain = importlib.import_module("lineworld").LineDomain  # installed by the fixture, unknown to mypy
    written = {name for name, value in vars(LineDomain).items() if callable(value) and not name.startswith("_")}
    assert Domain.__abstractmethods__ <= written and "play" in written and len(written) <= 10
    line = LineDomain()
    assert line.parse_world(["goal=6", "limit=9"]) == {"goal": 6.0, "limit": 9}  # the default check of `settings`
    with pytest.raises(ValueError, match=r"--world setting limit = 'soon': give a int, such as 8"):
        line.parse_world(["limit=soon"])
    with pytest.raises(ValueError, match=r"unknown --world setting\(s\) \['wind'\]; known --world settings"):
        line.parse_world(["wind=2"])
    assert line.describe_agents() == "the line world takes line-..."
    assert line.agent_source("line-hasty", {}) == {"kind": "scripted"}
    # the evaluation Foil computes from the episodes the world plays, with its documented keys
    assert main(["eval", "line-careful", "--scenario", "line-long", "--episodes", "6", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"success_rate", "success_ci95", "reward_mean", "reward_ci95", "length_mean"} <= set(result)
    rates = [result[f"{ending}_rate"] for ending in ("success", "collision", "timeout")]
    assert result["episodes"] == 6 and sum(rates) == pytest.approx(1.0)
    assert main(["eval", "line-careful", "--scenario", "line-long", "--episodes", "6"]) == 0
    assert f"line-careful: 6 episodes (seed 0), success rate {rates[0]:.3f}" in capsys.readouterr().out


@pytest.mark.parametrize("solver", ["disagreements", "highlights"])
def test_a_literature_method_is_refused_before_any_work(world, capsys, solver):
    """The line world's carts choose no actions of their own, so they cannot follow a leader: the methods that
    need it are refused, naming the capability and where it is documented, before a step is played."""
    args = ["--agents", PAIR, "--scenario", "line-short", "--budget", "120", "--out", "out", "--quiet"]
    assert main(["search", *args, "--solver", solver]) == 2
    error = capsys.readouterr().err
    assert f"the {solver} solver needs a problem with Follows" in error
    assert 'docs/worlds.md, "What the summary methods need of a world"' in error and "LineProblem has no" in error
    assert not (world / "out").exists()


def test_a_study_with_a_literature_method_is_refused_before_any_work(world, capsys):
    (world / "study.toml").write_text(STUDY.replace('solver = "nfirst"', 'solver = "highlights"'))
    assert main(["bundle", "study.toml", "--out", "bundle"]) == 2
    error = capsys.readouterr().err
    assert "the highlights solver needs a problem with Follows" in error and "LineProblem has no" in error
    assert not (world / "bundle" / "cache").exists()  # no agent evaluated, no search run
