"""What a bundle's build will cost, said before it is spent (`foil bundle --plan`, and the start of every
`foil bundle`): each step's count and, from a few timed steps of the study's world, its expected wall time at the
chosen number of workers.

The timed steps are each step's own jobs made small, in one process as a worker runs them: each agent's evaluation
on a few episodes, each scheme's first search on a small budget, the first pair's check on a few states, each
doubled until it takes a second (or is whole), so the last two give the job's pace and the time it takes besides;
and one clip rendered from a short search's summary. A step's jobs are dealt out to the workers in order as the
build deals them, so its wall time is its last worker's finish. Work the cache already holds is counted, not timed.
"""

from __future__ import annotations

import heapq
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, cast

from search.bundle.build import Prepared
from search.bundle.clips import render_job
from search.bundle.evaluations import eval_tasks, evaluation_job
from search.bundle.representativeness import check_tasks
from search.bundle.searches import search_job_files
from search.bundle.steps import Cache, Task, duration, input_key
from search.clips.render import RenderOptions
from search.core.workers import jobs
from search.solvers.runner import SearchJob
from search.solvers.solver import solver_named

FEWEST_EPISODES = 2  # an evaluation's fewest (an interval needs two)
PROBE_STEPS = 200  # simulator steps of each scheme's first timed search
PROBE_SECONDS = 1.0  # a timed job is doubled until it takes this long


@dataclass(frozen=True)
class Step:
    """One step of a build: what it holds, how many of its jobs the cache already has, and each job's expected
    seconds (those to run)."""

    name: str
    count: str
    cached: int
    seconds: list[float]


def plan_lines(prepared: Prepared, cache: Cache, workers: int) -> list[str]:
    """The build's plan as lines for its log: a line per step with its expected wall time at ``workers``, and
    the whole build's."""
    started = time.perf_counter()
    with jobs(1):  # each job as a worker runs it: in one process
        steps, rates = plan_steps(prepared, cache)
    walls = [makespan(step.seconds, workers) for step in steps]
    measured = ", ".join(f"{solver} {rate:,.0f} steps/s" for solver, rate in rates.items())
    lines = [
        f"plan at --jobs {workers}, timed on this machine in {time.perf_counter() - started:.1f} s"
        + (f" ({measured})" if measured else "")
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


def makespan(seconds: list[float], workers: int) -> float:
    """When the last of jobs taking ``seconds`` finishes, each started in order on the first worker free."""
    free = [0.0] * max(1, min(workers, len(seconds)))
    for job in seconds:
        heapq.heappush(free, heapq.heappop(free) + job)
    return max(free)


def paced(run: Callable[[int], float], start: int, whole: int) -> Callable[[int], float]:
    """A job's expected seconds at any size, from ``run(size)`` (its seconds) at ``start`` doubled until a run
    takes PROBE_SECONDS or the size is ``whole``: the last two runs' pace, and what the last took besides."""
    size = min(start, whole)
    timed = [(size, run(size))]
    while timed[-1][1] < PROBE_SECONDS and size < whole:
        size = min(2 * size, whole)
        timed.append((size, run(size)))
    if len(timed) == 1:  # whole at once, or long at its start: its time scaled
        return lambda wanted: timed[0][1] * wanted / size
    (before, took_before), (last, took) = timed[-2:]
    pace = max(took - took_before, 0.0) / (last - before)
    besides = max(took - pace * last, 0.0)
    return lambda wanted: besides + pace * wanted


def plan_steps(prepared: Prepared, cache: Cache) -> tuple[list[Step], dict[str, float]]:
    """Every step of the build with its jobs' expected seconds, and the simulator steps per second each scheme's
    timed search ran at."""
    study = prepared.study
    spec, domain = study.spec, study.domain
    runs = eval_tasks(study, [(agent, spec.eval_episodes) for agent in spec.agents])
    todo = [arguments for inputs, (_, arguments) in runs.values() if not cache.valid("eval", inputs, "eval.json")]
    evaluations = Step(
        "evaluations",
        f"{len(spec.agents)} agents x {spec.eval_episodes} episodes",
        len(runs) - len(todo),
        [_evaluation(arguments)(arguments[2]) for arguments in todo],
    )

    searches: dict[str, tuple[str, SearchJob, dict[str, Any]]] = {}  # one per input: clips may share a search
    for job, search, inputs in zip(prepared.jobs, prepared.searches, prepared.inputs, strict=True):
        searches.setdefault(input_key(inputs), (job.scheme.name, search, inputs))
    wanted = [
        (scheme, search)
        for scheme, search, inputs in searches.values()
        if not cache.valid("search", inputs, "summary-001.json")
    ]
    timed: dict[str, tuple[Callable[[int], float], float, bytes | None]] = {}  # scheme: pace, steps/s, a summary
    for scheme, search in wanted:
        if scheme not in timed:
            timed[scheme] = _search(search)
    budgets = sorted({search.budget for _, search, _ in searches.values()})
    search_step = Step(
        "searches",
        f"{len(searches)} of {budgets[0]:,}" + (f" to {budgets[-1]:,}" if len(budgets) > 1 else "") + " steps",
        len(searches) - len(wanted),
        [timed[scheme][0](search.budget) for scheme, search in wanted],
    )

    checks = check_tasks(study)
    unchecked = [
        task for _, _, inputs, task in checks.values() if not cache.valid("representativeness", inputs, "report.json")
    ]
    settings = spec.representativeness
    check_step = Step(
        "representativeness checks",
        f"{len(checks)} pair{'' if len(checks) == 1 else 's'} x ({settings.states} states + their scenarios) x "
        f"{settings.pushes} pushes",
        len(checks) - len(unchecked),
        [_check(unchecked[0])(settings.states)] * len(unchecked) if unchecked else [],
    )

    files = sum(2 if solver_named(job.scheme.solver).reels else 1 for job in prepared.jobs)
    found = next((summary for *_, summary in timed.values() if summary is not None), None)
    each = _render_seconds(domain.name, found, spec.render) if found is not None else 0.0
    clips = Step(
        "clips",
        f"{files} files to render" + ("" if wanted else ", those whose summaries are unchanged reused"),
        0,
        [each] * files if wanted else [],
    )
    rates = {scheme: rate for scheme, (_, rate, _) in timed.items()}
    return [evaluations, search_step, check_step, clips], rates


def _evaluation(arguments: tuple[Any, ...]) -> Callable[[int], float]:
    """An agent's evaluation's pace, on a few of its episodes."""
    domain, agent, episodes, *rest = arguments
    return paced(lambda size: evaluation_job(domain, agent, size, *rest)[1], FEWEST_EPISODES, episodes)


def _search(search: SearchJob) -> tuple[Callable[[int], float], float, bytes | None]:
    """A scheme's pace, from its first search on small budgets (from the fewest steps its solver accepts: one
    that must finish whole rollouts refuses too few), the simulator steps/s of its largest, and the best summary
    found, to time a clip's rendering by."""
    found: dict[str, str] = {}
    took: dict[int, float] = {}

    def run(budget: int) -> float:
        if budget not in took:
            files, took[budget] = search_job_files(replace(search, budget=budget))
            found.update(files)
        return took[budget]

    start = min(search.budget, PROBE_STEPS)
    while True:
        try:
            run(start)
            break
        except ValueError:
            if start == search.budget:
                raise
            start = min(search.budget, 2 * start)
    pace = paced(run, start, search.budget)
    rate = json.loads(found["run.json"])["steps_per_s"]  # the last run's, the largest
    return pace, rate, found["summary-001.json"].encode() if "summary-001.json" in found else None


def _check(task: Task) -> Callable[[int], float]:
    """A pair's check's pace, on a few of its starting states."""
    function, (domain, pair, fixed, distribution, world, settings, reward) = task

    def run(states: int) -> float:
        fewer = settings.model_copy(update={"states": states})
        return cast(float, function(domain, pair, fixed, distribution, world, fewer, reward)[1])

    return paced(run, 1, settings.states)


def _render_seconds(domain: str, summary: bytes, options: RenderOptions) -> float:
    """The seconds one clip takes to render, timed on a short search's summary."""
    started = time.perf_counter()
    render_job(domain, [("summary.json", summary)], "plan.mp4", [1, 2], options)
    return time.perf_counter() - started
