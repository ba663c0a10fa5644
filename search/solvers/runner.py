"""Running searches: one comparison (``foil search``), or every agent pair on every scenario (``foil search-all``)
in parallel processes on this machine or as tasks on a Ray cluster.

A job returns its output files as text and the caller writes them, so a Ray worker on another machine needs no
shared file system. Every job of a study uses the same seed, so ``foil search`` with that seed reproduces any one
of them exactly.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import socket
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from importlib.util import find_spec
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.formats import summary_json
from search.core.domain import domain_for
from search.core.problem import require
from search.core.rollout import Tracker
from search.core.settings import check_keys, field_types
from search.core.workers import one_core
from search.solvers.reward import RewardConfig
from search.solvers.solver import DEFAULT_SOLVER, Comparison, OwnSummaries, ProblemSearch, solver_named

if TYPE_CHECKING:
    from concurrent.futures import ProcessPoolExecutor

# Independent jobs: key -> (function, arguments), each run as function(*arguments).
Tasks = dict[Any, tuple[Callable[..., Any], tuple[Any, ...]]]


@dataclass(frozen=True)
class SearchJob:
    """One search: agents compared in one coupled simulator on one scenario. Settings override defaults; the
    solver's config is its solver's ``config_class`` (None: its defaults)."""

    agents: tuple[str, ...]
    scenario: str
    solver: str = DEFAULT_SOLVER
    budget: int = 20_000
    seed: int = 0
    top_k: int = 30
    solver_config: Any = None
    reward_settings: dict[str, Any] = field(default_factory=dict)
    world_settings: dict[str, Any] = field(default_factory=dict)
    world: str | None = None  # the world's name where a study names it (world = "..."), else found by the agents

    def __post_init__(self) -> None:
        if len(self.agents) < 2:
            raise ValueError("a search compares at least two agents: give --agents A,B[,C...]")
        config_class = solver_named(self.solver).config_class
        if self.solver_config is None:
            object.__setattr__(self, "solver_config", config_class())
        elif type(self.solver_config) is not config_class:
            raise ValueError(
                f"the {self.solver} solver takes a {config_class.__name__}, not a "
                f"{type(self.solver_config).__name__}: give its settings as {config_class.__name__}(...)"
            )
        if self.budget < 1 or self.top_k < 1:
            raise ValueError("--budget and --top-k must be at least 1")

    @property
    def label(self) -> str:
        return f"{'-vs-'.join(map(_slug, self.agents))}/{_slug(self.scenario)}"


def _slug(name: str) -> str:
    """A file-name-safe form of an agent or scenario name (a checkpoint path becomes its stem)."""
    stem = Path(name).stem if ("/" in name or name.endswith((".pt", ".toml"))) else name
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", stem)


def parse_settings(cls: type, items: list[str], what: str) -> dict[str, Any]:
    """``key=value`` strings as a dict for dataclass ``cls``, each value converted to its field's type."""
    types = field_types(cls)
    settings: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep:
            raise ValueError(f"bad {what} setting {item!r}: use key=value with a key among {sorted(types)}")
        try:
            check_keys([key], types, f"{what} setting")
        except ValueError as error:
            raise ValueError(f"bad {what} setting {item!r}: {error}") from None
        kind = types[key]
        try:
            if kind is bool:
                if text.lower() not in ("true", "false", "1", "0"):
                    raise ValueError
                settings[key] = text.lower() in ("true", "1")
            else:
                settings[key] = kind(text)
        except ValueError:
            raise ValueError(f"bad {what} setting {item!r}: {key} takes a {kind.__name__}") from None
    return settings


def refuse_before_work(job: SearchJob) -> None:
    """Refuse, before any work, a search that cannot be what was meant: a searched clip given longer than an episode
    of its world (a horizon written in steps before lengths of time became seconds, a longest clip; the reward's
    default of 100 steps is no length anyone wrote, and its rollouts end with the episode), and a solver
    that needs a capability its world's coupled problem lacks (`search.core.problem.require`; the problem of one
    starting state is built, never stepped)."""
    solver = solver_named(job.solver)
    domain = domain_for(job.agents, job.scenario, job.world)
    world = domain.search_settings(job.agents, job.world_settings, job.scenario)
    horizon = RewardConfig.from_dict(job.reward_settings).horizon
    step, longest = domain.step_seconds(job.scenario, world), domain.episode_seconds(job.scenario, world)
    clip = solver.longest_clip(job.solver_config, horizon)
    written = job.reward_settings.get("horizon", RewardConfig().horizon) != RewardConfig().horizon  # not the default
    if clip is not None and longest is not None and written and horizon * step > longest:
        raise ValueError(
            f"the reward's horizon is {horizon} steps ({horizon * step:g} s), longer than an episode here "
            f"({longest:g} s): a horizon written in steps before lengths of time became seconds now asks for that many "
            "seconds; give it in seconds (horizon = S) or in steps as horizon_steps = N"
        )
    if clip is not None and longest is not None and clip > horizon and clip * step > longest:
        raise ValueError(
            f"the {solver.name} solver's longest clip is {clip} steps ({clip * step:g} s), longer than an episode here "
            f"({longest:g} s): give it at most {longest:g} s"
        )
    if not solver.needs:
        return
    if domain.is_distribution(job.scenario):
        state = domain.draw_states(job.scenario, world, np.random.default_rng(job.seed), 1)[0]
    else:
        state = domain.state(job.scenario, world)
    require(domain.coupled(job.agents, state, job.reward_settings).problem, solver.needs, solver.name)


def run_search(job: SearchJob, progress: bool = False, pool: Any = None) -> dict[str, str]:
    """Run one search in its agents' world and return its output files, name -> text: ``summary-001.json``, ...
    (best first, or in the order of a solver that chooses its own) and ``run.json``. Kept trajectories are
    replayed at batch size 1 and ranked by that authoritative reward. A solver that chooses its own summaries
    reads rollouts it shares with other searches from ``pool`` (`search.solvers.pool.Pool`). Its callers
    refuse, once and before any work, a search that cannot be what was meant (`refuse_before_work`)."""
    started = time.perf_counter()
    solver = solver_named(job.solver)
    domain = domain_for(job.agents, job.scenario, job.world)
    job = replace(job, world_settings=domain.search_settings(job.agents, job.world_settings, job.scenario))
    reward_config = RewardConfig.from_dict(job.reward_settings)
    entry = {"name": job.solver, "parameters": asdict(job.solver_config), "seed": job.seed, "budget": job.budget}
    tracker = Tracker(job.budget, job.top_k, progress=progress, description=job.label)
    rng = np.random.default_rng(job.seed)
    chosen: tuple[str, list[dict[str, Any]], dict[str, Any]] | None = (
        None  # a solver's own: its record's key, summaries and record
    )
    try:
        if isinstance(solver, ProblemSearch):
            coupled = domain.coupled(job.agents, domain.state(job.scenario, job.world_settings), job.reward_settings)
            scenario_name = coupled.scenario_name
            solver.run(coupled.problem, tracker, rng, job.solver_config)
        elif isinstance(solver, OwnSummaries):
            scenario_name = job.scenario
            comparison = Comparison(
                job.agents, job.scenario, domain, job.world_settings, job.reward_settings, entry, pool
            )
            chosen = (solver.record_key, *solver.choose(comparison, tracker, rng, job.solver_config))
        else:
            raise TypeError(f"solver {job.solver!r} is a {type(solver).__name__}: a ProblemSearch or OwnSummaries runs")
    finally:
        tracker.close()
    search_time = time.perf_counter() - started
    entry["budget_used"] = tracker.steps
    summaries: list[Any]  # each checked as a Summary when written
    if chosen is None:
        summaries = [
            coupled.summarize(found.actions, entry | {"search_reward": found.reward, "found_at_step": found.sim_steps})
            for found in tracker.queue.ranked()
        ]
        summaries.sort(key=lambda s: -s["reward"])  # stable: ties keep the search's order
    else:
        summaries = chosen[1]
    files = {}
    for rank, summary in enumerate(summaries, start=1):
        summary["solver"]["rank"] = rank
        files[f"summary-{rank:03d}.json"] = summary_json(summary)
    record = {
        "format": "foil.run/1",
        "agents": list(job.agents),
        "scenario": scenario_name,
        "solver": entry,
        "reward_parameters": reward_config.to_dict(),
        "top_k": job.top_k,
        "trajectories": tracker.trajectories,
        "sim_steps": tracker.steps,
        "search_wall_s": search_time,
        "wall_s": time.perf_counter() - started,
        "steps_per_s": tracker.steps / max(search_time, 1e-9),
        "best_reward": summaries[0]["reward"] if summaries else None,
        "curve": [[steps, reward] for steps, reward in tracker.curve],
        "summaries": [
            {"file": name, "reward": s["reward"], "search_reward": s["solver"].get("search_reward")}
            for name, s in zip(files, summaries, strict=True)
        ],
    }
    if chosen is not None:
        record[chosen[0]] = chosen[2]
    files["run.json"] = json.dumps(record, indent=1) + "\n"
    return files


def write_outputs(out: str | Path, files: dict[str, str]) -> Path:
    """Write a search's files into ``out``, removing summaries left there by an earlier run."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob("summary-[0-9][0-9][0-9].json"):
        stale.unlink()
    for name, text in files.items():
        (out / name).write_text(text)
    return out


def study_jobs(
    agents: list[str], scenarios: list[str], solvers: list[str], joint: bool = False, **common: Any
) -> list[SearchJob]:
    """Every pair of agents (or, with ``joint``, all agents together) on every scenario with every solver."""
    groups = [tuple(agents)] if joint else list(itertools.combinations(agents, 2))
    return [
        SearchJob(agents=group, scenario=scenario, solver=solver, **common)
        for solver in solvers
        for group in groups
        for scenario in scenarios
    ]


class JobFailed(RuntimeError):
    """A job that raised on its worker (or whose worker died more often than Ray retries it), named by what it
    was for: a search by its scheme, scenario and pair, an evaluation by its agent."""


def in_processes(
    tasks: Tasks, workers: int, describe: Callable[[Any], str] = str, pool: ProcessPoolExecutor | None = None
) -> Iterator[tuple[Any, Any]]:
    """Run ``tasks`` (key -> (function, arguments)), ``workers`` at a time in separate processes (``pool``'s where
    one is open, in this process when one worker or one task), yielding (key, result) as each finishes. A task
    that fails raises JobFailed naming it by ``describe(key)``; it, or a caller that stops reading, cancels the
    tasks not yet started."""
    if workers <= 1 or len(tasks) <= 1:
        for key, (function, arguments) in tasks.items():
            with _named(key, describe):
                result = function(*arguments)
            yield key, result
        return
    if pool is None:
        with process_pool(min(workers, len(tasks))) as own:
            yield from in_processes(tasks, workers, describe, own)
        return
    from concurrent.futures import as_completed

    futures = {pool.submit(function, *arguments): key for key, (function, arguments) in tasks.items()}
    try:
        for future in as_completed(futures):
            with _named(futures[future], describe):
                result = future.result()
            yield futures[future], result
    except BaseException:  # GeneratorExit too: nobody waits for the rest
        for future in futures:
            future.cancel()
        raise


def process_pool(workers: int) -> ProcessPoolExecutor:
    """``workers`` fresh processes, each with one core's worth of threads."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")  # no fork of a process holding numba or torch threads
    return ProcessPoolExecutor(workers, mp_context=context, initializer=one_core)


@contextmanager
def _named(key: Any, describe: Callable[[Any], str]) -> Iterator[None]:
    try:
        yield
    except Exception as error:
        raise JobFailed(f"{describe(key)} failed: {type(error).__name__}: {error}") from error


BACKENDS = ("process", "ray")
RAY_ADDRESS = re.compile(r"auto|(ray://)?[A-Za-z0-9.\-\[\]:]+:[0-9]{1,5}")  # HOST:PORT, ray://HOST:PORT
RAY_RETRIES = 2  # a task whose worker or node died is run again this many times; an exception is not (same seed)
RAY_CONNECT_S = 10.0  # how long a cluster's head may take to accept a connection (Ray itself waits for minutes)


def answers(address: str) -> None:
    """Refuse a Ray address where nothing accepts a connection, at once: Ray retries such an address for minutes,
    printing warnings. ``auto`` is Ray's own to find."""
    if address == "auto":
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CONNECT_S).close()
    except OSError as error:
        raise ValueError(
            f"no Ray cluster answers at {address} ({error or 'timed out'}): start its head with `ray start --head` "
            "on that machine (docs/search.md), check the host and port, or leave out --ray-address for a Ray "
            "instance on this machine"
        ) from None


class Backend:
    """Where a command's independent jobs run: ``workers`` processes on this machine (``process``), or tasks on
    a Ray cluster (``ray``: the one at ``address``, else a local instance of ``workers`` CPUs). A job takes and
    returns values, never paths, so a worker on another machine needs no shared disk; the caller writes the
    files, so where a job ran never changes them."""

    def __init__(self, name: str = "process", workers: int = 1, address: str | None = None) -> None:
        if name not in BACKENDS:
            raise ValueError(f"unknown backend {name!r}: use {' or '.join(map(repr, BACKENDS))}")
        if workers < 1:
            raise ValueError(f"--jobs must be at least 1, got {workers}")
        if address is not None and name != "ray":
            raise ValueError("--ray-address needs --backend ray")
        if name == "ray" and find_spec("ray") is None:
            raise ValueError("the ray backend needs Ray: pip install 'foil[ray]'")
        if address is not None and not RAY_ADDRESS.fullmatch(address):
            raise ValueError(
                f"bad Ray address {address!r}: give HOST:PORT of the cluster's head (e.g. 10.0.0.5:6379), "
                "ray://HOST:PORT of its client server, or auto"
            )
        if address is not None:
            answers(address)
        self.name, self.workers, self.address = name, workers, address
        self._pool: ProcessPoolExecutor | None = None

    def __repr__(self) -> str:
        return f"Backend({self.name!r}, workers={self.workers}, address={self.address!r})"

    @contextmanager
    def session(self) -> Iterator[Backend]:
        """The backend held open for every ``run`` inside, so a command's steps share one set of worker
        processes (started, and their imports paid, once) or one connection to Ray (a local instance started
        here is stopped at the end)."""
        if self.name == "process":
            if self.workers == 1 or self._pool is not None:
                yield self
                return
            with process_pool(self.workers) as self._pool:
                try:
                    yield self
                finally:
                    self._pool = None
            return
        import ray

        started_here = not ray.is_initialized()
        if started_here:
            if self.address:
                try:
                    ray.init(address=self.address, log_to_driver=False)
                except (ConnectionError, RuntimeError, ValueError) as error:
                    raise ValueError(f"cannot connect to the Ray cluster at {self.address}: {error}") from None
            else:
                ray.init(num_cpus=self.workers, include_dashboard=False, log_to_driver=False)
        try:
            yield self
        finally:
            if started_here:
                ray.shutdown()

    def run(self, tasks: Tasks, describe: Callable[[Any], str] = str) -> Iterator[tuple[Any, Any]]:
        """(key, result) of each of ``tasks`` (key -> (function, arguments)) as it finishes; a failed one raises
        JobFailed naming it by ``describe(key)`` and cancels those not started."""
        if self.name == "process":
            yield from in_processes(tasks, self.workers, describe, self._pool)
            return
        with self.session():
            import ray

            remote = ray.remote(num_cpus=1, max_retries=RAY_RETRIES)(_in_worker)
            place = (os.getcwd(), list(sys.path))
            pending = {remote.remote(place, function, arguments): key for key, (function, arguments) in tasks.items()}
            try:
                while pending:
                    done, _ = ray.wait(list(pending), num_returns=1)
                    for ref in done:
                        key = pending.pop(ref)
                        with _named(key, describe):
                            result = ray.get(ref)
                        yield key, result
            finally:
                for ref in pending:
                    ray.cancel(ref)


def _in_worker(place: tuple[str, list[str]], function: Callable[..., Any], arguments: tuple[Any, ...]) -> Any:
    """A job on a Ray worker, one core's worth of threads, reading relative files and importing as the command
    does where its folder is there too (a worker on this machine); elsewhere from the worker's own."""
    one_core()
    folder, path = place
    if os.path.isdir(folder):
        os.chdir(folder)
        sys.path[:] = list(dict.fromkeys([*path, *sys.path]))
    return function(*arguments)


def run_all(
    jobs: list[SearchJob],
    out: str | Path,
    workers: int | None = None,
    backend: str = "process",
    ray_address: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run jobs in parallel and write each one's files to ``out/<solver>/<agents>/<scenario>/``; also writes
    ``out/study.json`` with every job's record. Returns that record."""
    from tqdm import tqdm

    started = time.perf_counter()
    for job in jobs:  # every job's capabilities before the first runs
        refuse_before_work(job)
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    runner = Backend(backend, workers, ray_address)
    bar = tqdm(total=len(jobs), unit="search", disable=not progress)
    results: dict[int, dict[str, str]] = {}
    tasks = {index: (run_search, (job,)) for index, job in enumerate(jobs)}
    for index, files in runner.run(tasks, lambda index: f"search {jobs[index].solver} {jobs[index].label}"):
        results[index] = files
        bar.update()
    bar.close()

    records = []
    for index, job in enumerate(jobs):
        where = write_outputs(Path(out) / job.solver / job.label, results[index])
        record = json.loads(results[index]["run.json"])
        records.append(
            {
                "dir": str(where.relative_to(out)),
                "agents": list(job.agents),
                "scenario": job.scenario,
                "solver": job.solver,
                "best_reward": record["best_reward"],
                "wall_s": record["wall_s"],
                "sim_steps": record["sim_steps"],
            }
            | ({"warning": " ".join(warnings)} if (warnings := solver_named(job.solver).warnings(record)) else {})
        )
    study = {
        "format": "foil.study-search/1",
        "backend": backend,
        "workers": workers,
        "wall_s": time.perf_counter() - started,
        "jobs": records,
    }
    (Path(out) / "study.json").write_text(json.dumps(study, indent=1) + "\n")
    return study
