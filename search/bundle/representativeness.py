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
    vote; each distribution's pairs measured together on ``backend`` (one job: each agent plays each drawn state
    and each scenario once, `search.solvers.pool`), each scenario and the distribution in the study's world
    settings (`Study.world_settings`)."""
    checks = check_tasks(study)
    todo: dict[str, dict[tuple[str, str], Any]] = {}  # distribution -> its pairs not cached
    for pair, (names, distribution, inputs) in checks.items():
        if not cache.valid("representativeness", inputs, "report.json"):
            todo.setdefault(distribution, {})[pair] = names
    tasks = {
        distribution: check_job(study, distribution, pairs, backend.workers) for distribution, pairs in todo.items()
    }

    def described(distribution: str) -> str:
        return f"representativeness {distribution}: {', '.join(f'{a}-{b}' for a, b in todo[distribution])}"

    for distribution, (found, seconds), progress in finished(
        tasks, backend, described, lambda distribution: check_work(tasks[distribution])
    ):
        for pair, measured in found.items():
            inputs = checks[pair][2]
            folder = cache.store("representativeness", inputs)
            (folder / "report.json").write_text(json.dumps(measured, indent=1))
            cache.seal("representativeness", inputs)
        log(f"{described(distribution)}: {seconds:.1f} s {progress}")
    reports: list[dict[str, Any]] = []
    for pair, (names, distribution, inputs) in checks.items():
        cached = json.loads((cache.path("representativeness", inputs) / "report.json").read_text())
        for name, one in zip(names, cached, strict=True):
            report = {"agents": list(pair), "scenario": name, "distribution": distribution} | {
                key: value for key, value in one.items() if key != "scenario"
            }
            reports.append(report)
            log(describe_representativeness(report))
    return reports


def check_tasks(study: Study) -> dict[tuple[str, str], tuple[list[str], str, dict[str, Any]]]:
    """Each pair shown on a fixed scenario in a pairwise or ranking part, with its scenarios, the distribution
    they are measured against and the check's inputs; none in a world with no distribution of starting states
    where the study names none."""

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
        inputs = {
            "agents": [agent_identity(a, domain) for a in pair],
            "scenarios": [s.to_dict() for s in fixed],
            "distribution": domain.scenario_dict(distribution, drawn_world),
            "states": settings.states,
            "pushes": settings.pushes,
            "seed": settings.seed,
            "reward": clip_reward(study, distribution, drawn_world),
            "check": 4,  # the check's rules (2: ties count half in the percentile; a test decides the warning; 3: the
            # distribution's states weigh in by how plainly they show a difference; 4: every agent is pushed until
            # each one's episode has ended, and each scenario's pushes are its own)
        }
        checks[pair] = (names, distribution, inputs)
    return checks


def check_job(study: Study, distribution: str, pairs: dict[tuple[str, str], list[str]], workers: int = 1) -> Task:
    """The job that checks ``pairs`` (each with its scenarios' names) against ``distribution`` on ``workers``
    processes: every agent's rollouts played once for all of them."""
    domain, world = study.domain, study.world_settings(distribution)
    fixed = {
        pair: [(name, domain.state(name, study.world_settings(name))) for name in names]
        for pair, names in pairs.items()
    }
    reward = clip_reward(study, distribution, world)
    settings = study.spec.representativeness
    return (representativeness_job, (domain.name, fixed, distribution, world, settings, reward, workers))


def check_work(task: Task, states: int | None = None) -> Work:
    """A check's size in simulator steps, its rollouts' most: (``states`` drawn, by default its settings', and its
    scenarios) x (pushes + 1) rollouts of the reward's horizon, for each agent."""
    _, (_, fixed, _, _, settings, reward, _) = task
    agents = {agent for pair in fixed for agent in pair}
    scenarios = {name for named in fixed.values() for name, _ in named}
    drawn = settings.states if states is None else states
    return Work("check", len(agents) * (drawn + len(scenarios)) * (settings.pushes + 1) * reward["horizon"])


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
    fixed: dict[tuple[str, str], list[tuple[str, Any]]],
    distribution: str,
    world: dict[str, Any],
    settings: Representativeness,
    reward: dict[str, Any],
    workers: int = 1,
) -> tuple[dict[tuple[str, str], list[dict[str, Any]]], float]:
    """The representativeness reports of every pair checked against one distribution (each with its fixed
    scenarios: name and state), and the seconds they took (in a worker process: the domain is found by name):
    every agent plays each drawn state and each scenario once (`search.solvers.pool.Pool`), each batch of states
    spread over ``workers`` processes where the world has no batched fast path, and each pair's reports read the
    same whichever pairs are checked beside it and however many workers play them."""
    import numpy as np

    from search.core.contrast import Rollouts
    from search.core.rollout import Tracker
    from search.core.workers import lent
    from search.solvers.pool import Pool
    from search.solvers.representative import RepresentativeConfig, how_representative, roll_out_states

    started, domain = time.perf_counter(), domain_named(domain_name)
    agents = list(dict.fromkeys(agent for pair in fixed for agent in pair))
    config = RepresentativeConfig(states=settings.states, pushes=settings.pushes)
    rng = np.random.default_rng(settings.seed)
    pool = Pool(domain, agents, distribution, world, reward, config.states, config.pushes, config.batch_states, rng)
    horizon, found = reward["horizon"], {}
    with lent(workers):
        for pair, scenarios in fixed.items():
            tracker = Tracker(2**62, 1)  # no budget: every drawn state votes, whatever it costs
            drawn, states, _ = roll_out_states(pool.rollouts(pair, horizon), pool.draw(horizon), config, tracker, 1)
            first, second = (agents.index(agent) for agent in pair)
            own: list[tuple[str, Rollouts]] = [
                (name, pool.fixed(name, state, horizon).pair(first, second)[0]) for name, state in scenarios
            ]
            found[pair] = how_representative(drawn, states, own, config.alpha)
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
