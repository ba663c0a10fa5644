"""What a bundle's build will cost, said before it is spent (`foil bundle --plan`): each step's count and its
expected wall time at the chosen number of workers, from rates measured on a few small jobs of the study's world.

Each job is sized in its step's units as the build's progress sizes it (`search.bundle.steps.Work`: a search's
budget, an evaluation's episodes, a check's rollout steps, a clip's file), and its seconds follow its group's
rate: each scheme's simulator steps per second, each agent's seconds per episode, the check's seconds per rollout
step, one clip's rendering. A rate is measured on its group's first job made small, in one process as a worker
runs it: run once to pay what a worker pays once (imports, an agent's loading, a compiled kernel), then timed,
doubled until a run takes PROBE_SECONDS (at least twice, or whole), so the last two give the seconds per unit and
the time the job takes besides. A step's jobs are dealt out to the workers in order as the build deals them, so
its wall time is its last worker's finish. Work the cache already holds is counted, not timed.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, cast

from search.bundle.build import Prepared
from search.bundle.clips import render_job
from search.bundle.evaluations import eval_tasks, evaluation_job, evaluation_work
from search.bundle.representativeness import check_tasks, check_work
from search.bundle.searches import search_job_files, search_work
from search.bundle.steps import Cache, Rate, Task, Work, duration, expected, input_key, makespan
from search.clips.render import RenderOptions
from search.core.workers import jobs
from search.solvers.runner import SearchJob
from search.solvers.solver import solver_named

FEWEST_EPISODES = 2  # an evaluation's fewest (an interval needs two)
PROBE_STEPS = 200  # simulator steps of each scheme's first timed search
PROBE_SECONDS = 0.5  # a timed job is doubled until it takes this long

Run = Callable[[int], tuple[float, int]]  # a job made small: its size -> (seconds, the size it reached)


@dataclass(frozen=True)
class Step:
    """One step of a build: what it holds, how many of its jobs the cache already has, each job to run's size,
    and how to measure each of their groups' rate (run once `plan_lines` asks)."""

    name: str
    count: str
    cached: int
    work: list[Work]
    probes: dict[str, Callable[[], Rate]] = field(default_factory=dict)


def plan_lines(prepared: Prepared, cache: Cache, workers: int) -> list[str]:
    """The build's plan as lines for its log: a line per step with its expected wall time at ``workers``, and
    the whole build's."""
    started = time.perf_counter()
    steps = plan_steps(prepared, cache)
    with jobs(1):  # each job as a worker runs it: in one process
        rates = [{group: probe() for group, probe in step.probes.items()} for step in steps]
    walls = [step_seconds(step, rate, workers) for step, rate in zip(steps, rates, strict=True)]
    paces = [f"{scheme} {1 / rate.per_unit:,.0f} steps/s" for scheme, rate in rates[1].items() if rate.per_unit]
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


def step_seconds(step: Step, rates: dict[str, Rate], workers: int) -> float:
    """A step's expected wall time: its jobs at their groups' ``rates``, dealt in order to ``workers``."""
    return makespan([expected(work, rates) for work in step.work], workers)


def measured(run: Run, start: int, whole: int, units: Callable[[int], float] = float) -> Rate:
    """A job's rate from ``run`` at ``start``, once to warm up and then timed, doubled until a run takes
    PROBE_SECONDS (at least twice) or is whole: the last two runs' seconds per unit (``units`` of the size each
    reached) and what the last took besides. A job that stops by itself short of its size (a search that found
    what it looks for) reaches as far at a larger one, and takes as long."""
    run(start)
    size, timed = start, []
    while True:
        took, reached = run(size)
        timed.append((units(reached), took))
        if size == whole or (len(timed) > 1 and (took >= PROBE_SECONDS or timed[-1][0] == timed[-2][0])):
            break
        size = min(2 * size, whole)
    if len(timed) == 1:  # whole at its start
        return Rate(took / max(timed[0][0], 1.0))
    (before, took_before), (last, took) = timed[-2:]
    if last == before:  # it stopped by itself
        return Rate(0.0, took)
    per_unit = max(took - took_before, 0.0) / (last - before)
    return Rate(per_unit, max(took - per_unit * last, 0.0))


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
        {evaluation_work(task).group: _evaluation(task) for task in todo},
    )

    searches: dict[str, tuple[Work, SearchJob, dict[str, Any]]] = {}  # one per input: clips may share a search
    for job, search, inputs in zip(prepared.jobs, prepared.searches, prepared.inputs, strict=True):
        searches.setdefault(input_key(inputs), (search_work(job, search), search, inputs))
    wanted = [
        (work, search)
        for work, search, inputs in searches.values()
        if not cache.valid("search", inputs, "summary-001.json")
    ]
    found: dict[str, bytes] = {}  # a summary a timed search found, to time a clip's rendering by
    probes: dict[str, Callable[[], Rate]] = {}
    for work, search in wanted:
        if work.group not in probes:  # a scheme's first search
            probes[work.group] = _search(search, found)
    budgets = sorted({search.budget for _, search, _ in searches.values()})
    search_step = Step(
        "searches",
        f"{len(searches)} of {budgets[0]:,}" + (f" to {budgets[-1]:,}" if len(budgets) > 1 else "") + " steps",
        len(searches) - len(wanted),
        [work for work, _ in wanted],
        probes,
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
        [check_work(task) for task in unchecked],
        {"": lambda: _check(unchecked[0])} if unchecked else {},
    )

    files = sum(2 if solver_named(job.scheme.solver).reels else 1 for job in prepared.jobs)
    clips = Step(
        "clips",
        f"{files} files to render" + ("" if wanted else ", those whose summaries are unchanged reused"),
        0,
        [Work("", 1)] * files if wanted else [],
        {"": lambda: _render(domain.name, found.get("summary"), spec.render)} if wanted else {},
    )
    return [evaluations, search_step, check_step, clips]


def _evaluation(task: Task) -> Callable[[], Rate]:
    """An agent's evaluation's rate, on a few of its episodes."""
    domain, agent, episodes, *rest = task[1]

    def run(size: int) -> tuple[float, int]:
        return evaluation_job(domain, agent, size, *rest)[1], size

    return lambda: measured(run, min(FEWEST_EPISODES, episodes), episodes)


def _search(search: SearchJob, found: dict[str, bytes]) -> Callable[[], Rate]:
    """A scheme's rate in seconds per simulator step of its budget, from its first search on small budgets (from
    the fewest steps its solver accepts: one that must finish whole rollouts refuses too few); the best summary
    found is kept in ``found``, to time a clip's rendering by."""

    def run(budget: int) -> tuple[float, int]:
        files, took = search_job_files(replace(search, budget=budget))
        if "summary-001.json" in files:
            found.setdefault("summary", files["summary-001.json"].encode())
        return took, json.loads(files["run.json"])["solver"]["budget_used"]  # one may stop short of its budget

    def rate() -> Rate:
        start = min(search.budget, PROBE_STEPS)
        while True:
            try:
                return measured(run, start, search.budget)
            except ValueError:
                if start == search.budget:
                    raise
                start = min(search.budget, 2 * start)

    return rate


def _check(task: Task) -> Rate:
    """A pair's check's rate in seconds per rollout step, on a few of its starting states."""
    function, (domain, pair, fixed, distribution, world, settings, reward) = task

    def run(states: int) -> tuple[float, int]:
        fewer = settings.model_copy(update={"states": states})
        return cast(float, function(domain, pair, fixed, distribution, world, fewer, reward)[1]), states

    return measured(run, 1, settings.states, lambda states: check_work(task, states).units)


def _render(domain: str, summary: bytes | None, options: RenderOptions) -> Rate:
    """The seconds one clip takes to render, timed on a short search's summary (none where no search found one)."""
    if summary is None:
        return Rate(0.0)
    return Rate(render_job(domain, [("summary.json", summary)], "plan.mp4", [1, 2], options)[1])
