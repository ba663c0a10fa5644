"""`in_processes`, which runs the bundle's and `foil search-all`'s jobs on this machine: a failure, named, stops the
tasks not started."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from search.solvers.runner import JobFailed, in_processes


def mark(folder: str, number: int) -> int:
    """A task that takes a moment and leaves a file saying it ran."""
    time.sleep(0.3)
    (Path(folder) / f"{number}.ran").touch()
    return number


def fail(folder: str, number: int) -> int:
    raise ValueError(f"task {number} failed")


def test_every_result_comes_back_once(tmp_path):
    tasks = {n: (mark, (str(tmp_path), n)) for n in range(6)}
    assert sorted(in_processes(tasks, 2)) == [(n, n) for n in range(6)]


def test_a_failed_task_cancels_those_not_yet_started(tmp_path):
    tasks = {0: (fail, (str(tmp_path), 0))} | {n: (mark, (str(tmp_path), n)) for n in range(1, 40)}
    with pytest.raises(JobFailed, match="^job 0 failed: ValueError: task 0 failed$"):
        for _ in in_processes(tasks, 2, describe=lambda number: f"job {number}"):
            pass
    assert len(list(tmp_path.glob("*.ran"))) < 39  # the rest were cancelled, not run to the end
