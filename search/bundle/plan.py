"""What a bundle's build will cost, said before it is spent (`foil bundle --plan`): each step's count and its
expected wall time at the chosen number of workers, from rates measured on a few small jobs of the study's world.

Each job is sized in its step's units as the build's progress sizes it (`search.bundle.steps.Work`: a search's
budget, an evaluation's episodes, a check's rollout steps, a clip's file), and its seconds follow its group's
rate: each scheme's simulator steps per second, each agent's seconds per episode, the check's seconds per rollout
step, one clip's rendering. A rate is measured on its group's first job made small, run as the build runs it
(`_where_jobs_run`: ``workers`` at once in worker processes): once to pay what a worker pays once (imports, a
compiled kernel), then at doubling sizes (`measured`), so the first and last runs give the seconds per unit and
the time the job takes besides (a search's setup and choice of clips, an evaluation's batch). A step's jobs are
dealt out to the workers in order as the build deals them, so its wall time is its last worker's finish. Work
the cache already holds is counted, not timed.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple, cast

from search.bundle.build import Prepared
from search.bundle.clips import render_job
from search.bundle.evaluations import eval_tasks, evaluation_job, evaluation_work
from search.bundle.representativeness import check_job, check_tasks, check_work
from search.bundle.searches import ClipJob, group_work, search_groups, search_job_files
from search.bundle.steps import Cache, Rate, Task, Work, duration, expected, input_key, makespan
from search.clips.render import RenderOptions
from search.core.workers import jobs
from search.solvers.runner import SearchJob, process_pool
from search.solvers.solver import solver_named

FEWEST_EPISODES = 2  # an evaluation's fewest (an interval needs two)
PROBE_STEPS = 100  # simulator steps of each scheme's first timed search (more where its solver asks for more)
PROBE_TOTAL = 4.0  # a timed job is doubled until its runs took this long together (or it is whole)

Run = Callable[[int], "Timed"]  # a job made small, run at a size
Call = Callable[..., Any]  # call(function, *arguments): a job's function run where the build runs it


class Timed(NamedTuple):
    """A job made small, run: its seconds, the size it reached (a search may stop short of its budget), and of its
    seconds those its size does not change (a search's setup and choice of clips, as its record says)."""

    seconds: float
    reached: int
    fixed: float = 0.0


@dataclass(frozen=True)
class Step:
    """One step of a build: what it holds, how many of its jobs the cache already has, each job to run's size,
    and how to measure each of their groups' rate (run once `plan_lines` asks)."""

    name: str
    count: str
    cached: int
    work: list[Work]
    probes: dict[str, Callable[[Call], Rate]] = field(default_factory=dict)


def plan_lines(prepared: Prepared, cache: Cache, workers: int) -> list[str]:
    """The build's plan as lines for its log: a line per step with its expected wall time at ``workers``, and
    the whole build's."""
    started = time.perf_counter()
    steps = plan_steps(prepared, cache)
    with jobs(1), _where_jobs_run(workers) as call:
        rates = [{group: probe(call) for group, probe in step.probes.items()} for step in steps]
    walls = [step_seconds(step, rate, workers) for step, rate in zip(steps, rates, strict=True)]
    searches: dict[str, Work] = {}  # each scheme's first search, at its rate
    for work in steps[1].work:
        searches.setdefault(work.group, work)
    paces = [f"{scheme} {work.units / expected(work, rates[1]):,.0f} steps/s" for scheme, work in searches.items()]
    lines = [
        f"plan at --jobs {workers}, timed on this machine in {time.perf_counter() - started:.1f} s"
        + (f" ({', '.join(paces)})" if paces else "")
        + ":"
    ]
    for step, wall in zip(steps, walls, strict=True):
        held = f", {step.cached} cached" if step.cached else ""
        lines.append(f"  {step.name}: {step.count}{held}: about {duration(wall)}")
    lines.append(
        f"  expected wall time: about {duration(sum(walls))} (more where the evaluation cannot tell a pair apart "
        "and evaluates it on more episodes)"
    )
    return lines


@contextmanager
def _where_jobs_run(workers: int) -> Iterator[Call]:
    """Where and how the build runs its jobs, to time them so: in this process at one worker, else ``workers`` at
    once in worker processes of one core's threads, their seconds' mean (this process's libraries may use every
    core's threads, which under load wait on each other far longer than one does alone; jobs run at once share
    the cores, and a clip's encoder the threads it would use alone). A job returns (result, seconds)."""
    if workers == 1:
        yield lambda function, *arguments: function(*arguments)
        return

    def at_once(function: Callable[..., Any], *arguments: Any) -> tuple[Any, float]:
        results = [future.result() for future in [pool.submit(function, *arguments) for _ in range(workers)]]
        return results[0][0], sum(seconds for _, seconds in results) / workers

    with process_pool(workers) as pool:
        yield at_once


def step_seconds(step: Step, rates: dict[str, Rate], workers: int) -> float:
    """A step's expected wall time: its jobs at their groups' ``rates``, dealt in order to ``workers``, each
    worker's first paying the step's warm-up."""
    seconds = [expected(work, rates) for work in step.work]
    warm_up = max((rate.warm_up for rate in rates.values()), default=0.0)
    return makespan(seconds, workers, [warm_up] * min(workers, len(seconds)))


def measured(run: Run, start: int, whole: int, units: Callable[[int], float] = float, cold: bool = True) -> Rate:
    """A job's rate from ``run``: once at ``start`` to warm up where the workers are ``cold`` (its step's first
    job), then timed from ``start`` at doubling sizes (eight times the size, at most whole, where the runs so far
    say that may take no more than twice what they took or PROBE_TOTAL: `hoped`), until two or more have taken
    PROBE_TOTAL together or one is whole (`fitted`, each run at ``units`` of its size), with what the cold run
    took more than the same run warm. A job that reaches well short of its size may have stopped by itself (a
    search that found what it looks for): a larger run tells, and if it reaches no further, the job takes as long
    at any size."""
    first, size = run(start) if cold else None, start
    timed = [(units(size), run(size))]
    warm_up = max(first.seconds - timed[0][1].seconds, 0.0) if first else 0.0
    while size < whole:
        spent, short = sum(one.seconds for _, one in timed), timed[-1][1].reached < 0.75 * size
        if len(timed) > 1 and spent >= PROBE_TOTAL and not short:
            break
        leap = min(8 * size, whole)
        size = leap if hoped(timed, units(leap)) <= max(PROBE_TOTAL, 2 * spent) else min(2 * size, whole)
        timed.append((units(size), run(size)))
        if timed[-1][1].reached <= timed[-2][1].reached:  # it stopped by itself
            return Rate(0.0, timed[-1][1].seconds, warm_up)
    return fitted(timed, warm_up)


def hoped(timed: list[tuple[float, Timed]], units: float) -> float:
    """A hopeful guess at what a job of ``units`` takes, from runs at growing sizes (units, run): the last run's
    seconds grown as the last two grew, by the same power of the size (a batched world's jobs grow more slowly
    than their size; a lone run: in proportion)."""
    at, last = timed[-1]
    if len(timed) == 1:
        return last.seconds * units / max(at, 1.0)
    at_before, before = timed[-2]
    grew = math.log(max(last.seconds, 1e-9) / max(before.seconds, 1e-9)) / math.log(at / at_before)
    return last.seconds * math.pow(units / at, min(max(grew, 0.0), 1.0))


def fitted(timed: list[tuple[float, Timed]], warm_up: float) -> Rate:
    """The rate of a job timed at growing sizes (units, run): the seconds per unit between the last two runs (a
    batched world's jobs grow more slowly than their size, so the largest say best how the rest grows; one run
    alone: its seconds per unit), and what the last took besides."""
    at, last = timed[-1]
    following = last.seconds - last.fixed
    if len(timed) == 1:
        return Rate(following / max(at, 1.0), last.fixed, warm_up)
    at_before, before = timed[-2]
    per_unit = max(following - (before.seconds - before.fixed), 0.0) / (at - at_before)
    return Rate(per_unit, max(following - per_unit * at, 0.0) + last.fixed, warm_up)


def plan_steps(prepared: Prepared, cache: Cache) -> list[Step]:
    """Every step of the build with the size of each job to run, and a probe of each of their groups."""
    study = prepared.study
    spec, domain = study.spec, study.domain
    runs = eval_tasks(study, [(agent, spec.eval_episodes) for agent in spec.agents])
    todo = [task for inputs, task in runs.values() if not cache.valid("eval", inputs, "eval.json")]
    evaluations = Step(
        "evaluations",
        f"{len(spec.agents)} agents x {spec.eval_episodes} episodes",
        len(runs) - len(todo),
        [evaluation_work(task) for task in todo],
        {evaluation_work(task).group: _evaluation(task, cold=n == 0) for n, task in enumerate(todo)},
    )

    searches: dict[str, tuple[ClipJob, SearchJob, dict[str, Any]]] = {}  # one per input: clips may share a search
    for job, search, inputs in zip(prepared.jobs, prepared.searches, prepared.inputs, strict=True):
        searches.setdefault(input_key(inputs), (job, search, inputs))
    wanted = {
        key: (job, search)
        for key, (job, search, inputs) in searches.items()
        if not cache.valid("search", inputs, "summary-001.json")
    }
    groups = search_groups({key: search for key, (_, search) in wanted.items()})
    found: dict[str, bytes] = {}  # a summary a timed search found, to time a clip's rendering by
    probes: dict[str, Callable[[Call], Rate]] = {}
    for job, search in wanted.values():
        if job.scheme.name not in probes:  # a scheme's first search
            probes[job.scheme.name] = _search(search, found, cold=not probes)
    budgets = sorted({search.budget for _, search, _ in searches.values()})
    search_step = Step(
        "searches",
        f"{len(searches)} of {budgets[0]:,}" + (f" to {budgets[-1]:,}" if len(budgets) > 1 else "") + " steps",
        len(searches) - len(wanted),
        [group_work([wanted[key] for key in keys]) for keys in groups.values()],
        probes,
    )

    checks = check_tasks(study)
    pending: dict[str, dict[tuple[str, str], list[str]]] = {}  # distribution -> its pairs not cached
    for pair, (names, distribution, inputs) in checks.items():
        if not cache.valid("representativeness", inputs, "report.json"):
            pending.setdefault(distribution, {})[pair] = names
    unchecked = [check_job(study, distribution, pairs) for distribution, pairs in pending.items()]
    settings = spec.representativeness
    check_step = Step(
        "representativeness checks",
        f"{len(checks)} pair{'' if len(checks) == 1 else 's'} x ({settings.states} states + their scenarios) x "
        f"{settings.pushes} pushes",
        len(checks) - sum(len(pairs) for pairs in pending.values()),
        [check_work(task) for task in unchecked],
        {"check": lambda call: _check(unchecked[0], call)} if unchecked else {},
    )

    files = sum(2 if solver_named(job.scheme.solver).reels else 1 for job in prepared.jobs)
    clips = Step(
        "clips",
        f"{files} files to render" + ("" if wanted else ", those whose summaries are unchanged reused"),
        0,
        [Work("clip", 1)] * files if wanted else [],
        {"clip": lambda call: _render(domain.name, found.get("summary"), spec.render, call)} if wanted else {},
    )
    return [evaluations, search_step, check_step, clips]


def _evaluation(task: Task, cold: bool) -> Callable[[Call], Rate]:
    """An agent's evaluation's rate, on a few of its episodes."""
    domain, agent, episodes, *rest = task[1]

    def rate(call: Call) -> Rate:
        def run(size: int) -> Timed:
            return Timed(call(evaluation_job, domain, agent, size, *rest)[1], size)

        return measured(run, min(FEWEST_EPISODES, episodes), episodes, cold=cold)

    return rate


def _search(search: SearchJob, found: dict[str, bytes], cold: bool) -> Callable[[Call], Rate]:
    """A scheme's rate in seconds per simulator step of its budget, from its first search on small budgets (from
    the fewest steps its solver accepts: one that must finish whole rollouts refuses too few); the best summary
    found is kept in ``found``, to time a clip's rendering by."""

    def rate(call: Call) -> Rate:
        def run(budget: int) -> Timed:
            files, took = call(search_job_files, replace(search, budget=budget))
            if "summary-001.json" in files:
                found.setdefault("summary", files["summary-001.json"].encode())
            record = json.loads(files["run.json"])
            return Timed(took, record["solver"]["budget_used"], max(took - record["search_wall_s"], 0.0))

        start = min(search.budget, PROBE_STEPS)
        while True:
            try:
                return measured(run, start, search.budget, cold=cold)
            except ValueError:
                if start == search.budget:
                    raise
                start = min(search.budget, 2 * start)

    return rate


def _check(task: Task, call: Call) -> Rate:
    """A distribution's check's rate in seconds per rollout step, on a few of its starting states."""
    function, (domain, fixed, distribution, world, settings, reward, workers) = task

    def run(states: int) -> Timed:
        fewer = settings.model_copy(update={"states": states})
        found = call(function, domain, fixed, distribution, world, fewer, reward, workers)
        return Timed(cast(float, found[1]), states)

    return measured(run, 1, settings.states, lambda states: check_work(task, states).units)


def _render(domain: str, summary: bytes | None, options: RenderOptions, call: Call) -> Rate:
    """The seconds one clip takes to render, timed on a short search's summary (none where no search found one)."""
    if summary is None:
        return Rate(0.0)
    return Rate(call(render_job, domain, [("summary.json", summary)], "plan.mp4", [1, 2], options)[1])
