"""Choosing the shipped snapshots from a run's validation curve."""

from __future__ import annotations

import pytest

from search.release_agents import choose


def curve(rewards: list[float]) -> list[dict]:
    return [{"checkpoint": f"{i:06d}.pt", "env_steps": i * 1000, "reward_mean": r} for i, r in enumerate(rewards)]


def test_snapshots_closest_to_the_targets_in_training_order():
    rows = curve([-5, 9.5, 12, 17, 10.2, 15, 23, 25, 21])
    chosen = {name: row["reward_mean"] for name, row in choose(rows).items()}
    assert chosen == {"lo": 9.5, "med": 17, "hi": 21}
    # a snapshot near 10 after med does not count as lo: lo must be earlier than med
    assert choose(curve([3, 16, 10, 22]))["lo"]["reward_mean"] == 3


def test_too_short_a_curve_is_refused():
    with pytest.raises(SystemExit, match="not enough validated checkpoints"):
        choose(curve([20, 21]))
