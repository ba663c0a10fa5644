"""Choosing the shipped snapshots from a run's validation curve at the clips' horizon."""

from __future__ import annotations

import pytest

from search.core.release import ReleaseError
from search.crowd.agents.release import choose, separated


def row(i: int, success: float, reward: float, timeout: float = 0.0, half_width: float = 0.8) -> dict:
    return {
        "checkpoint": f"{i:06d}.pt",
        "env_steps": i * 1000,
        "episodes": 500,
        "reward_mean": reward,
        "reward_low": reward - half_width,
        "reward_high": reward + half_width,
        "success_rate": success,
        "collision_rate": 1 - success - timeout,
        "timeout_rate": timeout,
    }


CURVE = [
    row(0, 0.0, -5),
    row(1, 0.30, 8.0, 0.30),
    row(2, 0.45, 11.0),
    row(3, 0.55, 13.0),
    row(4, 0.70, 17.5),
    row(5, 0.85, 19.0),
    row(6, 0.93, 21.0, 0.01),
    row(7, 0.96, 22.0, 0.02),
    row(8, 0.97, 21.5, 0.05),
    row(9, 0.955, 21.8, 0.01),
]


def test_hi_is_the_best_snapshot_that_meets_the_bar_and_the_others_are_clearly_worse_and_earlier():
    chosen = choose(CURVE)
    # row 8 succeeds more but times out in 5% of episodes; row 7 has the best reward among those that qualify
    assert chosen["hi"]["checkpoint"] == "000007.pt"
    # the paper's spacing scaled to hi's 22.0: med near 16.9, lo near 10.2
    assert chosen["med"]["checkpoint"] == "000004.pt"
    assert chosen["lo"]["checkpoint"] == "000002.pt"
    assert separated(chosen["lo"], chosen["med"]) and separated(chosen["med"], chosen["hi"])
    assert chosen["lo"]["env_steps"] < chosen["med"]["env_steps"] < chosen["hi"]["env_steps"]


def test_overlapping_intervals_do_not_count_as_clearly_worse():
    assert not separated(row(1, 0.70, 17.5), row(2, 0.73, 18.0))  # success intervals overlap
    assert not separated(row(1, 0.50, 17.5), row(2, 0.80, 18.0))  # reward intervals overlap
    assert separated(row(1, 0.50, 15.0), row(2, 0.80, 18.0))
    # med may not be the snapshot just before hi when their intervals overlap
    chosen = choose([row(0, 0.2, 5.0), row(1, 0.5, 11.0), row(2, 0.94, 21.5), row(3, 0.96, 22.0)])
    assert chosen["med"]["checkpoint"] == "000001.pt" and chosen["lo"]["checkpoint"] == "000000.pt"


def test_runs_that_cannot_give_three_agents_say_what_to_do():
    with pytest.raises(ReleaseError, match=r"no snapshot reaches success >= 0.95.*train the run longer"):
        choose(CURVE[:7])
    with pytest.raises(ReleaseError, match=r"clearly worse.*to be lo; validate more checkpoints"):
        choose([row(0, 0.6, 15.0), row(1, 0.96, 22.0)])
