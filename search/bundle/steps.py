"""What every step of a bundle's build shares: results kept in the bundle's cache by a hash of their inputs (with
an agent's identity among them), and a step's jobs run on a backend with their progress for the log: its time
left from each job's size (`Work`) at the rate the jobs done ran at. The evaluations, searches, checks and renders
each use both; `search.bundle.plan` sizes the same jobs and measures their rates beforehand."""

from __future__ import annotations

import hashlib
import heapq
import json
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.formats import sha256_file
from search.core.domain import Domain
from search.solvers.runner import Backend, Tasks

IN_THIS_PROCESS = Backend()  # one worker: every job of a step in the building process

Log = Callable[[str], object]  # where a step's lines go: print, a list's append
Task = tuple[Callable[..., Any], tuple[Any, ...]]  # a job: (function, arguments), as `Backend.run` takes it


def input_key(inputs: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:16]


def agent_identity(agent: str, domain: Domain) -> dict[str, Any]:
    """What an agent's results depend on: its name and, for a network, the checksum of its file."""
    path = domain.agent_file(agent)
    return {"agent": agent, "sha256": sha256_file(path)} if path is not None and path.is_file() else {"agent": agent}


class Cache:
    """Results kept under ``root`` by a hash of their inputs, with the inputs beside them to check on reuse."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def path(self, kind: str, inputs: dict[str, Any]) -> Path:
        return self.root / kind / input_key(inputs)

    def valid(self, kind: str, inputs: dict[str, Any], *files: str) -> bool:
        folder = self.path(kind, inputs)
        try:
            recorded = json.loads((folder / "inputs.json").read_text())
        except (OSError, json.JSONDecodeError):
            return False
        return recorded == json.loads(json.dumps(inputs)) and all((folder / f).is_file() for f in files)

    def store(self, kind: str, inputs: dict[str, Any]) -> Path:
        """A fresh, empty folder for a result; write the result, then call ``seal``."""
        folder = self.path(kind, inputs)
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        return folder

    def seal(self, kind: str, inputs: dict[str, Any]) -> None:
        """Record the inputs last, so an interrupted build never leaves a result that looks complete."""
        (self.path(kind, inputs) / "inputs.json").write_text(json.dumps(inputs, sort_keys=True, indent=1))


@dataclass(frozen=True)
class Work:
    """A job's size in its step's units (a search's budget in simulator steps, an evaluation's episodes, a check's
    rollout steps, a clip's file) and the group whose pace it follows (a search its scheme's, an evaluation its
    agent's)."""

    group: str
    units: float


@dataclass(frozen=True)
class Rate:
    """What a job of a group takes: ``per_unit`` seconds for each unit of its size, and ``besides`` seconds; a
    worker's first job of its step ``warm_up`` seconds more (its imports, a compiled kernel)."""

    per_unit: float
    besides: float = 0.0
    warm_up: float = 0.0

    def seconds(self, work: Work) -> float:
        return self.besides + self.per_unit * work.units


def expected(work: Work, rates: dict[str, Rate]) -> float:
    """A job's expected seconds at its group's rate, else at the step's (under "")."""
    return (rates[work.group] if work.group in rates else rates[""]).seconds(work)


def learned(done: list[tuple[Work, float]]) -> dict[str, Rate]:
    """The rates of a step's jobs done, from their sizes and seconds: each group's seconds per unit, and under ""
    the mean seconds of a job, for a group none of whose jobs is done yet (a scheme's first search: budgets say
    little across schemes, where one scheme's searches stop by themselves well short of theirs)."""
    totals: dict[str, tuple[float, float]] = {}
    for work, seconds in done:
        units, took = totals.get(work.group, (0.0, 0.0))
        totals[work.group] = (units + work.units, took + seconds)
    rates = {group: Rate(took / units) for group, (units, took) in totals.items() if units > 0}
    return rates | {"": Rate(0.0, sum(seconds for _, seconds in done) / len(done))}


def makespan(seconds: list[float], workers: int, busy: list[float] | None = None) -> float:
    """When the last of jobs taking ``seconds`` finishes, each started in order on the first worker free;
    ``busy``: the seconds left of the jobs some workers are running."""
    busy = busy or []
    free = busy + [0.0] * min(workers - len(busy), len(seconds))
    heapq.heapify(free)
    for job in seconds:
        heapq.heappush(free, heapq.heappop(free) + job)
    return max(free, default=0.0)


def finished(
    tasks: Tasks, backend: Backend, describe: Callable[[Any], str], work: Callable[[Any], Work]
) -> Iterator[tuple[Any, Any, str]]:
    """Run a step's ``tasks``, each returning (result, its seconds), on ``backend``: (key, (result, seconds),
    progress) as each finishes, its progress the jobs done of the step's and the time left ("[3/8, about 2 min
    left]"): the jobs not done, sized by ``work``, at the rates of those done (`learned`: a scheme's searches at
    that scheme's pace once one is done), dealt to the workers in order as the backend deals them, less what
    the running ones have already run."""
    waiting = list(tasks)
    started = time.perf_counter()
    running = dict.fromkeys(waiting[: backend.workers], started)
    del waiting[: backend.workers]
    done: list[tuple[Work, float]] = []
    for count, (key, result) in enumerate(backend.run(tasks, describe), start=1):
        now = time.perf_counter()
        done.append((work(key), result[1]))
        del running[key]
        if waiting:
            running[waiting.pop(0)] = now
        rates = learned(done)
        busy = [max(expected(work(k), rates) - (now - began), 0.0) for k, began in running.items()]
        left = makespan([expected(work(k), rates) for k in waiting], backend.workers, busy)
        yield key, result, f"[{count}/{len(tasks)}" + (f", about {duration(left)} left]" if count < len(tasks) else "]")


def duration(seconds: float) -> str:
    """A length of time as a person reads it: 40 s, 12 min, 2 h 5 min."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 90 else f"{minutes // 60} h {minutes % 60} min"
