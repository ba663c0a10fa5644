"""Every budget is a bound: each registered solver, run through `foil search`'s runner on a tiny world, takes no
more simulator steps than its budget, finds trajectories within it, and run.json says what it spent. Batched
solvers used to finish whatever was in flight when the budget ran out (MCTS's first batch alone is 64
trajectories)."""

from __future__ import annotations

import json

import pytest

from search.solvers.runner import SearchJob, run_search
from search.solvers.solver import solver_named, solvers

FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"
# Settings that let each solver start at the smallest budgets here: the representative solver needs one starting
# state's rollouts, (pushes + 1) x horizon steps, to fit.
SETTINGS = {"representative": {"pushes": 2, "states": 4}}


@pytest.fixture
def track(tmp_path):
    """The tiny track of tests/gym/test_gym_clips.py: a scenario and a distribution of starting states."""
    (tmp_path / "track.toml").write_text('adapter = "tests.gym.test_gym_clips:TrackAdapter"\nseed = 3\n')
    (tmp_path / "starts.toml").write_text(
        'adapter = "tests.gym.test_gym_clips:TrackAdapter"\n[distribution]\nseeds = [0, 100]\n'
    )
    return tmp_path


@pytest.mark.parametrize("budget", [19, 50, 333])
@pytest.mark.parametrize("solver", sorted(solvers()))
def test_no_solver_takes_more_steps_than_its_budget(track, solver, budget):
    found = solver_named(solver)
    scenario = track / ("starts.toml" if found.starts == "distribution" else "track.toml")
    job = SearchJob(
        agents=(FAST, SLOW),
        scenario=str(scenario),
        solver=solver,
        budget=budget,
        top_k=3,
        solver_config=found.config_class(**SETTINGS.get(solver, {})),
        reward_settings={"horizon": 6},
        seed=1,
    )
    files = run_search(job)
    record = json.loads(files["run.json"])
    assert 0 < record["sim_steps"] <= budget
    assert record["solver"]["budget"] == budget and record["solver"]["budget_used"] == record["sim_steps"]
    summaries = [json.loads(text) for name, text in files.items() if name.startswith("summary-")]
    assert summaries and all(s["solver"]["budget_used"] == record["sim_steps"] for s in summaries)


@pytest.mark.parametrize("solver", ["mcts", "random"])
def test_a_search_that_spends_its_budget_stops_on_it_in_the_crowd(solver):
    """The crowd's batched searches, whose trajectories end at different steps, stop exactly on the budget."""
    job = SearchJob(
        agents=("lo", "hi"), scenario="paper-bl-tr", solver=solver, budget=777, top_k=2, reward_settings={"horizon": 20}
    )
    assert json.loads(run_search(job)["run.json"])["sim_steps"] == 777


def test_a_budget_too_small_for_any_trajectory_says_so(track, capsys, monkeypatch):
    from search.cli import main

    monkeypatch.chdir(track)
    args = ["--scenario", "track.toml", "--budget", "5", "--reward", "horizon_steps=6", "--out", "out", "--quiet"]
    assert main(["search", "--agents", f"{FAST},{SLOW}", *args]) == 0  # MCTS: the track's episodes last 6 steps
    assert "no trajectory ended within the budget of 5 steps: raise --budget" in capsys.readouterr().out
