"""Independent work over worker processes (search.core.workers): `foil eval`'s episodes and the representative
solver's starting states give byte-identical results in 1, 2 and 4 processes, and a bad count is refused."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from search.cli import main
from search.core.workers import in_order, jobs, workers
from search.gym.agents import load_agent
from tests.gym.test_gym_clips import TrackAdapter

ADAPTER = "tests.gym.test_gym_clips:TrackAdapter"
FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"


@pytest.fixture
def world(tmp_path, monkeypatch):
    """The tiny track of tests/gym/test_gym_clips.py: a scenario and a distribution of starting states."""
    (tmp_path / "track.toml").write_text(f'adapter = "{ADAPTER}"\nseed = 3\n')
    (tmp_path / "starts.toml").write_text(f'adapter = "{ADAPTER}"\n[distribution]\nseeds = [0, 100]\n')
    monkeypatch.chdir(tmp_path)
    return tmp_path


def square(x: int, y: int) -> tuple[int, int]:
    return x * x + y, workers()


def test_results_come_back_in_order_and_a_worker_does_its_share_itself():
    tasks = [(x, 1) for x in range(7)]
    assert in_order(square, tasks, 2) == [(x * x + 1, 1) for x in range(7)]  # a worker starts no workers of its own
    assert in_order(square, tasks, 1) == [(x * x + 1, workers()) for x in range(7)]


def test_an_agent_pickles_as_its_name_and_source():
    agent = load_agent(FAST, TrackAdapter())
    again = pickle.loads(pickle.dumps(agent))
    assert (again.name, again.source) == (agent.name, agent.source) and again.policy is agent.policy
    observations = np.zeros((3, 2))
    assert np.array_equal(again.act(observations), agent.act(observations))


def test_eval_is_byte_identical_in_one_two_and_four_processes(world, capsys):
    printed = []
    for count in (1, 2, 4):  # 40 episodes: five chunks of side-by-side episodes
        assert main(["eval", SLOW, "--scenario", "track.toml", "--episodes", "40", "--json", "--jobs", str(count)]) == 0
        printed.append(capsys.readouterr().out)
    assert printed[0] == printed[1] == printed[2]
    assert json.loads(printed[0])["episodes"] == 40


def test_a_representative_search_is_byte_identical_in_one_two_and_four_processes(world, capsys):
    found = []
    for count in (1, 2, 4):
        out = world / f"out{count}"
        args = [
            "--budget",
            "200",
            "--top-k",
            "2",
            "--quiet",
            "--reward",
            "horizon_steps=6",
            "--set",
            "pushes=2",
            "--set",
            "states=5",
        ]
        assert (
            main(
                ["search", "--agents", f"{FAST},{SLOW}", "--scenario", "starts.toml", "--solver", "representative"]
                + [*args, "--out", str(out), "--jobs", str(count)]
            )
            == 0
        )
        run = json.loads((out / "run.json").read_text())
        summaries = [p.read_bytes() for p in sorted(out.glob("summary-*.json"))]
        found.append((summaries, run["vote"], run["sim_steps"]))
    assert found[0][1]["states"] == 5  # every state voted, over the workers
    assert found[0] == found[1] == found[2]


@pytest.mark.parametrize("command", ["eval", "search", "search-all"])
def test_no_processes_is_refused(world, capsys, command):
    args = {
        "eval": ["eval", SLOW, "--scenario", "track.toml", "--episodes", "4"],
        "search": ["search", "--agents", f"{FAST},{SLOW}", "--scenario", "track.toml", "--out", "o"],
        "search-all": ["search-all", "--agents", f"{FAST},{SLOW}", "--scenarios", "track.toml", "--out", "o"],
    }[command]
    assert main([*args, "--jobs", "0"]) == 2
    assert "--jobs must be at least 1" in capsys.readouterr().err


def test_jobs_sets_the_count_within_and_restores_it():
    before = workers()
    with jobs(3):
        assert workers() == 3
    assert workers() == before
