"""The coupled problem for Gymnasium environments, on the tiny corridor environment of tests/gym/corridor.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.core.rollout import Tracker
from search.gym.adapter import load_adapter
from search.gym.agents import load_agent
from search.gym.problem import GymCoupledProblem, GymScenario, GymSnapshot
from search.solvers.reward import RewardConfig
from search.solvers.runner import SearchJob, run_search, write_outputs
from search.solvers.solver import ProblemSearch, solvers
from search.solvers.summary import verify

ADAPTER = "tests.gym.corridor:CorridorAdapter"
FAST = "tests.gym.corridor:FastCorridorAdapter"
BOX = ("tests.gym.corridor:straight", "tests.gym.corridor:dodging")
DISCRETE = ("tests.gym.corridor:straight_moves", "tests.gym.corridor:dodging_moves")


def scenario(discrete: bool = False, seed: int = 3, adapter: str = ADAPTER) -> GymScenario:
    return GymScenario("corridor", adapter, seed, {"discrete": discrete})


def scenario_file(folder, discrete: bool = False, adapter: str = ADAPTER, seed: int = 3) -> str:
    """The corridor scenario as a researcher writes it: a TOML file naming the adapter."""
    path = folder / f"corridor-{adapter.rpartition(':')[2]}-{int(discrete)}.toml"
    path.write_text(f'adapter = "{adapter}"\nseed = {seed}\n[settings]\ndiscrete = {str(discrete).lower()}\n')
    return str(path)


def problem(discrete: bool = False, adapter: str = ADAPTER, **reward) -> GymCoupledProblem:
    chosen = scenario(discrete, adapter=adapter)
    adapter = chosen.load_adapter()
    return GymCoupledProblem(
        [load_agent(spec, adapter) for spec in (DISCRETE if discrete else BOX)], chosen, RewardConfig(**reward)
    )


def walkers(p: GymCoupledProblem) -> np.ndarray:
    return np.array([[instance.env.walker for instance in row] for row in p.rows])


@pytest.mark.parametrize("adapter", [ADAPTER, FAST])
@pytest.mark.parametrize("discrete", [False, True])
def test_restore_continues_exactly_as_the_original_did(discrete, adapter):
    p = problem(discrete, adapter)
    p.reset(3)
    rng = np.random.default_rng(0)
    for _ in range(3):
        p.step(rng.uniform(-1, 1, (3, 1)))
    saved = p.snapshot()
    later = rng.uniform(-1, 1, (6, 3, 1))
    first = [p.step(a) for a in later], walkers(p)
    p.restore(saved)
    second = [p.step(a) for a in later], walkers(p)
    for (r1, t1), (r2, t2) in zip(first[0], second[0], strict=True):
        assert np.array_equal(r1, r2) and np.array_equal(t1, t2)
    assert np.array_equal(first[1], second[1])  # the wind (the environment's generator) was restored too


def test_snapshot_rows_assign_and_concat_keep_each_row():
    p = problem()
    p.reset(2)
    p.step(np.array([[1.0], [-1.0]]))
    both = p.concat([p.snapshot([1]), p.snapshot([0])])
    p.restore(both)
    swapped = walkers(p)
    p.assign([0], p.snapshot([1]))
    assert np.array_equal(walkers(p)[0], swapped[1]) and np.array_equal(p.t, [1, 1])


def test_each_agent_has_its_own_instance_from_the_same_seeded_state():
    p = problem()
    p.reset(1)
    first, second = p.rows[0]
    assert first.env is not second.env
    assert np.array_equal(first.observation, second.observation)
    other = GymCoupledProblem(p.agents, scenario(seed=4), RewardConfig())
    other.reset(1)
    assert not np.array_equal(other.rows[0][0].observation, first.observation)  # the seed sets the start


def test_box_divergence_is_the_norm_of_the_scaled_action_difference():
    p = problem()
    box = p.divergence
    assert box.actions([box.scaled([1.0, 0.0]), box.scaled([0.3, 1.0])]) == pytest.approx(np.hypot(0.7, 1.0))
    squared = problem(norm="squared").divergence
    assert squared.actions([squared.scaled([1.0, 0.0]), squared.scaled([0.3, 1.0])]) == pytest.approx(1.49)
    assert box.actions([box.scaled([2.0, 0.0]), box.scaled([1.0, 0.0])]) == 0.0  # clipped to the box first


def test_discrete_divergence_counts_different_choices():
    d = problem(discrete=True).divergence
    assert d.actions([d.scaled(1), d.scaled(1)]) == 0.0
    assert d.actions([d.scaled(1), d.scaled(3)]) == 1.0
    assert d.actions([d.finished(), d.finished()]) == 1.0  # a finished agent matches nothing
    assert problem(discrete=True, combine="min").divergence.actions([d.scaled(1), d.scaled(1), d.scaled(2)]) == 0.0


def test_events_map_to_success_collision_and_timeout():
    adapter = load_adapter(ADAPTER)
    assert adapter.outcome(True, False, {"is_success": True}) == "success"
    assert adapter.outcome(True, False, {"crashed": True}) == "collision"
    assert adapter.outcome(False, True, {}) == "timeout"
    for finish in ("all", "first"):
        p = problem(finish=finish)
        p.reset(1)
        for _ in range(12):  # the obstacle driven onto the straight walker's line: it hits it near x = 2.5
            obstacle_y = p.rows[0][0].env.obstacle[1]
            reward, terminal = p.step(np.clip([[-obstacle_y / 0.5]], -1, 1))
            if p.rows[0][0].outcome:
                break
        crashed, other = p.rows[0]
        assert (crashed.outcome, other.outcome) == (2, 0)  # collision; the dodging walker goes on
        assert bool(terminal[0]) == (finish == "first")
    where = crashed.env.walker.copy()
    p = problem()
    p.restore(GymSnapshot([[crashed, other]], np.array([crashed.event_step])))
    p.step(np.zeros((1, 1)))
    assert np.array_equal(p.rows[0][0].env.walker, where)  # a finished agent stands still


@pytest.mark.parametrize("solver", sorted(name for name, s in solvers().items() if isinstance(s, ProblemSearch)))
def test_every_solver_searches_the_gym_problem(solver):
    p = problem(horizon=40)
    tracker = Tracker(300, 5)
    search = solvers()[solver]
    search.run(p, tracker, np.random.default_rng(0), search.config_class())
    assert tracker.trajectories > 0 and tracker.curve  # nfirst stops after its N trajectories
    assert len(tracker.queue.ranked()) == min(5, tracker.trajectories)


@pytest.mark.parametrize("agents", [BOX, DISCRETE])
def test_search_is_deterministic_and_verify_reproduces_it(tmp_path, agents):
    discrete = agents == DISCRETE
    where = scenario_file(tmp_path, discrete)
    job = SearchJob(agents=agents, scenario=where, budget=400, top_k=3, reward_settings={"horizon": 40})
    files = run_search(job)
    again = run_search(job)
    assert {k: v for k, v in files.items() if k != "run.json"} == {k: v for k, v in again.items() if k != "run.json"}
    out = write_outputs(tmp_path, files)
    summaries = sorted(out.glob("summary-*.json"))
    assert len(summaries) == 3
    for path in summaries:
        assert verify(path) == []
    data = json.loads(summaries[0].read_text())
    assert data["scenario"]["domain"] == "gym" and len(data["steps"]) == len(data["env_actions"])
    assert {o["event"] for o in data["outcomes"]} <= {"success", "collision", "timeout"}
    data["steps"][-1]["agent_positions"][0][0] += 1e-9
    summaries[0].write_text(json.dumps(data))
    assert verify(summaries[0])[0].startswith(".steps[")


def test_bad_adapters_and_agents_are_refused_with_how_to_fix():
    with pytest.raises(ValueError, match="module:Class"):
        load_adapter("CorridorAdapter")
    with pytest.raises(ValueError, match="not a subclass"):
        load_adapter("tests.gym.corridor:Corridor")
    with pytest.raises(ValueError, match="Stable-Baselines3 .zip file or module:attribute"):
        load_agent("nobody", load_adapter(ADAPTER))


def test_a_faster_state_hook_gives_the_same_search_as_deep_copies(tmp_path):
    common = {"agents": BOX, "budget": 300, "top_k": 2, "reward_settings": {"horizon": 40}}
    deep = run_search(SearchJob(scenario=scenario_file(tmp_path), **common))
    fast = run_search(SearchJob(scenario=scenario_file(tmp_path, adapter=FAST), **common))
    strip = lambda files: {k: json.loads(v) | {"scenario": None} for k, v in files.items() if k != "run.json"}  # noqa: E731
    assert strip(deep) == strip(fast)
