"""HIGHLIGHTS' and Agent Disagreements' episodes from drawn starting states over worker processes
(search.solvers.episodes.in_turn): the summaries and run.json are byte-identical in 1, 2 and 4 processes, with a
budget that plays every episode and with one that stops the groups' play part way (where a group played ahead must
play again from where the groups before it leave the count)."""

from __future__ import annotations

import json

import pytest

from search.cli import main
from search.core.domain import Problems
from search.gym.domain import GymDomain
from search.highway.domain import HighwayDomain

ADAPTER = "tests.gym.test_gym_clips:TrackAdapter"
AGENTS = "tests.gym.test_gym_clips:fast,tests.gym.test_gym_clips:slow"
WALL_TIMES = ("wall_s", "search_wall_s", "steps_per_s")


@pytest.fixture
def world(tmp_path, monkeypatch):
    """The tiny track of tests/gym/test_gym_clips.py, its starting states drawn from a distribution."""
    (tmp_path / "starts.toml").write_text(f'adapter = "{ADAPTER}"\n[distribution]\nseeds = [0, 100]\n')
    monkeypatch.chdir(tmp_path)
    return tmp_path


def searched(world, solver: str, budget: int, jobs: int, settings: list[str]) -> tuple[list[bytes], dict]:
    out = world / f"{solver}-{budget}-{jobs}"
    args = ["search", "--agents", AGENTS, "--scenario", "starts.toml", "--solver", solver, "--quiet"]
    args += ["--budget", str(budget), "--top-k", "3", "--reward", "horizon_steps=6", "--out", str(out)]
    for setting in settings:
        args += ["--set", setting]
    assert main([*args, "--jobs", str(jobs)]) == 0
    run = json.loads((out / "run.json").read_text())
    return [p.read_bytes() for p in sorted(out.glob("summary-*.json"))], {
        k: v for k, v in run.items() if k not in WALL_TIMES
    }


@pytest.mark.parametrize(
    ("solver", "settings", "budgets"),
    [
        # the stand-in importance: each state measured by rollouts of every alternative action
        ("highlights", ["episodes=11", "highlights=2", "lookahead=2"], (4000, 300)),
        ("disagreements", ["episodes=11"], (4000, 40)),
    ],
)
def test_a_method_is_byte_identical_in_one_two_and_four_processes(world, solver, settings, budgets):
    for budget in budgets:
        found = [searched(world, solver, budget, jobs, settings) for jobs in (1, 2, 4)]
        summaries, run = found[0]
        assert summaries and run["sim_steps"] <= budget
        assert found[0] == found[1] == found[2]


def test_only_a_world_without_a_batched_fast_path_spreads_its_episodes():
    assert Problems.batched and HighwayDomain.batched and not GymDomain.batched
