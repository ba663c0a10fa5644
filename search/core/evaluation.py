"""How good an agent is, from its test episodes: the ``foil eval --json`` object (docs/formats.md, "An agent's
evaluation"), computed here from each episode's ending, reward, length and visible score, so that a world only
plays its episodes and every world's evaluation has the same keys, intervals and text."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.visible import Score

EVENTS = ("success", "collision", "timeout")  # the endings an evaluation counts (search.core.outcomes' names)


@dataclass(frozen=True)
class Episode:
    """One test episode as a world played it: its total reward, its length in seconds, how it ended (one of
    ``EVENTS``; None in a world whose episodes have no outcome, such as one scored by reward alone) and the
    visible score a clip of the whole episode shows (`app.visible.Score.of`; None where the world declares
    none)."""

    reward: float
    seconds: float
    event: str | None = None
    score: float | None = None


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson 95% interval of a rate."""
    p = successes / n
    centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)


def episodes_result(
    agent: str,
    seed: int,
    events: Sequence[str | None],
    rewards: Sequence[float],
    steps: Sequence[int | float],
    dt: float,
    limit: float | None,
) -> dict[str, Any]:
    """The ``foil eval --json`` object of test episodes (each one's event, reward and steps of ``dt`` seconds):
    rates with Wilson intervals where the episodes have outcomes, mean reward with its 95% interval, mean time to
    success, mean episode length (seconds) and the time limit the world allows (null when none)."""
    episodes = len(events)
    if episodes < 2:
        raise ValueError("evaluate at least 2 episodes (an interval needs them)")
    outcomes = [event for event in events if event is not None]
    if outcomes and len(outcomes) != episodes:
        raise ValueError("give every episode an outcome, or none (a world scored by reward alone)")
    unknown = sorted(set(outcomes) - set(EVENTS))
    if unknown:
        raise ValueError(f"episode outcome {unknown[0]!r}: use one of {EVENTS}")
    values = np.asarray(rewards, dtype=np.float64)
    half = 1.96 * values.std(ddof=1) / math.sqrt(episodes)
    rates: dict[str, Any] = {}
    if outcomes:
        rates = {f"{event}_rate": outcomes.count(event) / episodes for event in EVENTS}
        rates |= {f"{event}_ci95": list(wilson(outcomes.count(event), episodes)) for event in EVENTS}
    success_s = [n * dt for n, event in zip(steps, events, strict=True) if event == "success"]
    return {
        "agent": agent,
        "episodes": episodes,
        "seed": seed,
        **rates,
        "reward_mean": float(values.mean()),
        "reward_ci95": [float(values.mean() - half), float(values.mean() + half)],
        "nav_time_mean": float(np.mean(success_s)) if success_s else None,
        "length_mean": float(np.mean(steps) * dt),
        "time_limit": limit,
    }


def scores_result(score: Score | None, scores: Sequence[float]) -> dict[str, Any]:
    """The visible score of test episodes (each one summed as a clip of the whole episode would show it): its
    mean with a 95% interval, under ``score``; nothing where the world declares no visible score."""
    if score is None:
        return {}
    values = np.asarray(scores, dtype=np.float64)
    half = 1.96 * values.std(ddof=1) / math.sqrt(len(values))
    mean = float(values.mean())
    return {"score": score.to_manifest() | {"mean": mean, "ci95": [mean - half, mean + half]}}


def evaluation(
    agent: str, seed: int, played: Sequence[Episode], score: Score | None, per_episode: bool = False
) -> dict[str, Any]:
    """The ``foil eval --json`` object of a world's played episodes: `episodes_result` and, where the world
    declares a visible score, `scores_result`; with ``per_episode``, each episode's reward (``episode_rewards``,
    which the bundle compares two agents by, episode by episode)."""
    rewards = [episode.reward for episode in played]
    events = [episode.event for episode in played]
    result = episodes_result(agent, seed, events, rewards, [e.seconds for e in played], 1.0, None)
    if score is not None:
        missing = [i for i, episode in enumerate(played) if episode.score is None]
        if missing:
            raise ValueError(
                f"the world declares the visible score {score.name!r}, but episode {missing[0]} has none: give each "
                "Episode its score (Score.of over the episode's measurements)"
            )
        result |= scores_result(score, [float(episode.score) for episode in played if episode.score is not None])
    return result | ({"episode_rewards": rewards} if per_episode else {})


def describe(result: dict[str, Any]) -> str:
    """``foil eval``'s line for a person: the outcome rates where the episodes have outcomes, the mean reward and
    length, and the visible score where the world declares one, each with its 95% interval."""
    rates = ", ".join(
        f"{event} rate {result[f'{event}_rate']:.3f} ({result[f'{event}_ci95'][0]:.3f} to "
        f"{result[f'{event}_ci95'][1]:.3f})"
        for event in EVENTS
        if f"{event}_rate" in result
    )
    low, high = result["reward_ci95"]
    text = (
        f"{result['agent']}: {result['episodes']} episodes (seed {result['seed']}), {rates + ', ' if rates else ''}"
        f"mean reward {result['reward_mean']:.2f} ({low:.2f} to {high:.2f}), mean length {result['length_mean']:.1f} s"
    )
    if "score" in result:
        shown = result["score"]
        score = Score.from_manifest({k: v for k, v in shown.items() if k not in ("mean", "ci95")})
        digits = 1 if score.summed == "band" else score.digits  # a band's sum is seconds, at one decimal
        mean, low_score, high_score = (f"{v:.{digits}f}" for v in (shown["mean"], *shown["ci95"]))
        if score.summed == "band":
            text += f", visible score: {mean} s of {score.name} within its band ({low_score} to {high_score} s)"
        else:
            unit = f" {score.unit}" if score.unit else ""
            how = "at the end" if score.summed == "final" else "mean over the episode"
            text += f", visible score: {score.name} {how} {mean}{unit} ({low_score} to {high_score}{unit})"
    return text
