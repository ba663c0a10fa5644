"""How good a highway agent is: collision rate and mean episode reward over test episodes, with 95% intervals.

Episode i of evaluation seed s starts from the traffic ``reset(seed=EPISODE_BASE * (s + 1) + i)``: far from the
shipped scenarios' seeds and from training's, so no test episode was seen in training. The agent acts
deterministically.
"""

from __future__ import annotations

import json
import math

import numpy as np

from search.gym.agents import GymAgent, load_agent
from search.highway.adapter import HighwayAdapter
from search.highway.batch import make_batch

EPISODE_BASE = 1_000_000


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson 95% interval of a rate."""
    p = successes / n
    centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)


def evaluate(
    agent: GymAgent, episodes: int, seed: int = 0, adapter: HighwayAdapter | None = None, batch: int = 64
) -> dict:
    """Rates, mean reward and their 95% intervals over ``episodes`` test episodes, ``batch`` of them stepped at
    once on the highway kernel (search.highway.batch). The agent still acts on one observation at a time: its
    network's results depend on the batch around an observation in the last bits, and one at a time they are
    the ones a lone highway-env episode gets."""
    if episodes < 2:
        raise ValueError("evaluate at least 2 episodes (an interval needs them)")
    seeds = [EPISODE_BASE * (seed + 1) + i for i in range(episodes)]
    envs = make_batch(min(batch, episodes), (adapter or HighwayAdapter()).settings)
    rewards, collisions, lengths = [], 0, []
    for start in range(0, episodes, envs.batch):
        chunk = seeds[start : start + envs.batch]
        rows = np.arange(len(chunk))
        observations = envs.reset(chunk, rows)
        totals, steps = [0.0] * len(chunk), np.zeros(len(chunk), np.int64)
        running, crashed = np.ones(len(chunk), bool), np.zeros(len(chunk), bool)
        while running.any():
            live = rows[running]
            actions = np.stack([agent.act(observations[b][None])[0] for b in live])
            observations[live], reward, terminated, truncated = envs.step(actions, live)
            for b, r in zip(live, reward, strict=True):
                totals[b] = totals[b] + float(r)
            steps[live] += 1
            ended = terminated | truncated
            crashed[live[ended]] = terminated[ended]
            running[live[ended]] = False
        collisions += int(crashed.sum())
        rewards.extend(totals)
        lengths.extend(steps.tolist())
    rewards = np.asarray(rewards)
    half = 1.96 * rewards.std(ddof=1) / math.sqrt(episodes)
    return {
        "agent": agent.name,
        "domain": "highway",
        "episodes": episodes,
        "seed": seed,
        "collision_rate": collisions / episodes,
        "collision_ci95": list(wilson(collisions, episodes)),
        "timeout_rate": 0.0,  # an episode ends in a crash or lasts the whole drive
        "success_rate": 1 - collisions / episodes,
        "reward_mean": float(rewards.mean()),
        "reward_ci95": [float(rewards.mean() - half), float(rewards.mean() + half)],
        "length_mean": float(np.mean(lengths)),
    }


def run_eval(spec: str, episodes: int, seed: int, as_json: bool) -> int:
    """`foil eval` for a highway agent."""
    adapter = HighwayAdapter()
    result = evaluate(load_agent(spec, adapter), episodes, seed, adapter)
    if as_json:
        print(json.dumps(result))
    else:
        low, high = result["collision_ci95"]
        r_low, r_high = result["reward_ci95"]
        print(
            f"{spec}: {episodes} episodes (seed {seed}), collision rate {result['collision_rate']:.3f} "
            f"({low:.3f} to {high:.3f}), mean reward {result['reward_mean']:.2f} ({r_low:.2f} to {r_high:.2f}), "
            f"mean length {result['length_mean']:.1f} s"
        )
    return 0
