"""The representativeness check of a study's fixed scenarios: for every pair shown on one in a pairwise or ranking
part, how often each agent looks better there under nominal pushes, against the vote of the task's distribution
of starting states (`[build.representativeness]`), with a warning line for a scenario whose clips tend to show what
most starting states do not."""

from __future__ import annotations

import itertools
import json
import time
from typing import Any

from search.bundle.spec import Representativeness
from search.bundle.steps import IN_THIS_PROCESS, Cache, Log, Task, Work, agent_identity, finished
from search.bundle.study import Study
from search.core.domain import domain_named
from search.solvers.runner import Backend


def representativeness(
    study: Study, cache: Cache, log: Log, backend: Backend = IN_THIS_PROCESS
) -> list[dict[str, Any]]:
    """For every pair shown on a fixed scenario in a pairwise or ranking part: how often each agent looks better
    there under nominal pushes, against the vote of the task's distribution (`[build.representativeness]`, by
    default the world's own), with a warning line when the scenario's majority disagrees with the distribution's
    vote; pairs measured on ``backend``, each scenario and the distribution in the study's world settings
    (`Study.world_settings`)."""
    checks = check_tasks(study)
    todo = {
        pair: task
        for pair, (_, _, inputs, task) in checks.items()
        if not cache.valid("representativeness", inputs, "report.json")
    }
    described = {pair: f"representativeness {pair[0]}-{pair[1]}" for pair in todo}
    for pair, (found, seconds), progress in finished(
        todo, backend, described.__getitem__, lambda pair: check_work(todo[pair])
    ):
        folder = cache.store("representativeness", checks[pair][2])
        (folder / "report.json").write_text(json.dumps(found, indent=1))
        cache.seal("representativeness", checks[pair][2])
        log(f"{described[pair]}: {seconds:.1f} s {progress}")
    reports: list[dict[str, Any]] = []
    for pair, (names, distribution, inputs, _) in checks.items():
        found = json.loads((cache.path("representativeness", inputs) / "report.json").read_text())
        for name, one in zip(names, found, strict=True):
            report = {"agents": list(pair), "scenario": name, "distribution": distribution} | {
                key: value for key, value in one.items() if key != "scenario"
            }
            reports.append(report)
            log(describe_representativeness(report))
    return reports


def check_tasks(study: Study) -> dict[tuple[str, str], tuple[list[str], str, dict[str, Any], Task]]:
    """Each pair shown on a fixed scenario in a pairwise or ranking part, with its scenarios, the distribution
    they are measured against, the check's inputs and its job (function, arguments); none in a world with no
    distribution of starting states where the study names none."""

    spec, domain = study.spec, study.domain
    settings = spec.representativeness
    scenarios_of: dict[tuple[str, str], list[str]] = {}
    for clip_set in spec.sets:
        if {"pairwise", "ranking"} & set(clip_set.parts):
            for pair, name in itertools.product(clip_set.pairs, clip_set.scenarios):
                if not domain.is_distribution(name):
                    scenarios_of.setdefault(pair, []).append(name)
    checks = {}
    for pair, names in scenarios_of.items():
        distribution = settings.distribution or domain.default_distribution
        if distribution is None:
            continue  # a world with no distribution of starting states, and none named in the study
        names = list(dict.fromkeys(names))
        fixed = [domain.state(name, study.world_settings(name)) for name in names]
        drawn_world = study.world_settings(distribution)
        reward = clip_reward(study, distribution, drawn_world)
        inputs = {
            "agents": [agent_identity(a, domain) for a in pair],
            "scenarios": [s.to_dict() for s in fixed],
            "distribution": domain.scenario_dict(distribution, drawn_world),
            "states": settings.states,
            "pushes": settings.pushes,
            "seed": settings.seed,
            "reward": reward,
            "check": 3,  # the check's rules (2: ties count half in the percentile; a test decides the warning; 3: the
            # distribution's states weigh in by how plainly they show a difference)
        }
        task = (representativeness_job, (domain.name, pair, fixed, distribution, drawn_world, settings, reward))
        checks[pair] = (names, distribution, inputs, task)
    return checks


def check_work(task: Task, states: int | None = None) -> Work:
    """A check's size in simulator steps, its rollouts' most: (``states`` drawn, by default its settings', and its
    scenarios) x (pushes + 1) rollouts of the reward's horizon."""
    _, (_, _, fixed, _, _, settings, reward) = task
    drawn = settings.states if states is None else states
    return Work("check", (drawn + len(fixed)) * (settings.pushes + 1) * reward["horizon"])


def clip_reward(study: Study, distribution: str, world: dict[str, Any]) -> dict[str, Any]:
    """The divergence reward's settings the check's rollouts end by: the study's clip length where
    `[build.budget] clip_seconds` holds every scheme to one, else the reward's default length, in the
    distribution's steps (so a clip the check scores is as long as a clip the study shows)."""
    from search.core.settings import in_steps
    from search.solvers.reward import RewardConfig

    given = {} if study.spec.clip_seconds is None else {"horizon": study.spec.clip_seconds}
    steps = in_steps(RewardConfig, given, study.domain.step_seconds(distribution, world), defaults=True)
    return RewardConfig(**steps).to_dict()


def representativeness_job(
    domain_name: str,
    pair: tuple[str, str],
    fixed: list[Any],
    distribution: str,
    world: dict[str, Any],
    settings: Representativeness,
    reward: dict[str, Any],
) -> tuple[list[dict[str, Any]], float]:
    """One pair's representativeness reports and the seconds they took (in a worker process: the domain is
    found by name)."""
    import numpy as np

    from search.solvers.representative import RepresentativeConfig, how_representative

    started, domain = time.perf_counter(), domain_named(domain_name)
    rng = np.random.default_rng(settings.seed)
    drawn = domain.draw_states(distribution, world, rng, settings.states)
    found = how_representative(
        lambda states, pushes, rng, tracker: domain.roll_out(pair, states, reward, pushes, rng, tracker),
        fixed,
        drawn,
        RepresentativeConfig(states=settings.states, pushes=settings.pushes),
        rng,
    )
    return found, time.perf_counter() - started


def describe_representativeness(report: dict[str, Any]) -> str:
    """One line on a fixed scenario against the distribution, a warning when their majorities disagree; a weak
    distribution vote (its test not below alpha) is called weak, since it cannot say which agent most states
    show as better."""
    first, second = report["agents"]
    vote = report["distribution_vote"]
    voted = {1: first, -1: second, 0: "neither"}[vote["direction"]]
    p = vote["p"]  # one look
    line = (
        f"{report['scenario']}, {first} vs {second}: {first} looks better in {report['first_looks_better']:.0%} "
        f"of {report['rollouts']} nominal rollouts, {second} in {report['second_looks_better']:.0%}; "
        f"{report['distribution']}'s {vote['states']} states vote {voted} ({vote['for_first']} for {first}, "
        f"{vote['for_second']} for {second}, weighed by how plainly), p {'< 0.001' if p < 0.001 else f'= {p:.2g}'}"
    )
    if report["percentile"] is not None:
        line += (
            f"; it agrees with that vote as often as or more often than {report['percentile']:.0f}% of the "
            f"distribution's states do (percentile {report['percentile']:.0f}; near 0: unusual for the pair)"
        )
    weak = (
        ""
        if vote["decided"]
        else f"; a weak vote (p not below {vote['alpha']}): too few or too evenly split states to say which agent "
        f"most starting states show as better"
    )
    if report["disagrees"] and not report["decided"]:
        agreeing = f"binomial test p = {report['agreeing_p']:.2g}"
        return (
            f"representativeness {line}: undecided, its {report['rollouts']} rollouts cannot tell whether it shows "
            f"less than the vote ({agreeing}); raise [build.representativeness] pushes to decide it{weak}"
        )
    if report["disagrees"] and report["majority"] == 0:
        return (
            f"warning: unrepresentative scenario {line}: its clips tend to show no difference where most "
            f"starting states show one{weak}"
        )
    if report["disagrees"]:
        return (
            f"warning: unrepresentative scenario {line}: its clips tend to show the other agent as better than "
            f"most starting states do{weak}"
        )
    return f"representativeness {line}{weak}"
