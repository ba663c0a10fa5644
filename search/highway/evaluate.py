"""`foil eval` of a highway agent on the batched kernel: the test episodes of `search.gym.evaluate` (the same
seeds), ``batch`` of them stepped at once, each exactly as highway-env plays it under the agent's decisions; and
how the agent drives: its visible score (mean speed) and lane changes per drive.

The agent decides for every running episode of a batch in one call. Its network's outputs for an observation then
differ from those of a lone call in the last bits (the matrix products sum in another order), so a decision
differs from the one a lone highway-env episode gets only where two actions' values tie to those bits:
`benchmarks/bench_highway.py --eval` counts such decisions (none in 200 test episodes of each shipped agent), and
`tests/highway/test_kernel.py` plays the episodes in highway-env one observation at a time and compares with
``==``. The batch an episode is decided in is fixed by ``batch`` alone, so the same seed gives the same result."""

from __future__ import annotations

import numpy as np

from search.core.evaluation import episodes_result, scores_result
from search.gym.adapter import Adapter
from search.gym.agents import GymAgent
from search.gym.evaluate import EPISODE_BASE
from search.highway.adapter import HighwayAdapter, kmh
from search.highway.batch import make_batch
from search.highway.env import DURATION_S


def evaluate(
    agent: GymAgent,
    episodes: int,
    seed: int = 0,
    adapter: Adapter | None = None,
    batch: int = 64,
    per_episode: bool = False,
) -> dict:
    """Rates, mean reward, mean speed and their 95% intervals, and mean lane changes, over ``episodes`` test
    episodes, ``batch`` of them stepped at once on the highway kernel (search.highway.batch), the agent acting
    on all of their observations in one call; with ``per_episode``, each episode's reward too
    (``episode_rewards``)."""
    if episodes < 2:
        raise ValueError("evaluate at least 2 episodes (an interval needs them)")
    adapter = adapter or HighwayAdapter()
    seeds = [EPISODE_BASE * (seed + 1) + i for i in range(episodes)]
    envs = make_batch(min(batch, episodes), adapter.settings)
    events: list[str] = []
    rewards: list[float] = []
    lengths: list[int] = []
    speeds: list[list[float]] = [[] for _ in seeds]  # km/h after each step, as the clips' visible score reads it
    changes = np.zeros(len(seeds), np.int64)
    for start in range(0, episodes, envs.batch):
        chunk = seeds[start : start + envs.batch]
        rows = np.arange(len(chunk))
        observations = envs.reset(chunk, rows)
        totals, steps = [0.0] * len(chunk), np.zeros(len(chunk), np.int64)
        running, crashed, cut = np.ones(len(chunk), bool), np.zeros(len(chunk), bool), np.zeros(len(chunk), bool)
        lanes = envs.ego(rows)[1]
        while running.any():
            live = rows[running]
            actions = agent.act(observations[live])
            observations[live], reward, terminated, truncated = envs.step(actions, live)
            speed, lane = envs.ego(live)
            for b, v in zip(live, speed, strict=True):
                speeds[start + b].append(float(kmh(v)))
            changes[start + live] += lane != lanes[live]
            lanes[live] = lane
            for b, r in zip(live, reward, strict=True):
                totals[b] = totals[b] + float(r)
            steps[live] += 1
            ended = terminated | truncated
            crashed[live[ended]], cut[live[ended]] = terminated[ended], truncated[ended]
            running[live[ended]] = False
        events.extend(adapter.outcome(bool(c), bool(t), {}) for c, t in zip(crashed, cut, strict=True))
        rewards.extend(totals)
        lengths.extend(steps.tolist())
    duration = float(adapter.settings.get("duration", DURATION_S))
    result = episodes_result(agent.name, seed, events, rewards, lengths, adapter.dt, duration * adapter.dt)
    score = HighwayAdapter.score
    result |= scores_result(score, [score.of(values, adapter.dt) for values in speeds])
    result["lane_changes_mean"] = float(changes.mean())
    return result | ({"episode_rewards": rewards} if per_episode else {})
