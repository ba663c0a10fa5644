"""A coupled problem's rows over worker processes (search.gym.rows): a Gymnasium world's problem steps, saves,
restores and reassigns its rows the same in one process and in two or four, so an MCTS search gives byte-identical
summaries whatever the number of workers; a world whose steps are quick keeps its rows in one process, an adapter
that does not pickle too (and says so); a worker's error reaches the search. The tests' worlds step in
microseconds, so most tests move their rows at once (``spread_at_once``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.cli import main
from search.core.outcomes import RUNNING
from search.gym import rows
from search.gym.agents import load_agent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.solvers.reward import RewardConfig
from tests.gym.test_gym_clips import TrackAdapter

TRACK, DRIFT = "tests.gym.test_gym_clips:TrackAdapter", "tests.gym.test_visible_score:DriftAdapter"
FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"
STEADY, IDLE = "tests.gym.test_visible_score:steady", "tests.gym.test_visible_score:idle"


@pytest.fixture
def spread_at_once(monkeypatch):
    """Rows move to the workers after their first step, however quick the world."""
    monkeypatch.setattr(rows, "SPREAD_AFTER_S", 0.0)
    monkeypatch.setattr(rows, "SPREAD_STEP_S", 0.0)


def problem(adapter: str, agents: tuple[str, str], workers: int, adapter_class=None) -> GymCoupledProblem:
    scenario = GymScenario("s", adapter, 3)
    made = adapter_class() if adapter_class else scenario.load_adapter()
    loaded = [load_agent(agent, made) for agent in agents]
    return GymCoupledProblem(loaded, scenario, RewardConfig(horizon=40), made, workers=workers)


def walk(p: GymCoupledProblem) -> list:
    """Steps, saves, reassigns and restores rows as MCTS does; everything the problem tells on the way."""
    rng = np.random.default_rng(5)
    told = []

    def tell(reward, terminal):
        told.append((reward.tolist(), terminal.tolist(), p.agent_rewards.tolist(), p.t.tolist()))
        told.append(
            [
                [(i.observation.tolist(), i.outcome, i.event_step, i.path_length, [*i.measured]) for i in row]
                for row in p.rows
            ]
        )

    p.reset(5)
    for _ in range(6):
        tell(*p.step(rng.uniform(-1, 1, (p.batch, 1))))
    saved = p.snapshot([4, 1, 1])
    p.assign([0, 2], p.snapshot([3, 3]))
    tell(*p.step(rng.uniform(-1, 1, (p.batch, 1))))
    p.restore(p.concat([p.snapshot([2]), saved]))
    for _ in range(16):  # past the end of every episode: finished instances stand still and are read
        tell(*p.step(rng.uniform(-1, 1, (p.batch, 1))))
    again = p.snapshot()
    told.append([[(i.outcome, i.event_step, i.path_length) for i in row] for row in again.rows])
    told.append(again.steps.tolist())
    return told


# a world that crashes, one scored by reward with a visible score, one copied by its own state get/set
@pytest.mark.parametrize(
    ("adapter", "agents"),
    [
        (TRACK, (FAST, SLOW)),
        (DRIFT, (STEADY, IDLE)),
        ("tests.gym.corridor:FastCorridorAdapter", ("tests.gym.corridor:straight", "tests.gym.corridor:dodging")),
    ],
)
def test_rows_in_workers_step_save_and_restore_as_in_one_process(spread_at_once, adapter, agents):
    alone = walk(problem(adapter, agents, 1))
    for count in (2, 4):
        spread = problem(adapter, agents, count)
        assert walk(spread) == alone
        assert spread.spread is not None and all(i.env is None for row in spread.rows for i in row)
    assert any(outcome != RUNNING for row in alone[-2] for outcome, _, _ in row)  # ended ones stood still, read


def test_an_mcts_search_is_byte_identical_with_its_rows_in_one_two_and_four_processes(
    spread_at_once, tmp_path, monkeypatch
):
    (tmp_path / "track.toml").write_text(f'adapter = "{TRACK}"\nseed = 3\n')
    monkeypatch.chdir(tmp_path)
    found = []
    for count in (1, 2, 4):
        out = tmp_path / f"out{count}"
        args = ["search", "--agents", f"{FAST},{SLOW}", "--scenario", "track.toml", "--solver", "mcts"]
        args += ["--budget", "600", "--top-k", "3", "--quiet", "--set", "batch=8", "--out", str(out)]
        assert main([*args, "--jobs", str(count)]) == 0
        run = json.loads((out / "run.json").read_text())
        found.append(([p.read_bytes() for p in sorted(out.glob("summary-*.json"))], run["sim_steps"], run["curve"]))
    assert len(found[0][0]) == 3
    assert found[0] == found[1] == found[2]


@pytest.mark.parametrize(("kept", "waived"), [("SPREAD_AFTER_S", "SPREAD_STEP_S"), ("SPREAD_STEP_S", "SPREAD_AFTER_S")])
def test_a_quick_worlds_rows_stay_here(monkeypatch, kept, waived):
    """Either rule alone keeps them: the walk's steps took well under two seconds, and microseconds each."""
    monkeypatch.setattr(rows, waived, 0.0)
    p = problem(TRACK, (FAST, SLOW), 2)
    assert walk(p) == walk(problem(TRACK, (FAST, SLOW), 1))
    assert p.spread is None and p.stepped_here[1] > 0


def test_an_adapter_that_does_not_pickle_keeps_its_rows_here_and_says_so(spread_at_once, capsys):
    unpicklable = type("Unpicklable", (TrackAdapter,), {})  # no module attribute: pickle cannot find its class
    p = problem(TRACK, (FAST, SLOW), 2, unpicklable)
    p.reset(3)
    for _ in range(2):  # the rows would move after the first step
        p.step(np.zeros((3, 1)))
    assert p.spread is None and p.workers == 1
    assert "Unpicklable's rows step in one process" in capsys.readouterr().err


class Failing(TrackAdapter):
    def apply(self, env, action):
        if env.unwrapped.x > 1.0:
            raise ValueError("the wind broke the track")
        super().apply(env, action)


def test_a_workers_error_reaches_the_search(spread_at_once):
    p = problem("tests.gym.test_spread_rows:Failing", (FAST, SLOW), 2)
    p.reset(4)
    with pytest.raises(ValueError, match="the wind broke the track"):
        for _ in range(20):
            p.step(np.zeros((4, 1)))
