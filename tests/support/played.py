"""A world's rollouts for the representative solver checked three ways: its fast path against the interface's
default (each rollout's summary), and each pair read from every agent's rollouts against the pair played alone."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from search.core.contrast import Played
from search.core.domain import Domain


def checked_rollouts(domain: Domain, agents: list[str], states: list[Any], horizon: int, pushes: int) -> Played:
    """Every agent's rollouts by the world's fast path, once it is checked that the default path plays the same
    pushes, ends and clips and that each pair reads as it does played alone (same pushes, contrasts and steps)."""
    reward = {"horizon": horizon, "finish": "last"}

    def play(how: Any, which: list[str]) -> Played:
        played: Played = how(domain, which, states, reward, pushes, np.random.default_rng(1))
        return played

    fast, exact = play(type(domain).play_states, agents), play(Domain.play_states, agents)
    assert np.array_equal(fast.ends, exact.ends) and np.array_equal(fast.state, exact.state)
    assert all(np.array_equal(a, b) for a, b in zip(fast.env, exact.env, strict=True))
    for first, second in itertools.combinations(range(len(agents)), 2):
        (ours, steps), (theirs, exact_steps) = fast.pair(first, second), exact.pair(first, second)
        assert np.array_equal(ours.contrast, theirs.contrast) and steps == exact_steps
        alone, alone_steps = play(type(domain).play_states, [agents[first], agents[second]]).pair(0, 1)
        assert np.array_equal(ours.contrast, alone.contrast) and steps == alone_steps
        assert all(np.array_equal(a, b) for a, b in zip(ours.actions, alone.actions, strict=True))
    return fast
