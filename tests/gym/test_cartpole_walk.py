"""docs/gym.md's walk, on a tiny budget: CartPole with gusts from its adapter and TOML files alone
(docs/examples/cartpole) through eval, search, verify, render, bundle and the served survey."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

from fastapi.testclient import TestClient

from app.store.database import migrate
from app.web.main import create_app
from app.web.settings import ServerSettings
from search.cli import main
from tests.support.survey import start, walk

EXAMPLE = Path(__file__).parents[2] / "docs" / "examples" / "cartpole"
AGENTS = "cartpole_push:nudge,cartpole_push:steady"
CROWD_WORDS = re.compile(r"\b(robots?|crowds?|pedestrians?|humans?|bumped|a person|people)\b", re.IGNORECASE)


def visible_text(html: str) -> str:
    """What a page says to a reader: its text and its attributes' words, without the markup, styles and scripts
    (class names such as robot-colour-1 are the stylesheet's, not the reader's)."""
    html = re.sub(r"<(style|script)\b.*?</\1>", " ", html, flags=re.DOTALL | re.IGNORECASE)
    said = re.findall(r'(?:alt|title|aria-label|placeholder)="([^"]*)"', html)
    return " ".join([re.sub(r"<[^>]+>", " ", html), *said])


def small(text: str) -> str:
    """The example study with budgets for a test."""
    changes = (
        ("budget = 20_000", "budget = 1_500"),
        ("budget = 4_000", "budget = 400"),
        ("episodes = 20", "episodes = 4"),
    )
    for old, new in changes:
        assert old in text
        text = text.replace(old, new)
    return text


def test_the_cartpole_walk_runs_as_the_docs_say(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "cartpole"
    shutil.copytree(EXAMPLE, folder, ignore=shutil.ignore_patterns("__pycache__"))
    (folder / "study.toml").write_text(small((folder / "study.toml").read_text()))
    monkeypatch.chdir(folder)

    assert main(["eval", "cartpole_push:steady", "--scenario", "cartpole.toml", "--episodes", "3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["success_rate"] == 1.0  # keeps the pole up for CartPole's 500 steps
    common = ["--agents", AGENTS, "--reward", "horizon_steps=200", "--quiet", "--top-k", "1"]
    assert main(["search", *common, "--scenario", "cartpole.toml", "--budget", "300", "--out", "out"]) == 0
    rep = ["--solver", "representative", "--set", "states=3", "--set", "pushes=2"]
    assert (
        main(["search", *common, *rep, "--scenario", "cartpole-starts.toml", "--budget", "1500", "--out", "rep"]) == 0
    )
    assert main(["verify", "out/summary-001.json", "rep/summary-001.json"]) == 0
    assert main(["render", "rep/summary-001.json", "--out", "clip.mp4", "--speed", "4"]) == 0
    assert (folder / "clip.sheet.png").is_file()

    assert main(["bundle", "study.toml", "--out", "bundle"]) == 0
    log = capsys.readouterr()
    assert "representativeness cartpole.toml" in log.out
    gallery = (folder / "bundle" / "index.html").read_text()
    assert CROWD_WORDS.findall(log.out + log.err + gallery) == []  # the build speaks of agents, in CartPole's words
    manifest = json.loads((folder / "bundle" / "manifest.json").read_text())
    assert manifest["world"]["domain"] == "cartpole" and manifest["world"]["rule"] == "survival"
    assert {c["audit"]["shows"] for c in manifest["clips"]} == {"better"}
    database = f"sqlite:///{folder / 'cartpole.sqlite3'}"
    migrate(database)
    settings = ServerSettings(bundle_dir=folder / "bundle", study_file=folder / "study.toml", database_url=database)
    with TestClient(create_app(settings), follow_redirects=True) as client:
        seen = "\n".join(walk(client, start(client)))
    assert "balancing a pole on its own cart" in seen and "FOIL-CARTPOLE" in seen
    assert CROWD_WORDS.findall(visible_text(seen)) == []
