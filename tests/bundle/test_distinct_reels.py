"""An agent met in several questions of one part is shown in other moments each time: three runners on the tiny
track of tests/gym/test_gym_clips.py, every pair in one pairwise part under HIGHLIGHTS-DIV, so each runner has two
reels in the part. Each shows other moments of its runs, and the bundle is the same every time it is built."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.formats import sha256_file
from search.bundle.build import build_bundle
from search.bundle.searches import plan_clips
from search.bundle.spec import BuildError, parse_build
from tests.gym.test_any_world import track_study

FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"
MIDDLING = "tests.bundle.test_distinct_reels:middling"
RUNNERS = f'["{FAST}", "{MIDDLING}", "{SLOW}"]'
PAIRS = f'[["{FAST}", "{MIDDLING}"], ["{FAST}", "{SLOW}"], ["{MIDDLING}", "{SLOW}"]]'


def middling(observations):
    """Runs at about half the fast runner's pace."""
    return np.full((len(observations), 1), 0.45)


STUDY = track_study(
    'schemes = ["highlights"]\nscheme_factor = "within"\nscenarios = ["track.toml"]',
    PAIRS,
    """[build.render]
speed = 4.0
width = 320

[build.schemes.highlights]
solver = "highlights-div"
budget = 300
seed = 0
settings = { highlights = 1, context = 3, lookahead = 2 }
SCHEME

[[build.sets]]
parts = ["pairwise"]
schemes = ["highlights"]
scenarios = ["track.toml"]
agents = RUNNERS
""".replace("RUNNERS", RUNNERS),
)


def study(folder: Path, scheme: str = "") -> Path:
    """The study file in ``folder``, its highlights scheme with the lines ``scheme`` added."""
    (folder / "track.toml").write_text('adapter = "tests.gym.test_gym_clips:TrackAdapter"\nseed = 3\n')
    path = folder / "study.toml"
    path.write_text(STUDY.replace("SCHEME", scheme))
    return path


def reels_of(bundle: Path) -> dict[str, list[tuple[list[tuple[int, int]], str]]]:
    """Per agent, each of its reels in the bundle: the moments it shows (episode, state) and its video's sha256."""
    manifest = json.loads((bundle / "manifest.json").read_text())
    found: dict[str, list[tuple[list[tuple[int, int]], str]]] = {}
    for clip in manifest["clips"]:
        for reel in clip["reels"]:
            entries = [json.loads((bundle / path).read_text())["solver"] for path in reel["summaries"]]
            moments = [(entry["episode"], entry["state_step"]) for entry in entries]
            found.setdefault(reel["agent"], []).append((moments, reel["sha256"]))
    return found


def test_an_agents_reels_in_one_part_show_other_moments_in_every_build(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # where the study's scenario file is
    first, again = tmp_path / "first", tmp_path / "again"
    for bundle in (first, again):
        build_bundle(study(tmp_path), bundle, log=lambda line: None)
    reels = reels_of(first)
    assert sorted(reels) == sorted([FAST, MIDDLING, SLOW]) and all(len(two) == 2 for two in reels.values())
    for (moments, video), (other_moments, other_video) in reels.values():
        assert set(moments).isdisjoint(other_moments) and video != other_video
    files = [path.relative_to(first) for path in sorted([*first.glob("clips/*"), *first.glob("summaries/*")])]
    assert files and all(sha256_file(first / file) == sha256_file(again / file) for file in files)
    assert (first / "manifest.json").read_text() == (again / "manifest.json").read_text()


def test_reels_repeat_only_where_the_study_lets_them(tmp_path, monkeypatch):
    """Each reel search is told how many reels of each of its agents the part shows before it; a scheme with
    reels = "repeat" shows one reel per agent in every question, and a solver without reels takes no such key."""
    monkeypatch.chdir(tmp_path)

    def earlier(scheme: str) -> list[tuple[int, int]]:
        spec = parse_build(study(tmp_path, scheme).read_text())
        return [job.scheme.solver_config.earlier for job in plan_clips(spec)]

    assert earlier("") == [(0, 0), (1, 0), (1, 1)]  # fast-middling, fast-slow, middling-slow
    assert earlier('reels = "repeat"') == [(0, 0)] * 3
    text = study(tmp_path).read_text().replace('solver = "highlights-div"', 'solver = "nfirst"\nreels = "repeat"')
    with pytest.raises(BuildError, match="build.schemes.highlights.reels: the nfirst solver shows no reels"):
        parse_build(text.replace("settings = { highlights = 1, context = 3, lookahead = 2 }", ""))
