"""What every step of a bundle's build shares: results kept in the bundle's cache by a hash of their inputs (with
an agent's identity among them), and a step's jobs run on a backend with their progress for the log. The
evaluations, searches, checks and renders each use both; `search.bundle.plan` times the same jobs."""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from collections.abc import Callable, Iterator
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


def finished(tasks: Tasks, backend: Backend, describe: Callable[[Any], str]) -> Iterator[tuple[Any, Any, str]]:
    """Run a step's ``tasks`` on ``backend``: (key, result, progress) as each finishes, its progress the jobs done
    of the step's and, at the pace so far, the time left ("[3/8, about 2 min left]"), for a long step's log."""
    started = time.perf_counter()
    for done, (key, result) in enumerate(backend.run(tasks, describe), start=1):
        left = (time.perf_counter() - started) / done * (len(tasks) - done)
        yield key, result, f"[{done}/{len(tasks)}" + (f", about {duration(left)} left]" if done < len(tasks) else "]")


def duration(seconds: float) -> str:
    """A length of time as a person reads it: 40 s, 12 min, 2 h 5 min."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 90 else f"{minutes // 60} h {minutes % 60} min"
