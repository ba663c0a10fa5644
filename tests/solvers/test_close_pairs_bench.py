"""The close-pairs benchmark's judging (benchmarks/bench_close_pairs.py) on hand-made verdicts."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture
def bench(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    return importlib.import_module("bench_close_pairs")


def test_a_clip_is_flagged_by_an_undecided_truth_or_a_vote_warning(bench):
    assert bench.classify("better", False, []) == {"flagged": False, "misleading_unflagged": False}
    assert bench.classify("worse", False, []) == {"flagged": False, "misleading_unflagged": True}
    assert bench.classify("tie", False, []) == {"flagged": False, "misleading_unflagged": True}
    assert bench.classify("worse", True, []) == {"flagged": True, "misleading_unflagged": False}
    weak = ["weak vote: 3 states for a, 2 for b; the clip may show either agent as the better one"]
    assert bench.classify("worse", False, weak) == {"flagged": True, "misleading_unflagged": False}
    assert bench.classify("better", False, weak) == {"flagged": True, "misleading_unflagged": False}


def test_a_pairs_tally_counts_each_verdict_and_averages_the_cost(bench):
    def made(shows, undecided, warnings, vote_for, decided, steps, wall):
        return {"shows": shows, "vote_for": vote_for, "vote_decided": decided, "sim_steps": steps, "wall_s": wall} | (
            bench.classify(shows, undecided, warnings)
        )

    verdicts = [
        made("better", False, [], "better", True, 1000, 1.0),
        made("better", False, ["weak vote"], "better", False, 2000, 2.0),
        made("worse", False, [], "better", True, 3000, 3.0),
        made("tie", True, [], "neither", False, 4000, 4.0),
    ]
    row = bench.tally(verdicts)
    assert (row["clips"], row["better"], row["worse"], row["tie"]) == (4, 2, 1, 1)
    assert (row["flagged"], row["misleading_unflagged"]) == (2, 1)
    assert (row["votes_decided"], row["votes_for_better"]) == (2, 3)
    assert (row["sim_steps"], row["wall_s"]) == (2500, 2.5)
    assert bench.share(0, 20) == "0 of 20 (0%) [0%, 16%]"
    assert bench.share(20, 20) == "20 of 20 (100%) [84%, 100%]"


def test_the_ground_truth_is_the_close_pairs_last_look_else_the_studys_episodes(bench):
    from search.bundle.truth import PairedComparison

    evaluations = {"a": {"episode_rewards": [3.0, 2.0, 4.0, 3.0]}, "b": {"episode_rewards": [1.0, 1.0, 2.0, 1.5]}}
    first = bench.ground_truth(("a", "b"), evaluations, {})
    assert (first.difference, first.episodes, first.decided) == (1.625, 4, True)
    looked = PairedComparison(("b", "a"), -0.1, (-0.4, 0.2), 1.0, 32, False)
    assert bench.ground_truth(("a", "b"), evaluations, {("b", "a"): looked}) is looked
