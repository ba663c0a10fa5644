"""A summary method is one module and its registration: the runner, the study file and the bundle builder take a
new one from the registry without an edit, and a solver is refused, before any work, a problem that lacks what it
needs."""

from __future__ import annotations

import json
from dataclasses import dataclass

import pytest

from search.bundle.searches import plan_clips, search_inputs, search_job
from search.bundle.spec import BuildError, parse_build
from search.core.problem import ActionValues, Follows, require
from search.core.rollout import Tracker
from search.solvers.baselines import SamplingConfig, random_search
from search.solvers.episodes import Episodes, play
from search.solvers.follow import ALWAYS, Follow
from search.solvers.runner import SearchJob, run_search, write_outputs
from search.solvers.solver import SOLVERS, Comparison, ProblemSearch, register, solver_named, solvers
from search.solvers.summary import verify
from search.solvers.watching import Summarize, Watching
from tests.gym.test_gym_problem import BOX, scenario_file
from tests.support.synthetic import LockProblem


@dataclass(frozen=True)
class SpacedConfig:
    episodes: int = 1  # episodes the first agent plays (the first is the one shown)
    spacing: int = 5  # steps between the starts of two moments
    context: int = 4  # steps each moment shows


class Spaced(Watching):
    """The first K moments of the first agent's first episode, ``spacing`` steps apart: a summary that knows
    nothing of importance, as small as a summary method gets."""

    name = "spaced"
    config_class = SpacedConfig

    def watch(
        self, groups: list[Episodes], tracker: Tracker, config: SpacedConfig, summary: Summarize, comparison: Comparison
    ) -> tuple[list[dict], dict]:
        group = groups[0]
        problem = group.coupled.problem
        problem.reset(1)
        problem.override = Follow(0, ALWAYS)
        length = int(play(problem, group.env[:1], tracker, lambda t, running: None)[0])
        starts = list(range(0, length - config.context + 1, config.spacing))[: tracker.queue.k]
        moments = [
            summary(group, group.first, s + config.context, Follow(0, s + config.context), (s, s + config.context), {})
            for s in starts
        ]
        return moments, {"played": length, "starts": starts}


@pytest.fixture
def spaced():
    """The method registered for one test, and gone after it, so no other test sees it among the solvers."""
    method = register(Spaced())
    yield method
    del SOLVERS[method.name]


def test_a_new_summary_method_runs_from_its_registration_alone(spaced, tmp_path):
    job = SearchJob(
        agents=BOX,
        scenario=scenario_file(tmp_path),
        solver="spaced",
        budget=500,
        top_k=3,
        reward_settings={"horizon": 40},
        solver_config=SpacedConfig(spacing=3),
    )
    files = run_search(job)
    run = json.loads(files["run.json"])
    assert run["method"]["starts"] == [0, 3, 6] and run["method"]["played"] >= 10
    assert run["solver"]["name"] == "spaced" and run["solver"]["parameters"] == {
        "episodes": 1,
        "spacing": 3,
        "context": 4,
    }
    out = write_outputs(tmp_path / "out", files)
    summaries = sorted(out.glob("summary-*.json"))
    assert len(summaries) == 3
    for rank, (path, start) in enumerate(zip(summaries, [0, 3, 6], strict=True), start=1):
        data = json.loads(path.read_text())
        assert data["window"] == [start, start + 4] and data["solver"]["rank"] == rank
        assert data["solver"]["budget_used"] == run["sim_steps"]
        assert verify(path) == []


def test_a_study_file_takes_a_new_solver_and_checks_its_settings(spaced):
    text = """\
[build]
seed = 7
[build.budget]
clip_seconds = 10.0
[build.schemes.spaced]
solver = "spaced"
budget = 300
seed = 1
[build.schemes.spaced.settings]
spacing = 3
[[build.sets]]
parts = ["example"]
schemes = ["spaced"]
scenarios = ["paper-code"]
pairs = [["goal", "orca"]]
"""
    (job,) = plan_clips(parse_build(text))
    search = search_job(job)
    assert search.solver_config == SpacedConfig(spacing=3)
    assert search_inputs(search)["solver_settings"] == {"episodes": 1, "spacing": 3, "context": 4}
    assert search.reward_settings["horizon"] == 40  # 10 s of clip at the crowd's 0.25 s a step: the default hold
    with pytest.raises(BuildError, match=r"build\.schemes\.spaced\.settings\.spcing: unknown solver setting"):
        parse_build(text.replace("spacing = 3", "spcing = 3"))


def test_a_solver_is_refused_a_problem_without_a_capability_it_needs():
    """The crowd's problem has no action values: a search that needs them says so before it spends a step."""
    greedy = register(ProblemSearch("greedy", SamplingConfig, random_search, needs=(ActionValues,)))
    try:
        with pytest.raises(ValueError, match=r"the greedy solver needs a problem with ActionValues .*CoupledProblem"):
            run_search(SearchJob(agents=("goal", "orca"), scenario="paper-code", solver="greedy", budget=100))
    finally:
        del SOLVERS[greedy.name]
    with pytest.raises(ValueError, match=r"LockProblem has no override and no proposed: give it override and proposed"):
        require(LockProblem(), (Follows,), "spaced")
    assert Follows in solver_named("highlights").needs and not solver_named("mcts").needs


def test_a_name_is_registered_once_and_an_unknown_one_lists_the_known():
    with pytest.raises(ValueError, match="a solver named 'mcts' is registered already"):
        register(ProblemSearch("mcts", SamplingConfig, random_search))
    with pytest.raises(ValueError, match=r"unknown solver 'annealing': use one of \['cem', 'disagreements'"):
        solver_named("annealing")
    assert {
        "mcts",
        "nfirst",
        "random",
        "cem",
        "representative",
        "disagreements",
        "highlights",
        "highlights-div",
    } == set(solvers())
