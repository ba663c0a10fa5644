"""The whole world in a Gymnasium summary, and an adapter's hooks without friction: a world that lists nothing of
itself but its agents still verifies only as it ran, an outcome may read the step's reward, an environment that
cannot be copied and an agent trained behind wrappers the adapter forgot get errors that say what to do."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import gymnasium
import numpy as np
import pytest

from app.formats import summary_json
from search.gym.adapter import Adapter
from search.gym.agents import load_agent
from search.gym.evaluate import evaluate
from search.gym.problem import GymCoupledProblem, GymScenario
from search.gym.summary import build_gym_summary
from search.solvers.reward import RewardConfig
from search.solvers.summary import verify
from tests.gym.corridor import Corridor, CorridorAdapter

HERE = "tests.gym.test_world_state"
AGENTS = ("tests.gym.corridor:straight", f"{HERE}:slow")
REWARD = RewardConfig(horizon=40)


def slow(observations):
    """Walks straight at the goal at half speed: like `straight`, it never looks at the obstacle."""
    return np.tile([0.5, 0.0], (len(observations), 1))


class UnlistedCorridorAdapter(CorridorAdapter):
    """The corridor whose adapter lists nothing of the world but the walker: no ``others``."""

    others = Adapter.others


def world_summary(adapter: str, scale: float = 1.0) -> dict:
    """A complete trajectory in which the environment action pushes the obstacle away from the walkers' line,
    ``scale`` times as fast: the walkers' own paths never change with it."""
    scenario = GymScenario("corridor", adapter, 3)
    loaded = scenario.load_adapter()
    agents = [load_agent(spec, loaded) for spec in AGENTS]
    problem = GymCoupledProblem(agents, scenario, REWARD)
    away = np.sign(problem._initial[0].observation[3]) or 1.0
    problem.reset(1)
    steps = 0
    while not problem.step(np.array([[away * scale]]))[1][0]:
        steps += 1
    actions = np.full((steps + 1, 1), away * scale)
    return build_gym_summary(agents, scenario, REWARD, actions, {"name": "test"})


def test_a_world_without_others_records_its_state_and_verify_sees_it_move(tmp_path):
    summary = world_summary(f"{HERE}:UnlistedCorridorAdapter")
    path = tmp_path / "summary.json"
    path.write_text(summary_json(summary))
    assert verify(path) == []
    assert all(len(step["world_digests"]) == 2 for step in summary["steps"])

    slower = world_summary(f"{HERE}:UnlistedCorridorAdapter", scale=0.5)
    for key in ("agent_positions", "agent_actions", "other_positions"):
        assert [s[key] for s in slower["steps"]] == [s[key] for s in summary["steps"]]  # the agents never saw it
    assert slower["outcomes"] == summary["outcomes"] and slower["reward"] == summary["reward"]

    tampered = json.loads(path.read_text())
    tampered["env_actions"] = slower["env_actions"]
    path.write_text(json.dumps(tampered))
    problems = verify(path)
    assert problems and problems[0].startswith(".steps[0].world_digests[0]: file has")


def test_a_world_with_others_records_them_and_no_digest():
    summary = world_summary("tests.gym.corridor:CorridorAdapter")
    assert all("world_digests" not in step and step["other_positions"][0] for step in summary["steps"])


def digests() -> None:
    """Prints a summary's digests: run in processes of their own, whose string hashes differ."""
    summary = world_summary(f"{HERE}:UnlistedCorridorAdapter")
    print(json.dumps([step["world_digests"] for step in summary["steps"]]))


def test_the_digest_is_the_same_in_every_process():
    runs = [
        subprocess.run(
            [sys.executable, "-c", f"from {HERE} import digests; digests()"],
            capture_output=True,
            text=True,
            check=True,
            env=os.environ | {"PYTHONHASHSEED": seed},
        ).stdout
        for seed in ("1", "2")
    ]
    here = [step["world_digests"] for step in world_summary(f"{HERE}:UnlistedCorridorAdapter")["steps"]]
    assert json.loads(runs[0]) == json.loads(runs[1]) == here


class LockedCorridor(Corridor):
    """A corridor holding a lock, as an environment talking to a simulator process does: it cannot be copied."""

    def __init__(self, discrete: bool = False):
        super().__init__(discrete)
        self.lock = threading.Lock()


class LockedCorridorAdapter(CorridorAdapter):
    def make(self, render=False):
        return LockedCorridor()


def test_an_environment_that_cannot_be_copied_names_the_hooks_that_copy_it():
    scenario = GymScenario("corridor", f"{HERE}:LockedCorridorAdapter", 3)
    agents = [load_agent(spec, scenario.load_adapter()) for spec in AGENTS]
    with pytest.raises(ValueError, match=r"cannot deep-copy.*_thread.lock.*snapshot_env\(env\) and restore_env") as e:
        GymCoupledProblem(agents, scenario, REWARD)
    assert "docs/gym.md, 'Environments that cannot be copied'" in str(e.value)
    assert e.value.__cause__ is None and e.value.__suppress_context__


class Silent(gymnasium.Wrapper):
    """The corridor with an empty ``info``: success and a crash differ only by the step's reward."""

    def step(self, action):
        observation, reward, terminated, truncated, _ = self.env.step(action)
        return observation, reward, terminated, truncated, {}


class SilentCorridorAdapter(CorridorAdapter):
    def make(self, render=False):
        return Silent(Corridor())

    def outcome(self, terminated, truncated, info, reward, env):
        assert isinstance(env.unwrapped, Corridor)
        if terminated:
            return "success" if reward > 0 else "collision"
        return "timeout"


class OlderCorridorAdapter(SilentCorridorAdapter):
    """An adapter written before ``outcome`` had the reward: its override is called as it was."""

    def outcome(self, terminated, truncated, info):
        return "collision" if terminated else "timeout"


def test_an_outcome_may_read_the_steps_reward_where_info_is_empty():
    assert world_summary(f"{HERE}:SilentCorridorAdapter")["outcomes"][0]["event"] == "success"
    silent, plain = SilentCorridorAdapter(), CorridorAdapter()
    read = evaluate(load_agent(AGENTS[0], silent), 12, 0, silent)
    assert read == evaluate(load_agent(AGENTS[0], plain), 12, 0, plain)  # the reward says what info said
    assert read["success_rate"] > 0 and read["collision_rate"] > 0


def test_an_outcome_of_the_older_signature_is_still_called():
    assert world_summary(f"{HERE}:OlderCorridorAdapter")["outcomes"][0]["event"] == "collision"


def test_an_outcome_of_another_signature_is_refused_with_the_one_to_use():
    class Confused(CorridorAdapter):
        def outcome(self, terminated, info):
            return "timeout"

    with pytest.raises(ValueError, match=r"outcome\(self, terminated, truncated, info, reward, env\)"):
        GymCoupledProblem(
            [load_agent(s, Confused()) for s in AGENTS], GymScenario("c", f"{HERE}:x", 3), adapter=Confused()
        )


def test_an_agent_trained_behind_wrappers_the_adapter_lacks_names_them(tmp_path):
    from stable_baselines3 import PPO

    trained_in = gymnasium.wrappers.FrameStackObservation(Corridor(), 2)  # the wrapper make() forgets
    PPO("MlpPolicy", trained_in, n_steps=8, batch_size=8, seed=0, device="cpu").save(tmp_path / "stacked.zip")
    adapter = CorridorAdapter()
    agents = [load_agent(str(tmp_path / "stacked.zip"), adapter), load_agent(AGENTS[0], adapter)]
    problem = GymCoupledProblem(agents, GymScenario("corridor", "tests.gym.corridor:CorridorAdapter", 3), REWARD)
    problem.reset(1)
    with pytest.raises(ValueError, match=r"shape \(2, 4\), but the environment gives \(4,\).*make\(\) likely lacks"):
        problem.step(np.zeros((1, 1)))
    with pytest.raises(ValueError, match="observation wrappers the agent was trained with"):
        agents[0].value(problem.observations(0))
