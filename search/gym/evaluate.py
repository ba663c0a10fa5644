"""How good an agent is in a Gymnasium world: success, collision and timeout rates (the adapter's ``outcome`` of
each episode's end) and mean episode reward over test episodes, with 95% intervals.

Episode i of evaluation seed s starts from ``reset(seed=EPISODE_BASE * (s + 1) + i)``: far from the seeds
scenario files use and from training's, so no test episode was seen in training. The world is left as it goes
without Foil (no environment action is applied); the agent acts deterministically, on ``CHUNK`` episodes'
observations at a time (`play`), and the chunks are spread over worker processes (`foil eval --jobs`): the same
seed gives the same result, to the last bit, whatever the number of workers.
"""

from __future__ import annotations

import math

import numpy as np

from app.visible import Score
from search.core.workers import in_order
from search.gym.adapter import EVENTS, Adapter, ending
from search.gym.agents import GymAgent

EPISODE_BASE = 1_000_000
# episodes played side by side, the agent acting on all their observations in one call: a fixed number, so the
# batch an episode is played in, and with it the agent's every output to the last bit, never depends on the
# number of worker processes
CHUNK = 8


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson 95% interval of a rate."""
    p = successes / n
    centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)


def evaluate(agent: GymAgent, episodes: int, seed: int, adapter: Adapter, per_episode: bool = False) -> dict:
    """The ``foil eval --json`` object of ``episodes`` test episodes in the adapter's environment, ``CHUNK`` at a
    time side by side (`play`), the chunks over worker processes (search.core.workers); with ``per_episode``,
    each episode's reward too (``episode_rewards``)."""
    if episodes < 2:
        raise ValueError("evaluate at least 2 episodes (an interval needs them)")
    seeds = [EPISODE_BASE * (seed + 1) + i for i in range(episodes)]
    played = in_order(play, [(agent, adapter, seeds[i : i + CHUNK]) for i in range(0, episodes, CHUNK)])
    events, rewards, steps, scores = ([x for part in played for x in part[k]] for k in range(4))
    limit = played[0][4]
    result = episodes_result(
        agent.name, seed, events, rewards, steps, adapter.dt, limit * adapter.dt if limit else None
    ) | scores_result(adapter.score, scores)
    return result | ({"episode_rewards": rewards} if per_episode else {})


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


def episodes_result(
    agent: str, seed: int, events: list[str], rewards: list[float], steps: list[int], dt: float, limit: float | None
) -> dict:
    """The ``foil eval --json`` object of test episodes (each one's event, reward and steps): rates with Wilson
    intervals, mean reward with its 95% interval, mean time to success, mean episode length (seconds) and the
    time limit the environment allows (null when none)."""
    episodes = len(events)
    unknown = sorted(set(events) - set(EVENTS))
    if unknown:
        raise ValueError(f"adapter outcome {unknown[0]!r}: use one of {EVENTS}")
    values = np.asarray(rewards)
    half = 1.96 * values.std(ddof=1) / math.sqrt(episodes)
    success_s = [n * dt for n, event in zip(steps, events, strict=True) if event == "success"]
    return {
        "agent": agent,
        "episodes": episodes,
        "seed": seed,
        **{f"{event}_rate": events.count(event) / episodes for event in EVENTS},
        **{f"{event}_ci95": list(wilson(events.count(event), episodes)) for event in EVENTS},
        "reward_mean": float(values.mean()),
        "reward_ci95": [float(values.mean() - half), float(values.mean() + half)],
        "nav_time_mean": float(np.mean(success_s)) if success_s else None,
        "length_mean": float(np.mean(steps) * dt),
        "time_limit": limit,
    }


def scores_result(score: Score | None, scores: list[float]) -> dict:
    """The visible score of test episodes (each one summed as a clip of the whole episode would show it): its
    mean with a 95% interval, under ``score``; nothing where the world declares no visible score."""
    if score is None:
        return {}
    values = np.asarray(scores, dtype=np.float64)
    half = 1.96 * values.std(ddof=1) / math.sqrt(len(values))
    mean = float(values.mean())
    return {"score": score.to_manifest() | {"mean": mean, "ci95": [mean - half, mean + half]}}


def format_result(result: dict) -> str:
    rates = ", ".join(
        f"{event} rate {result[f'{event}_rate']:.3f} ({result[f'{event}_ci95'][0]:.3f} to "
        f"{result[f'{event}_ci95'][1]:.3f})"
        for event in EVENTS
    )
    low, high = result["reward_ci95"]
    text = (
        f"{result['agent']}: {result['episodes']} episodes (seed {result['seed']}), {rates}, mean reward "
        f"{result['reward_mean']:.2f} ({low:.2f} to {high:.2f}), mean length {result['length_mean']:.1f} s"
    )
    if "score" in result:
        shown = result["score"]
        score = Score.from_manifest({k: v for k, v in shown.items() if k not in ("mean", "ci95")})
        digits = 1 if score.summed == "band" else score.digits  # a band's sum is seconds, at one decimal
        mean, low, high = (f"{v:.{digits}f}" for v in (shown["mean"], *shown["ci95"]))
        if score.summed == "band":
            text += f", visible score: {mean} s of {score.name} within its band ({low} to {high} s)"
        else:
            unit = f" {score.unit}" if score.unit else ""
            how = "at the end" if score.summed == "final" else "mean over the episode"
            text += f", visible score: {score.name} {how} {mean}{unit} ({low} to {high}{unit})"
    return text
