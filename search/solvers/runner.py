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
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.formats import summary_json
from search.core.settings import check_keys, field_types
from search.solvers.baselines import CEMConfig, SamplingConfig, cem, n_first, random_search
from search.solvers.disagreements import Disagreement, DisagreementsConfig, disagreements
from search.solvers.domain import Domain, domain_for
from search.solvers.episodes import Episodes, draw_episodes
from search.solvers.follow import Follow
from search.solvers.highlights import HighlightsConfig, HighlightsDivConfig, Moment, highlights
from search.solvers.mcts import MCTSConfig, mcts
from search.solvers.representative import RepresentativeConfig, representative, summary_contrast, weak_vote
from search.solvers.reward import RewardConfig
from search.solvers.rollout import Tracker

SOLVERS: dict[str, tuple[Callable[..., Any], type]] = {
    "mcts": (mcts, MCTSConfig),
    "nfirst": (n_first, SamplingConfig),
    "random": (random_search, SamplingConfig),
    "cem": (cem, CEMConfig),
    "representative": (representative, RepresentativeConfig),  # draws its own states: see _representative
    # the field's summary methods: they play episodes and choose their own summaries (see _watching)
    "disagreements": (disagreements, DisagreementsConfig),
    "highlights": (highlights, HighlightsConfig),
    "highlights-div": (highlights, HighlightsDivConfig),
}
WATCHING = ("disagreements", "highlights", "highlights-div")


@dataclass(frozen=True)
class SearchJob:
    """One search: agents compared in one coupled simulator on one scenario. Settings override defaults."""

    agents: tuple[str, ...]
    scenario: str
    solver: str = "mcts"
    budget: int = 20_000
    seed: int = 0
    top_k: int = 30
    solver_settings: dict = field(default_factory=dict)
    reward_settings: dict = field(default_factory=dict)
    world_settings: dict = field(default_factory=dict)
    world: str | None = None  # the world's name where a study names it (world = "..."), else found by the agents

    def __post_init__(self):
        if len(self.agents) < 2:
            raise ValueError("a search compares at least two agents: give --agents A,B[,C...]")
        solver_config_class(self.solver)
        if self.budget < 1 or self.top_k < 1:
            raise ValueError("--budget and --top-k must be at least 1")

    @property
    def label(self) -> str:
        return f"{'-vs-'.join(map(_slug, self.agents))}/{_slug(self.scenario)}"


def solver_config_class(name: str):
    if name not in SOLVERS:
        raise ValueError(f"unknown solver {name!r}: use one of {sorted(SOLVERS)}")
    return SOLVERS[name][1]


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
    (best first) and ``run.json``. Kept trajectories are replayed at batch size 1 and ranked by that
    authoritative reward."""
    started = time.perf_counter()
    domain = domain_for(job.agents, job.scenario, job.world)
    job = replace(job, world_settings=domain.search_settings(job.agents, job.world_settings, job.scenario))
    reward_config = RewardConfig.from_dict(job.reward_settings)
    if job.solver == "representative" or job.solver in WATCHING:
        own = _representative if job.solver == "representative" else _watching
        return search_files(
            job,
            None,
            job.scenario,
            reward_config,
            started,
            progress,
            None,
            choose=lambda tracker, rng, config, solver: own(job, domain, tracker, rng, config, solver),
        )
    coupled = domain.coupled(job.agents, domain.state(job.scenario, job.world_settings), job.reward_settings)
    return search_files(
        job, coupled.problem, coupled.scenario_name, reward_config, started, progress, coupled.summarize
    )


def search_files(
    job: SearchJob,
    problem,
    scenario_name: str,
    reward_config: RewardConfig,
    started: float,
    progress: bool,
    summarize,
    choose=None,
) -> dict[str, str]:
    """Search ``problem`` with the job's solver and write its files; ``summarize(env_actions, solver)`` builds the
    summary of a kept trajectory (any domain's). ``choose(tracker, rng, solver_config, solver)`` (the solvers that
    choose their own summaries) replaces both: it gives the summaries in its own order and a record for run.json
    (``vote`` for the representative solver, ``method`` for the others)."""
    solve, config_class = SOLVERS[job.solver]
    solver_config = config_class(**job.solver_settings)
    tracker = Tracker(job.budget, job.top_k, progress=progress, description=job.label)
    rng = np.random.default_rng(job.seed)
    solver = {"name": job.solver, "parameters": asdict(solver_config), "seed": job.seed, "budget": job.budget}
    voted = None
    try:
        if choose is not None:
            summaries, voted = choose(tracker, rng, solver_config, solver)
        else:
            solve(problem, tracker, rng, solver_config)
    finally:
        tracker.close()
    search_time = time.perf_counter() - started
    solver["budget_used"] = tracker.steps
    if voted is None:
        summaries = [
            summarize(found.actions, solver | {"search_reward": found.reward, "found_at_step": found.sim_steps})
            for found in tracker.queue.ranked()
        ]
        summaries.sort(key=lambda s: -s["reward"])  # stable: ties keep the search's order
    files = {}
    for rank, summary in enumerate(summaries, start=1):
        summary["solver"]["rank"] = rank
        files[f"summary-{rank:03d}.json"] = summary_json(summary)
    record = {
        "format": "foil.run/1",
        "agents": list(job.agents),
        "scenario": scenario_name,
        "solver": solver,
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
    if voted is not None:
        record["vote" if job.solver == "representative" else "method"] = voted
    files["run.json"] = json.dumps(record, indent=1) + "\n"
    return files


def _representative(
    job: SearchJob,
    domain: Domain,
    tracker: Tracker,
    rng: np.random.Generator,
    config: RepresentativeConfig,
    solver: dict,
) -> tuple[list, dict]:
    """The representative solver's summaries (in its order: the chosen clip first) and the record of its vote.
    Each summary's scenario is the starting state it was drawn as; its solver entry says which state and what
    contrast the search saw."""
    if not domain.is_distribution(job.scenario):
        raise ValueError(
            f"the representative solver draws starting states from a distribution (such as "
            f"'training'); {job.scenario!r} is one fixed scenario"
        )
    if len(job.agents) != 2:
        raise ValueError(f"the representative solver votes which of two agents looks better; got {len(job.agents)}")
    scenarios = domain.draw_states(job.scenario, job.world_settings, rng, config.states)
    agents = list(job.agents)

    def roll_out(states: list, pushes: int, rng: np.random.Generator, tracker: Tracker):
        return domain.roll_out(agents, states, job.reward_settings, pushes, rng, tracker)

    def replay(scenario, actions) -> tuple[float, dict]:
        coupled = domain.coupled(agents, scenario, job.reward_settings)
        summary = coupled.summarize(actions, solver)
        return summary_contrast(summary, coupled.world), summary

    horizon = RewardConfig.from_dict(job.reward_settings).horizon
    summaries, vote = representative(roll_out, scenarios, tracker, rng, config, replay, horizon)
    warning = weak_vote(vote, agents)
    if warning:
        vote["warning"] = warning
    strength = {
        key: vote[key] for key in ("states", "for_first", "for_second", "no_majority", "sign_test_p", "decided")
    }
    for summary, chosen in zip(summaries, vote["chosen"], strict=True):
        summary["solver"] = summary["solver"] | {
            "budget_used": tracker.steps,
            "state": chosen["state"],
            "search_contrast": chosen["contrast"],
            "vote": strength,
        }
    return summaries, vote


def _watching(
    job: SearchJob, domain: Domain, tracker: Tracker, rng: np.random.Generator, config, solver: dict
) -> tuple[list, dict]:
    """The summaries of a method that watches the agents play (Agent Disagreements, HIGHLIGHTS, HIGHLIGHTS-DIV),
    from the job's scenario, or from states drawn from it when it is a distribution."""
    if len(job.agents) != 2:
        raise ValueError(f"the {job.solver} method compares two agents; got {len(job.agents)}")
    if domain.is_distribution(job.scenario):
        states = domain.draw_states(job.scenario, job.world_settings, rng, config.episodes)
    else:
        states = [domain.state(job.scenario, job.world_settings)]
    agents = list(job.agents)
    groups = draw_episodes(lambda s: domain.coupled(agents, s, job.reward_settings), states, config.episodes, rng)
    shown = domain.shown

    def summary(
        group: Episodes, episode: int, end: int, follow: Follow | None, window: tuple[int, int] | None, note: dict
    ):
        actions = group.env[episode - group.first, :end]
        return group.coupled.summarize(actions, solver | note, follow=follow, window=window, horizon=end)

    if job.solver == "disagreements":

        def of_disagreement(group: Episodes, d: Disagreement) -> dict:
            end = d.step + d.branch
            if not d.forked:
                return summary(group, d.episode, end, None, None, {"episode": d.episode, "disagreement_step": None})
            window = (max(0, d.step - config.horizon // 2), end)
            note = {"episode": d.episode, "disagreement_step": d.step, "importance": d.importance}
            return summary(group, d.episode, end, Follow(0, d.step), window, note)

        return _spent(disagreements(groups, tracker, config, shown, of_disagreement), tracker)

    def of_moment(group: Episodes, agent: int, m: Moment) -> dict:
        first, end = m.window(config.context)
        note = {"reel": agents[agent], "episode": m.episode, "state_step": m.step, "importance": m.importance}
        return summary(group, m.episode, end, Follow(agent, end), (first, end), note)

    return _spent(highlights(groups, tracker, config, of_moment), tracker)


def _spent(chosen: tuple[list, dict], tracker: Tracker) -> tuple[list, dict]:
    """The summaries with the steps the whole search took, as every solver's summaries say."""
    for summary in chosen[0]:
        summary["solver"]["budget_used"] = tracker.steps
    return chosen


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
