"""A build's time left and its plan follow measured rates: a job's seconds are its size (a search's budget, an
evaluation's episodes) at its group's rate, learned from the jobs done or measured on a few small jobs after one
run that pays what a worker pays once. The jobs here report the seconds they took, so nothing depends on this
machine's speed."""

from __future__ import annotations

import pytest

from search.bundle.plan import Timed, measured
from search.bundle.steps import IN_THIS_PROCESS, Rate, Work, finished


def reported(seconds: float) -> tuple[None, float]:
    """A job that took ``seconds``, as a step's job reports it."""
    return None, seconds


def test_the_time_left_follows_each_groups_rate_learned_from_its_jobs_done():
    sizes = {"a": Work("slow", 10), "b": Work("fast", 10), "c": Work("slow", 20), "d": Work("fast", 10)}
    took = {"a": 100.0, "b": 1.0, "c": 200.0, "d": 1.0}
    tasks = {key: (reported, (seconds,)) for key, seconds in took.items()}
    progress = [line for _, _, line in finished(tasks, IN_THIS_PROCESS, str, sizes.__getitem__)]
    assert progress == [
        "[1/4, about 7 min left]",  # c at the slow group's 10 s a unit, b and d as long as a job so far: 400 s
        "[2/4, about 3 min left]",  # c at the slow group's 10 s a unit, d at the fast group's 0.1 s: 201 s
        "[3/4, about 1 s left]",  # d at the fast group's rate, whatever the slow jobs took
        "[4/4]",
    ]


def test_a_measured_rate_leaves_out_the_first_run_and_follows_the_size():
    calls = []

    def run(size: int) -> Timed:  # a first run that pays 30 s of imports, then 0.5 s + 0.01 s a unit
        calls.append(size)
        return Timed(30.0 if len(calls) == 1 else 0.5 + 0.01 * size, size)

    rate = measured(run, 2, 1000)
    assert calls[:2] == [2, 2] and calls[-1] <= 1000  # warmed up at the start, then doubled
    assert rate.seconds(Work("", 1000)) == pytest.approx(0.5 + 0.01 * 1000)


def test_a_job_that_stops_by_itself_takes_what_it_took_at_any_size():
    rate = measured(lambda budget: Timed(0.3, min(budget, 71)), 200, 5000)  # it finds its clip in 71 steps
    assert rate == Rate(0.0, 0.3)
    assert rate.seconds(Work("", 5000)) == 0.3


def test_a_slow_job_that_falls_short_of_its_size_is_run_larger_to_tell_whether_it_stopped_by_itself():
    def run(budget: int) -> Timed:  # a search that finds its moments in 137 steps, 20 ms a step after 2 s
        steps = min(budget, 137)
        return Timed(2.0 + 0.02 * steps, steps)

    rate = measured(run, 100, 5000)  # its two runs at 100 and 200 steps take PROBE_TOTAL, but the second fell short
    assert rate.seconds(Work("", 5000)) == pytest.approx(2.0 + 0.02 * 137)
