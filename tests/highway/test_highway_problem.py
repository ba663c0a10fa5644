"""Highway driving as a domain: snapshots, determinism, verify, the environment action and agent files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.gym.agents import load_agent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.highway.adapter import LANE_THRESHOLD, PERTURBED, SPEED_RANGE, HighwayAdapter
from search.highway.scenarios import SCENARIOS, load_highway_scenario
from search.solvers.baselines import SamplingConfig
from search.solvers.reward import RewardConfig
from search.solvers.runner import SearchJob, run_search, write_outputs
from search.solvers.summary import verify

DRIVERS = ("tests.highway.drivers:idle", "tests.highway.drivers:slower")
CONTINUOUS = ("tests.highway.drivers:cruise", "tests.highway.drivers:cautious")


def problem(scenario: GymScenario, agents=DRIVERS) -> GymCoupledProblem:
    adapter = scenario.load_adapter()
    return GymCoupledProblem([load_agent(a, adapter) for a in agents], scenario, RewardConfig())


def world(p: GymCoupledProblem) -> list:
    """Every vehicle's position, speed and heading in every instance."""
    return [[[(*v.position, v.speed, v.heading) for v in i.env.unwrapped.road.vehicles] for i in row] for row in p.rows]


def test_restore_continues_exactly_as_the_original_did():
    p = problem(SCENARIOS["highway-dense"])
    p.reset(2)
    rng = np.random.default_rng(1)
    p.step(rng.uniform(-1, 1, (2, PERTURBED, 2)))
    saved = p.snapshot()
    later = rng.uniform(-1, 1, (3, 2, PERTURBED, 2))
    first = [p.step(a)[0] for a in later], world(p)
    p.restore(saved)
    second = [p.step(a)[0] for a in later], world(p)
    assert np.array_equal(first[0], second[0]) and first[1] == second[1]


def test_scenarios_are_distinct_initial_traffic_from_their_seeds():
    starts = {}
    for name, scenario in SCENARIOS.items():
        assert name.startswith("highway-")
        p = problem(scenario)
        p.reset(1)
        starts[name] = world(p)[0][0]
        assert world(p)[0][0] == world(p)[0][1]  # both agents start in the same traffic
        again = problem(scenario)
        again.reset(1)
        assert world(again) == world(p)
    assert len({str(s) for s in starts.values()}) == len(SCENARIOS)
    with pytest.raises(ValueError, match="highway-dense"):
        load_highway_scenario("highway-nowhere")


def test_environment_action_moves_other_drivers_within_bounds_and_never_the_ego():
    adapter = HighwayAdapter()
    env = adapter.make()
    env.reset(seed=5)
    road, ego = env.unwrapped.road, env.unwrapped.vehicle
    ego_state = (tuple(ego.position), ego.speed, ego.heading, dict(ego.action))
    others = [v for v in road.vehicles if v is not ego][:PERTURBED]
    own = [v.target_speed for v in others]
    action = np.zeros((PERTURBED, 2))
    action[:, 0] = 1.0
    action[0, 1] = LANE_THRESHOLD + 0.1
    action[1, 1] = LANE_THRESHOLD - 0.1  # inside the dead zone: MOBIL decides
    adapter.apply(env, action)
    adapter.apply(env, action)  # not cumulative: relative to each vehicle's own wish
    assert [v.target_speed for v in others] == pytest.approx([s + SPEED_RANGE for s in own])
    lanes = len(road.network.graph[others[0].lane_index[0]][others[0].lane_index[1]])
    wanted = others[0].lane_index[2] + 1
    assert others[0].target_lane_index[2] == (wanted if wanted < lanes else others[0].lane_index[2])
    assert others[1].target_lane_index == others[1].lane_index
    assert (tuple(ego.position), ego.speed, ego.heading, dict(ego.action)) == ego_state


@pytest.mark.parametrize(
    "agents,discrete", [(CONTINUOUS, False), (("tests.highway.drivers:idle", "tests.highway.drivers:faster"), True)]
)
def test_search_is_deterministic_and_verify_reproduces_it(tmp_path, agents, discrete):
    job = SearchJob(
        agents=agents,
        scenario="highway-light",
        solver="random",
        budget=40,
        top_k=2,
        solver_config=SamplingConfig(batch=2),
        world_settings={"discrete": discrete},
    )
    files = run_search(job)
    again = run_search(job)
    assert {k: v for k, v in files.items() if k != "run.json"} == {k: v for k, v in again.items() if k != "run.json"}
    for path in sorted(write_outputs(tmp_path, files).glob("summary-*.json")):
        assert verify(path) == []
        summary = json.loads(path.read_text())
        for k, outcome in enumerate(summary["outcomes"]):  # the path driven, from the positions it went through
            xs = [step["agent_positions"][k][0] for step in summary["steps"]]
            assert outcome["path_length"] >= xs[-1] - xs[0] > 0


@pytest.mark.parametrize("algorithm,discrete", [("SAC", False), ("PPO", False), ("DQN", True)])
def test_any_stable_baselines3_model_file_loads_as_an_agent(tmp_path, algorithm, discrete):
    import stable_baselines3

    adapter = HighwayAdapter({"discrete": discrete})
    env = adapter.make()
    options = {} if algorithm == "PPO" else {"buffer_size": 100}
    model = getattr(stable_baselines3, algorithm)("MlpPolicy", env, seed=0, device="cpu", **options)
    model.save(tmp_path / "model.zip")
    agent = load_agent(str(tmp_path / "model.zip"), adapter)
    observation, _ = env.reset(seed=0)
    action = agent.act(observation[None])
    assert action.shape == ((1,) if discrete else (1, 2))
    assert env.action_space.contains(action[0].astype(env.action_space.dtype))
    with pytest.raises(ValueError, match="not a Stable-Baselines3 model file"):
        (tmp_path / "bad.zip").write_bytes(b"not a zip")
        load_agent(str(tmp_path / "bad.zip"), adapter)
