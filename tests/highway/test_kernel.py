"""The highway kernel against highway-env itself, side by side and bit for bit (the 1,000-episode version:
benchmarks/bench_highway_exact.py)."""

import numpy as np
import pytest

from search.gym.agents import load_agent
from search.highway.adapter import HighwayAdapter
from search.highway.batch import EnvBatch, KernelBatch, make_batch
from search.highway.kernel_check import compare, env_state, random_driver


def _hi(observations, rng):
    return _hi.agent.act(observations)


@pytest.mark.parametrize(
    "driver, settings, env_action, seeds",
    [
        (random_driver(False), {"discrete": False, "vehicles_density": 1.5}, "extreme", range(6)),
        (random_driver(True), {"vehicles_density": 0.8}, "uniform", range(10, 14)),
        ("highway-hi", {"lanes_count": 4}, "uniform", range(20, 21)),
    ],
    ids=["random-steering-extreme-pushes", "meta-actions", "highway-hi-four-lanes"],
)
def test_kernel_steps_exactly_as_highway_env(driver, settings, env_action, seeds):
    if driver == "highway-hi":
        _hi.agent = load_agent("highway-hi", HighwayAdapter())
        driver = _hi
    result = compare(list(seeds), driver, settings, env_action)
    assert result.first_difference is None, result.first_difference
    assert result.steps >= 2 * result.episodes
    if env_action == "extreme":
        assert result.crashes > 0  # the collision path (highway-env's own polygon test) was taken


def _run(batch, seeds, steps, rng_seed=0):
    rng = np.random.default_rng(rng_seed)
    batch.reset(seeds)
    for _ in range(steps):
        batch.apply(rng.uniform(-1, 1, (len(seeds), 8, 2)))
        batch.step((rng.uniform(-1, 1, (len(seeds), 2)) * [1, 0.05]).astype(np.float32))


CONTINUOUS = {"discrete": False}  # continuous control: every action array these tests step with is one


def test_same_seeds_and_actions_give_bit_identical_states():
    one, two = make_batch(3, CONTINUOUS), make_batch(3, CONTINUOUS)
    _run(one, [1, 2, 3], 6)
    _run(two, [1, 2, 3], 6)
    assert isinstance(one, KernelBatch) and one.state.equals(two.state)


def test_stepping_some_rows_and_restoring_snapshots():
    whole, part = make_batch(3, CONTINUOUS), make_batch(3, CONTINUOUS)
    _run(whole, [4, 5, 6], 2)
    _run(part, [4, 5, 6], 2)
    saved = part.snapshot()
    actions = np.full((3, 2), 0.1, np.float32)
    whole.step(actions)
    part.step(actions[[0, 2]], rows=[0, 2])
    assert whole.state.take([0, 2]).equals(part.state.take([0, 2]))
    assert saved.take([1]).equals(part.state.take([1]))  # untouched
    part.restore(saved)
    part.step(actions)
    assert whole.state.equals(part.state)


def test_reset_without_a_seed_continues_the_generator_as_highway_env_does():
    env, batch = HighwayAdapter().make(), make_batch(1)
    env.reset(seed=7)
    batch.reset([7])
    env.reset()
    batch.reset([None])
    reference = env_state(env, discrete=True)
    assert np.array_equal(reference["x"], batch.state.x[0]) and np.array_equal(reference["lane"], batch.state.lane[0])


def test_an_uncovered_setting_runs_highway_env_with_a_notice(capsys):
    batch = make_batch(2, CONTINUOUS | {"observation": {"type": "Kinematics", "absolute": True}})
    assert isinstance(batch, EnvBatch)
    assert capsys.readouterr().err.count("not covered") == 1
    batch.reset([0, 1])
    saved = batch.snapshot()
    first = batch.step(np.zeros((2, 2), np.float32))
    batch.restore(saved)
    again = batch.step(np.zeros((2, 2), np.float32))
    assert first[0].shape == (2, 5, 5) and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))


def test_the_kernel_vector_environment_steps_as_sb3s_over_highway_env():
    from stable_baselines3.common.env_util import make_vec_env

    from search.highway.env import make_env
    from search.highway.vector import KernelVecEnv

    reference, kernel = make_vec_env(lambda: make_env(discrete=False), n_envs=3, seed=5), KernelVecEnv(3, CONTINUOUS)
    kernel.seed(5)
    assert np.array_equal(reference.reset(), kernel.reset())
    rng, ends = np.random.default_rng(0), 0
    for _ in range(12):
        actions = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        expected, got = reference.step(actions), kernel.step(actions)
        for a, b in zip(expected[:3], got[:3], strict=True):
            assert np.array_equal(a, b)
        for a, b in zip(expected[3], got[3], strict=True):
            assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
            assert np.array_equal(a.get("terminal_observation"), b.get("terminal_observation"))
            assert a.get("episode", {}).get("r") == b.get("episode", {}).get("r")
        ends += int(expected[2].sum())
    assert ends > 0  # episodes ended and were reset from highway-env's continuing generator


def test_evaluation_on_the_kernel_scores_the_episodes_highway_env_plays():
    from search.highway.evaluate import EPISODE_BASE, evaluate

    adapter = HighwayAdapter()
    agent = load_agent("highway-med", adapter)
    env, rewards, lengths, speeds, changes = adapter.make(), [], [], [], []
    for i in range(3):  # evaluate's episodes, each played in highway-env
        observation, _ = env.reset(seed=EPISODE_BASE * 3 + i)
        total, done, steps, measured, lane, changed = 0.0, False, 0, [], env.unwrapped.vehicle.lane_index[2], 0
        while not done:
            observation, reward, terminated, truncated, _ = env.step(agent.act(observation[None])[0])
            total, steps, done = total + float(reward), steps + 1, terminated or truncated
            measured.append(adapter.measure(env))  # the visible score, as the clips read it
            changed += env.unwrapped.vehicle.lane_index[2] != lane
            lane = env.unwrapped.vehicle.lane_index[2]
        rewards.append(total)
        lengths.append(steps)
        speeds.append(adapter.score.of(measured, adapter.dt))
        changes.append(changed)
    result = evaluate(agent, 3, seed=2, batch=2)
    assert result["reward_mean"] == float(np.mean(rewards)) and result["length_mean"] == float(np.mean(lengths))
    assert result["score"]["name"] == "speed" and result["score"]["mean"] == float(np.mean(speeds))
    assert result["lane_changes_mean"] == float(np.mean(changes))


def test_dqn_learns_the_same_on_the_kernel_as_on_highway_env():
    """The shipped agents' training (search/highway/train.py) on the kernel, against SB3 over highway-env."""
    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.env_util import make_vec_env

    from search.highway.env import make_env
    from search.highway.vector import KernelVecEnv

    torch.set_num_threads(1)
    kernel = KernelVecEnv(1)
    kernel.seed(3)
    parameters = []
    for envs in (make_vec_env(lambda: make_env(), n_envs=1, seed=3), kernel):
        model = DQN("MlpPolicy", envs, learning_starts=16, batch_size=8, target_update_interval=8, seed=3, device="cpu")
        model.learn(64)
        parameters.append([p.detach().clone() for p in model.policy.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*parameters, strict=True))
