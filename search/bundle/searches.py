"""A bundle's clips and the searches behind them: every clip the study's sets ask for, with its robot numbers
(`plan_clips`), each clip's search with everything it depends on (its inputs, the key of its result in the cache),
and the searches run on a backend, a cached one reused while its inputs are unchanged and it still re-simulates."""

from __future__ import annotations

import hashlib
import itertools
import json
import random
import time
from dataclasses import asdict, dataclass, replace
from typing import Any, cast

from search.bundle.spec import BuildSpec, Scheme
from search.bundle.steps import IN_THIS_PROCESS, Cache, Log, Work, agent_identity, finished, input_key
from search.bundle.study import Study
from search.core.domain import Domain, domain_for
from search.solvers.runner import Backend, SearchJob, run_search, write_outputs
from search.solvers.solver import solver_named
from search.solvers.summary import verify


@dataclass(frozen=True)
class ClipJob:
    """One clip: the pair in search order (the summary's agents) and each one's robot number on screen."""

    id: str
    scheme: Scheme
    scenario: str
    pair: tuple[str, str]
    numbers: tuple[int, int]
    parts: tuple[str, ...]


def plan_clips(spec: BuildSpec) -> list[ClipJob]:
    """Every clip of the study with its robot numbers. Numbers are handed out in blocks and never twice: a block
    of two per clip, or, in a set that feeds a ranking, one per scheme and scenario (a round) with one number per
    agent across its clips. So a participant never sees one name (colour, shape) stand for two agents, whichever
    clips their plan shows, and a round's robots keep theirs. Which agent gets which number of its block is drawn
    from a seeded generator named after the clip or round. An agent's reels in one part show other moments in each
    of its questions (`_distinct_reels`)."""
    jobs, first = [], 1
    for i, clip_set in enumerate(spec.sets):
        for scheme, scenario in itertools.product(clip_set.schemes, clip_set.scenarios):
            group = f"{spec.seed}/{i}/{scheme}/{scenario}"
            if clip_set.ranking:
                block = range(first, first + len(clip_set.agents))
                first += len(block)
                shared = dict(zip(clip_set.agents, random.Random(group).sample(block, len(block)), strict=True))
            for pair in clip_set.pairs:
                name = f"{group}/{pair[0]}/{pair[1]}"
                if clip_set.ranking:
                    numbers = cast(tuple[int, int], tuple(shared[a] for a in pair))
                else:
                    numbers, first = (
                        cast(tuple[int, int], tuple(random.Random(name).sample([first, first + 1], 2))),
                        first + 2,
                    )
                for parts, suffix, drawn in _draws(spec.schemes[scheme], clip_set.parts):
                    jobs.append(
                        ClipJob(
                            id="clip-" + hashlib.sha256(f"{name}{suffix}".encode()).hexdigest()[:10],
                            scheme=drawn,
                            scenario=scenario,
                            pair=pair,
                            numbers=numbers,
                            parts=parts,
                        )
                    )
    return _distinct_reels(jobs)


def _distinct_reels(jobs: list[ClipJob]) -> list[ClipJob]:
    """The jobs with each reel search told, per agent, how many of its reels the study shows before it in the
    same part under the same scheme and scenario (the solver's ``earlier``): it then shows the agent's next
    moments, so a participant who meets an agent in two questions of a part sees two different reels, not one
    twice. A scheme whose reels may repeat (``reels = "repeat"``), and reels in different parts, are left alone."""
    shown: dict[tuple[str, str, str, str], int] = {}  # (part, scheme, scenario, agent): its reels planned so far
    planned = []
    for job in jobs:
        scheme = job.scheme
        if solver_named(scheme.solver).reels and scheme.reels == "distinct":
            keys = [[(part, scheme.name, job.scenario, agent) for part in job.parts] for agent in job.pair]
            earlier = tuple(max(shown.get(key, 0) for key in agent_keys) for agent_keys in keys)
            for agent_keys, count in zip(keys, earlier, strict=True):
                shown |= dict.fromkeys(agent_keys, count + 1)
            if any(earlier):
                job = replace(job, scheme=replace(scheme, solver_config=replace(scheme.solver_config, earlier=earlier)))
        planned.append(job)
    return planned


def _draws(scheme: Scheme, parts: tuple[str, ...]) -> list[tuple[tuple[str, ...], str, Scheme]]:
    """The clips of a set's pair under a scheme, as (parts fed, suffix of the clip's name, scheme): one for all the
    set's parts. A solver that votes on rollouts it shares (``pooled``: the representative solver) would choose
    the same clip for both parts, so a set feeding both gets a clip of its own for the ranking, whose round would
    otherwise replay part one's clips: from the same vote, another state (``earlier = 1``)."""
    if not solver_named(scheme.solver).pooled or not {"pairwise", "ranking"} <= set(parts):
        return [(parts, "", scheme)]
    ranking = replace(scheme, solver_config=replace(scheme.solver_config, earlier=1))
    return [(tuple(part for part in parts if part != "ranking"), "", scheme), (("ranking",), "/ranking", ranking)]


def search_job(job: ClipJob, study: Study | None = None) -> SearchJob:
    """The search behind a clip, with its scheme's settings, in the ``study``'s world settings
    (`Study.world_settings`: the agents', under the scenario file's and the scheme's); without a study, in the
    scheme's world settings alone, in the world the agents and scenario belong to."""
    scheme = job.scheme
    world = study.world_settings(job.scenario, scheme.world) if study is not None else dict(scheme.world)
    return SearchJob(
        agents=job.pair,
        scenario=job.scenario,
        solver=scheme.solver,
        budget=scheme.budget,
        seed=scheme.seed,
        top_k=scheme.top_k,
        solver_config=scheme.solver_config,
        reward_settings=scheme.reward.to_dict(),
        world_settings=world,
        world=study.named if study is not None else None,
    )


def search_inputs(search: SearchJob, domain: Domain | None = None) -> dict[str, Any]:
    """Everything a clip's search depends on, with every default resolved, so a changed default is a changed
    input; ``domain`` is the search's world (a study's, `Study.domain`), else found from its agents and
    scenario."""
    from search.solvers.reward import RewardConfig

    domain = domain or domain_for(search.agents, search.scenario, search.world)
    return {
        "agents": [agent_identity(a, domain) for a in search.agents],
        "scenario": domain.scenario_dict(search.scenario, search.world_settings),
        "solver": search.solver,
        "rules": solver_named(search.solver).rules,
        "solver_settings": asdict(search.solver_config),
        "reward": RewardConfig(**search.reward_settings).to_dict(),
        "budget": search.budget,
        "seed": search.seed,
        "top_k": search.top_k,
    }


def describe_search(job: ClipJob) -> str:
    """A clip's search as the log names it."""
    return f"search {job.scheme.name} {job.scenario} {job.pair[0]}-{job.pair[1]}"


def _reusable(job: ClipJob, inputs: dict[str, Any], cache: Cache, log: Log) -> bool:
    """A cached search is reused while its inputs are unchanged and its summary still re-simulates exactly
    (`foil verify`), so changes to the simulator or the policies' code are caught too."""
    if not cache.valid("search", inputs, "summary-001.json"):
        return False
    problems = verify(cache.path("search", inputs) / "summary-001.json")
    if problems:
        log(
            f"{describe_search(job)}: the cached summary no longer re-simulates exactly ({problems[0]}); "
            "searching again"
        )
        return False
    log(f"{describe_search(job)}: cached")
    return True


def search_work(job: ClipJob, search: SearchJob) -> Work:
    """A search's size: its budget in simulator steps, at its scheme's pace."""
    return Work(job.scheme.name, search.budget)


def search_job_files(search: SearchJob) -> tuple[dict[str, str], float]:
    """One search's files (`run_search`) and the seconds it took."""
    started = time.perf_counter()
    return run_search(search), time.perf_counter() - started


def pool_key(search: SearchJob) -> str | None:
    """What a search's shared rollouts depend on (`search.solvers.pool`), for a solver whose votes read a pool:
    searches with one key run in one job, in which each agent plays each drawn state once for all of them. None
    for any other search."""
    if not solver_named(search.solver).pooled:
        return None
    config = asdict(search.solver_config)
    shared = {key: config[key] for key in ("states", "pushes", "batch_states", "longest")}
    return json.dumps(
        {
            "scenario": search.scenario,
            "world": search.world,
            "world_settings": search.world_settings,
            "reward": search.reward_settings,
            "seed": search.seed,
        }
        | shared,
        sort_keys=True,
    )


def search_groups(searches: dict[str, SearchJob]) -> dict[str, list[str]]:
    """The jobs that run ``searches`` (by their keys): one for each `pool_key` of the searches that share a pool,
    one for each other search, each job's key and its searches' keys."""
    groups: dict[str, list[str]] = {}
    for key, search in searches.items():
        groups.setdefault(pool_key(search) or key, []).append(key)
    return groups


def group_work(searches: list[tuple[ClipJob, SearchJob]]) -> Work:
    """A job's size, in its scheme's steps: a search's budget; for searches that share a pool, the most budget of
    one scaled by the agents the pool plays over the two one search plays (each agent plays each state once)."""
    agents = {agent for _, search in searches for agent in search.agents}
    most = max(search_work(*one).units for one in searches)
    return Work(searches[0][0].scheme.name, most * len(agents) // 2)


def search_pools(searches: list[SearchJob]) -> list[Any]:
    """Each pooled search's pool (`search.solvers.pool.Pool`), shared by the searches with its `pool_key` whose
    agents resolve to the same world settings (an agent may bring its own), each pool playing every agent of its
    searches: the same draws as each search's own."""
    import numpy as np

    from search.solvers.pool import Pool

    keys: list[tuple[str, Any, dict[str, Any]]] = []
    agents: dict[str, list[str]] = {}
    for search in searches:
        domain = domain_for(search.agents, search.scenario, search.world)
        world = domain.search_settings(search.agents, search.world_settings, search.scenario)
        key = json.dumps([pool_key(search), world], sort_keys=True)
        keys.append((key, domain, world))
        agents.setdefault(key, []).extend(search.agents)
    pools = {}
    for search, (key, domain, world) in zip(searches, keys, strict=True):
        if key not in pools:
            config = search.solver_config
            pools[key] = Pool(
                domain,
                list(dict.fromkeys(agents[key])),
                search.scenario,
                world,
                search.reward_settings,
                config.states,
                config.pushes,
                config.batch_states,
                np.random.default_rng(search.seed),
            )
    return [pools[key] for key, _, _ in keys]


def search_group_files(searches: list[SearchJob], workers: int = 1) -> tuple[list[dict[str, str]], float]:
    """The files of searches with one `pool_key` (`run_search`) and the seconds they took, each reading its pool
    (`search_pools`), each batch of states spread over ``workers`` processes where the world has no batched fast
    path (the job stands for searches that would each have had a worker; the files are the same however many)."""
    from search.core.workers import lent

    started = time.perf_counter()
    if pool_key(searches[0]) is None:
        return [run_search(search) for search in searches], time.perf_counter() - started
    with lent(workers):
        files = [run_search(search, pool=pool) for search, pool in zip(searches, search_pools(searches), strict=True)]
    return files, time.perf_counter() - started


def run_searches(
    jobs: list[tuple[ClipJob, SearchJob, dict[str, Any]]], cache: Cache, log: Log, backend: Backend = IN_THIS_PROCESS
) -> None:
    """Run every search the cache cannot supply on ``backend``, those that share a pool (`pool_key`) in one job;
    each result is written and sealed in the cache as soon as its job is complete, so an interrupted build keeps
    the finished ones."""
    todo = {}
    for job, search, inputs in jobs:
        if input_key(inputs) not in todo and not _reusable(job, inputs, cache, log):
            todo[input_key(inputs)] = (job, search, inputs)
    groups = search_groups({key: search for key, (_, search, _) in todo.items()})

    tasks = {
        group: (search_group_files, ([todo[key][1] for key in keys], backend.workers)) for group, keys in groups.items()
    }

    def described(group: str) -> str:
        named = [describe_search(todo[key][0]) for key in groups[group]]
        return named[0] if len(named) == 1 else f"{named[0]} and {len(named) - 1} more sharing its rollouts"

    def work(group: str) -> Work:
        return group_work([todo[key][:2] for key in groups[group]])

    for group, (files, seconds), progress in finished(tasks, backend, described, work):
        for key, found in zip(groups[group], files, strict=True):
            job, _, inputs = todo[key]
            write_outputs(cache.store("search", inputs), found)
            cache.seal("search", inputs)
        log(f"{described(group)}: {seconds:.1f} s {progress}")
