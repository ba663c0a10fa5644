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
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.formats import summary_json
from search.core.settings import check_keys, field_types
from search.solvers.domain import domain_for
from search.solvers.reward import RewardConfig
from search.solvers.rollout import Tracker
from search.solvers.solver import DEFAULT_SOLVER, Comparison, OwnSummaries, ProblemSearch, solver_named


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
    reward_settings: dict = field(default_factory=dict)
    world_settings: dict = field(default_factory=dict)
    world: str | None = None  # the world's name where a study names it (world = "..."), else found by the agents

    def __post_init__(self):
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


def parse_settings(cls, items: list[str], what: str) -> dict:
    """``key=value`` strings as a dict for dataclass ``cls``, each value converted to its field's type."""
    types = field_types(cls)
    settings = {}
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


def run_search(job: SearchJob, progress: bool = False) -> dict[str, str]:
    """Run one search in its agents' world and return its output files, name -> text: ``summary-001.json``, ...
    (best first, or in the order of a solver that chooses its own) and ``run.json``. Kept trajectories are
    replayed at batch size 1 and ranked by that authoritative reward."""
    started = time.perf_counter()
    solver = solver_named(job.solver)
    domain = domain_for(job.agents, job.scenario, job.world)
    job = replace(job, world_settings=domain.search_settings(job.agents, job.world_settings, job.scenario))
    reward_config = RewardConfig.from_dict(job.reward_settings)
    entry = {"name": job.solver, "parameters": asdict(job.solver_config), "seed": job.seed, "budget": job.budget}
    tracker = Tracker(job.budget, job.top_k, progress=progress, description=job.label)
    rng = np.random.default_rng(job.seed)
    chosen: tuple[str, list, dict] | None = None  # a solver's own: its record's key, summaries and record
    try:
        if isinstance(solver, ProblemSearch):
            coupled = domain.coupled(job.agents, domain.state(job.scenario, job.world_settings), job.reward_settings)
            scenario_name = coupled.scenario_name
            solver.run(coupled.problem, tracker, rng, job.solver_config)
        elif isinstance(solver, OwnSummaries):
            scenario_name = job.scenario
            comparison = Comparison(job.agents, job.scenario, domain, job.world_settings, job.reward_settings, entry)
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
    agents: list[str], scenarios: list[str], solvers: list[str], joint: bool = False, **common
) -> list[SearchJob]:
    """Every pair of agents (or, with ``joint``, all agents together) on every scenario with every solver."""
    groups = [tuple(agents)] if joint else list(itertools.combinations(agents, 2))
    return [
        SearchJob(agents=group, scenario=scenario, solver=solver, **common)
        for solver in solvers
        for group in groups
        for scenario in scenarios
    ]


def limit_threads() -> None:
    """One search per core: keep libraries inside a worker from starting a thread per core each."""
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(name, "1")


def in_processes(tasks: dict, workers: int) -> Iterator[tuple[Any, Any]]:
    """Run ``tasks`` (key -> (function, arguments)), ``workers`` at a time in separate processes (in this one
    when one worker or one task), yielding (key, result) as each finishes. A task that fails, or a caller that
    stops reading, cancels the tasks not yet started."""
    if workers <= 1 or len(tasks) <= 1:
        for key, (function, arguments) in tasks.items():
            yield key, function(*arguments)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    context = multiprocessing.get_context("spawn")  # no fork of a process holding numba or torch threads
    with ProcessPoolExecutor(min(workers, len(tasks)), mp_context=context, initializer=limit_threads) as pool:
        futures = {pool.submit(function, *arguments): key for key, (function, arguments) in tasks.items()}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        except BaseException:  # GeneratorExit too: nobody waits for the rest
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _job_in_worker(job: SearchJob) -> dict[str, str]:
    limit_threads()
    return run_search(job)


def run_all(
    jobs: list[SearchJob],
    out: str | Path,
    workers: int | None = None,
    backend: str = "process",
    ray_address: str | None = None,
    progress: bool = True,
) -> dict:
    """Run jobs in parallel and write each one's files to ``out/<solver>/<agents>/<scenario>/``; also writes
    ``out/study.json`` with every job's record. Returns that record."""
    from tqdm import tqdm

    started = time.perf_counter()
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    bar = tqdm(total=len(jobs), unit="search", disable=not progress)
    results: dict[int, dict[str, str]] = {}
    if backend == "ray":
        finished = _run_ray(jobs, ray_address, workers)
    elif backend == "process":
        finished = in_processes({index: (run_search, (job,)) for index, job in enumerate(jobs)}, workers)
    else:
        raise ValueError(f"unknown backend {backend!r}: use 'process' or 'ray'")
    for index, files in finished:
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
            | ({"warning": record["vote"]["warning"]} if "warning" in record.get("vote", {}) else {})
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


def _run_ray(jobs: list[SearchJob], address: str | None, workers: int):
    """Yield (index, files) as Ray tasks finish; a local Ray instance when no address is given."""
    try:
        import ray
    except ImportError:
        raise ValueError("the ray backend needs Ray: pip install 'foil[ray]'") from None
    started_here = not ray.is_initialized()
    if started_here:
        if address:
            ray.init(address=address)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        task = ray.remote(num_cpus=1)(_job_in_worker)
        pending = {task.remote(job): index for index, job in enumerate(jobs)}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                yield pending.pop(ref), ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()
