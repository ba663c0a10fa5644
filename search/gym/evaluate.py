"""How good an agent is in a Gymnasium world: success, collision and timeout rates (the adapter's ``outcome`` of
each episode's end) and mean episode reward over test episodes, with 95% intervals.

Episode i of evaluation seed s starts from ``reset(seed=EPISODE_BASE * (s + 1) + i)``: far from the seeds
scenario files use and from training's, so no test episode was seen in training. The world is left as it goes
without Foil (no environment action is applied); the agent acts deterministically, on ``CHUNK`` episodes'
observations at a time (`play`), and the chunks are spread over worker processes (`foil eval --jobs`): the same
seed gives the same result, to the last bit, whatever the number of workers.
"""

from __future__ import annotations

import numpy as np

from search.core.evaluation import Episode, episodes_result, scores_result
from search.core.workers import in_order
from search.gym.adapter import Adapter, ending
from search.gym.agents import GymAgent

EPISODE_BASE = 1_000_000
# episodes played side by side, the agent acting on all their observations in one call: a fixed number, so the
# batch an episode is played in, and with it the agent's every output to the last bit, never depends on the
# number of worker processes
CHUNK = 8


def evaluate(agent: GymAgent, episodes: int, seed: int, adapter: Adapter, per_episode: bool = False) -> dict:
    """The ``foil eval --json`` object of ``episodes`` test episodes in the adapter's environment (`played`), with
    the environment's time limit; with ``per_episode``, each episode's reward too (``episode_rewards``)."""
    events, rewards, steps, scores, limit = played(agent, episodes, seed, adapter)
    result = episodes_result(
        agent.name, seed, events, rewards, steps, adapter.dt, limit * adapter.dt if limit else None
    ) | scores_result(adapter.score, scores)
    return result | ({"episode_rewards": rewards} if per_episode else {})


def test_episodes(agent: GymAgent, episodes: int, seed: int, adapter: Adapter) -> list[Episode]:
    """The test episodes `evaluate` summarises, one `Episode` each (the domain's `play`)."""
    events, rewards, steps, scores, _ = played(agent, episodes, seed, adapter)
    shown = scores if adapter.score is not None else [None] * len(events)
    return [
        Episode(reward, n * adapter.dt, event, score)
        for event, reward, n, score in zip(events, rewards, steps, shown, strict=True)
    ]


def played(
    agent: GymAgent, episodes: int, seed: int, adapter: Adapter
) -> tuple[list[str], list[float], list[int], list[float], int | None]:
    """``episodes`` test episodes, ``CHUNK`` at a time side by side (`play`), the chunks over worker processes
    (search.core.workers): each one's event, reward, steps and visible score, and the environment's step limit."""
    if episodes < 2:
        raise ValueError("evaluate at least 2 episodes (an interval needs them)")
    seeds = [EPISODE_BASE * (seed + 1) + i for i in range(episodes)]
    chunks = in_order(play, [(agent, adapter, seeds[i : i + CHUNK]) for i in range(0, episodes, CHUNK)])
    events, rewards, steps, scores = ([x for part in chunks for x in part[k]] for k in range(4))
    return events, rewards, steps, scores, chunks[0][4]


def play(
    agent: GymAgent, adapter: Adapter, seeds: list[int]
) -> tuple[list[str], list[float], list[int], list[float], int | None]:
    """Episodes from ``seeds``, one environment each, stepped side by side: the agent acts on the observations of
    every episode still running in one call. Each one's event, reward, steps and visible score, and the
    environment's step limit (None: none)."""
    envs, outcome = [adapter.make() for _ in seeds], ending(adapter)
    observations = [np.asarray(env.reset(seed=s)[0]) for env, s in zip(envs, seeds, strict=True)]
    events, rewards, steps = [""] * len(seeds), [0.0] * len(seeds), [0] * len(seeds)
    measured: list[list[float]] = [[] for _ in seeds]
    running = list(range(len(seeds)))
    while running:
        actions = agent.act(np.stack([observations[i] for i in running]))
        going = []
        for i, action in zip(running, actions, strict=True):
            observation, reward, terminated, truncated, info = envs[i].step(action)
            observations[i] = np.asarray(observation)
            rewards[i], steps[i] = rewards[i] + float(reward), steps[i] + 1
            if adapter.score is not None:
                measured[i].append(float(adapter.measure(envs[i])))
            if terminated or truncated:
                events[i] = outcome(bool(terminated), bool(truncated), info, float(reward), envs[i])
            else:
                going.append(i)
        running = going
    scores = [adapter.score.of(m, adapter.dt) for m in measured] if adapter.score is not None else []
    spec = envs[0].spec
    return events, rewards, steps, scores, getattr(spec, "max_episode_steps", None) if spec is not None else None
