"""Independent work spread over worker processes, for a world without a batched fast path, whose Python
environment steps on one core: `foil eval`'s episodes, the representative solver's starting states (and the
representativeness check's), and HIGHLIGHTS' and Agent Disagreements' episodes from drawn starting states.

A task's result depends on the task alone, never on which worker ran it or how many there are, and results come
back in the tasks' order, so one worker and many give byte-identical results. A task carries what it needs as
names and values (a world's name, agents that pickle as their files, a scenario), each worker builds its own from
them (a world caches its agents per process), and a worker does its share itself, with no workers of its own.

How many: ``--jobs`` where a command takes it (`jobs`), else one per core. The worker processes stay up for the
rest of the command, so a search that spreads each batch of states pays for starting them once.

Work whose state stays put between calls (a coupled problem's rows, which MCTS steps together for its whole
search) goes to `Keepers` instead: workers that keep what their calls leave them, so each call sends only what
changed.
"""

from __future__ import annotations

import atexit
import itertools
import multiprocessing
import os
import pickle
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from functools import cache
from typing import Any

JOBS = "FOIL_JOBS"  # the environment variable that carries the count into worker processes


def cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def workers() -> int:
    """The worker processes independent work spreads over: what `jobs` set, else one per core; one in a process
    that another started to share its work (`foil search-all`'s and the bundle's searches, these workers), whose
    siblings already take the other cores."""
    value = os.environ.get(JOBS)
    if value:
        return int(value)
    return 1 if multiprocessing.parent_process() is not None else cores()


@contextmanager
def jobs(count: int | None) -> Iterator[None]:
    """``count`` workers for the independent work done within (None: as before, by default one per core); worker
    processes started within inherit it."""
    if count is None:
        yield
        return
    if count < 1:
        raise ValueError(f"--jobs must be at least 1 (1: everything in this process), got {count}")
    before = os.environ.get(JOBS)
    os.environ[JOBS] = str(count)
    try:
        yield
    finally:
        if before is None:
            del os.environ[JOBS]
        else:
            os.environ[JOBS] = before


def in_order(function: Callable[..., Any], tasks: Sequence[tuple[Any, ...]], count: int | None = None) -> list[Any]:
    """``function(*task)`` for every task, in the tasks' order, over ``count`` worker processes (default
    `workers`); in this process where one worker or one task is all there is. ``function`` and the tasks must
    pickle (a module-level function; names, numbers, arrays)."""
    count = min(workers() if count is None else count, len(tasks))
    if count <= 1:
        return [function(*task) for task in tasks]
    place = (os.getcwd(), list(sys.path))  # a worker reads relative files and imports as this process does now
    try:
        return list(_pool(count).map(_run, itertools.repeat(place), itertools.repeat(function), tasks))
    except BrokenProcessPool:
        _pool.cache_clear()  # a worker died (killed, out of memory): the next call starts new ones
        raise


def _run(place: tuple[str, list[str]], function: Callable[..., Any], task: tuple[Any, ...]) -> Any:
    cwd, path = place
    if os.getcwd() != cwd:
        os.chdir(cwd)
    sys.path[:] = path
    return function(*task)


def one_core() -> None:
    """A worker process's start: its libraries use one thread each, and its own work stays in it (it starts no
    workers of its own)."""
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    os.environ[JOBS] = "1"


@contextmanager
def lent(count: int) -> Iterator[None]:
    """``count`` workers for a job that stands for several (a study's searches that share their rollouts), where
    it runs in a worker process of its own: started on first use, and shut down when it ends, since a worker
    process ends without running `atexit` and would wait for them for ever."""
    with jobs(count):
        try:
            yield
        finally:
            if multiprocessing.parent_process() is not None and _pool.cache_info().currsize:
                for pool in _POOLS:
                    pool.shutdown(cancel_futures=True)
                _POOLS.clear()
                _pool.cache_clear()


_POOLS: list[ProcessPoolExecutor] = []  # the pools `_pool` started


@cache
def _pool(count: int) -> ProcessPoolExecutor:
    # spawned, not forked: no fork of a process that holds numba's or torch's threads
    pool = ProcessPoolExecutor(count, mp_context=multiprocessing.get_context("spawn"), initializer=one_core)
    atexit.register(pool.shutdown, cancel_futures=True)
    _POOLS.append(pool)
    return pool


class Keepers:
    """Worker processes that keep what their calls leave them, for work whose state stays put between calls: a
    coupled problem's rows stay in the worker that holds them, and each step sends only the step's actions. Each
    worker holds a dict that the functions it runs read and change (under a key of their own); its calls run on
    all chosen workers at once. Started once per command, like the pool."""

    def __init__(self, count: int):
        context = multiprocessing.get_context("spawn")
        self.connections: list[Any] = []
        self.forgotten: list[list[Any]] = [[] for _ in range(count)]  # keys to drop with each worker's next call
        for _ in range(count):
            mine, theirs = context.Pipe()
            context.Process(target=_keep, args=(theirs,), daemon=True).start()
            theirs.close()
            self.connections.append(mine)

    @property
    def count(self) -> int:
        return len(self.connections)

    def call(self, calls: dict[int, tuple[Callable[..., Any], tuple[Any, ...]]]) -> dict[int, Any]:
        """``function(kept, *arguments)`` on each chosen worker, all at once; the results by worker. A worker's
        error is raised here once every worker has answered, so the workers stay in step."""
        place = (os.getcwd(), list(sys.path))
        for worker, (function, arguments) in calls.items():
            forgotten, self.forgotten[worker] = self.forgotten[worker], []
            # the call as bytes, read once the worker imports as this process does (its classes may need that)
            self.connections[worker].send((place, forgotten, pickle.dumps((function, arguments))))
        results, failure = {}, None
        for worker in calls:
            try:
                ok, value = self.connections[worker].recv()
            except (EOFError, OSError):
                keepers.cache_clear()  # a worker died: the next command's problem starts new ones
                raise RuntimeError("a worker process holding a problem's rows died (killed, out of memory?)") from None
            if ok:
                results[worker] = value
            else:
                failure = failure or value
        if failure is not None:
            raise failure
        return results

    def forget(self, key: Any) -> None:
        """Drop what every worker keeps under ``key``, with its next call (safe from a finaliser: sends nothing)."""
        for forgotten in self.forgotten:
            forgotten.append(key)


def _keep(connection: Any) -> None:
    """A keeper's loop: run each call on the worker's dict and send its result, or its error, back."""
    one_core()
    kept: dict[Any, Any] = {}
    while True:
        try:
            (cwd, path), forgotten, call = connection.recv()
        except EOFError:  # the command ended
            return
        if os.getcwd() != cwd:
            os.chdir(cwd)
        sys.path[:] = path
        for key in forgotten:
            kept.pop(key, None)
        try:
            function, arguments = pickle.loads(call)
            connection.send((True, function(kept, *arguments)))
        except Exception as error:  # noqa: BLE001 - the caller raises it
            connection.send((False, _sendable(error)))


def _sendable(error: Exception) -> Exception:
    """The error itself where it pickles, else one that says what it was, with the worker's traceback."""
    import traceback

    try:
        pickle.loads(pickle.dumps(error))
        return error
    except Exception:  # noqa: BLE001 - any failure to pickle
        return RuntimeError("".join(traceback.format_exception(error)))


@cache
def keepers(count: int) -> Keepers:
    """The command's keepers: ``count`` worker processes, started on first use."""
    return Keepers(count)
