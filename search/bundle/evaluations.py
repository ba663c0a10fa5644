"""The ground truth of a bundle: each agent's evaluation on the study's episodes (`foil eval --json`, with its
per-episode rewards where the world gives them), the pairs shown together that those episodes cannot tell apart
compared on more paired episodes (`search.bundle.truth`), and which agent of a pair is the better one."""

from __future__ import annotations

import json
import time
from typing import Any

from app.visible import World
from search.bundle.searches import ClipJob
from search.bundle.spec import BuildError, BuildSpec
from search.bundle.steps import IN_THIS_PROCESS, Cache, Log, Task, Work, agent_identity, finished
from search.bundle.study import Study
from search.bundle.truth import PairedComparison, compare_pairs, describe_close_pair
from search.core.domain import domain_named
from search.solvers.runner import Backend


def evaluate_agents(
    study: Study, cache: Cache, log: Log, backend: Backend = IN_THIS_PROCESS
) -> dict[str, dict[str, Any]]:
    """Each agent's `foil eval --json` object on the study's episodes (the manifest's ground truth) in the study's
    world settings, with its per-episode rewards where the world gives them (`Domain.evaluate_episodes`)."""
    spec = study.spec
    found = evaluate_runs(study, cache, log, [(agent, spec.eval_episodes) for agent in spec.agents], backend)
    return {agent: found[agent, spec.eval_episodes] for agent in spec.agents}


def evaluate_runs(
    study: Study, cache: Cache, log: Log, runs: list[tuple[str, int]], backend: Backend
) -> dict[tuple[str, int], dict[str, Any]]:
    """Each (agent, episodes)'s evaluation at the study's eval seed, computed once per input on ``backend``."""
    spec = study.spec
    inputs_of: dict[tuple[str, int], dict[str, Any]] = {}
    todo: dict[tuple[str, int], Task] = {}
    for run, (inputs, task) in eval_tasks(study, runs).items():
        inputs_of[run] = inputs
        if cache.valid("eval", inputs, "eval.json"):
            log(f"eval {run_name(spec, *run)}: cached")
        else:
            todo[run] = task
    described = {run: f"eval {run_name(spec, *run)}" for run in todo}
    for run, (result, seconds), progress in finished(
        todo, backend, described.__getitem__, lambda run: evaluation_work(todo[run])
    ):
        folder = cache.store("eval", inputs_of[run])
        (folder / "eval.json").write_text(json.dumps(result, indent=1))
        cache.seal("eval", inputs_of[run])
        log(f"{described[run]}: {in_brief(result, study.shows)} ({seconds:.1f} s) {progress}")
    return {
        run: json.loads((cache.path("eval", inputs) / "eval.json").read_text()) for run, inputs in inputs_of.items()
    }


def in_brief(result: dict[str, Any], world: World) -> str:
    """An evaluation in a few words for the build's log: the mean reward, the success rate where the world's clips
    end in outcomes, the visible score where the world declares one."""
    parts = [f"reward {result['reward_mean']:.2f}"]
    if world.has_outcomes() and "success_rate" in result:
        parts.append(f"success {result['success_rate']:.2f}")
    if "score" in result:
        parts.append(f"{result['score']['name']} {result['score']['mean']:.{result['score'].get('digits', 1)}f}")
    return ", ".join(parts)


def eval_tasks(study: Study, runs: list[tuple[str, int]]) -> dict[tuple[str, int], tuple[dict[str, Any], Task]]:
    """Each (agent, episodes)'s inputs and job (function, arguments), in the study's world settings (the agents'
    own, `Study.world`); in a world whose agents act in their scenario's world, in the first scenario they are
    shown in."""
    spec, domain = study.spec, study.domain
    seed, world = spec.eval_seed, study.world
    found: dict[tuple[str, int], tuple[dict[str, Any], Task]] = {}
    for agent, episodes in runs:
        shown = [name for clip_set in spec.sets if agent in clip_set.agents for name in clip_set.scenarios]
        scenario = domain.eval_scenario(shown)
        inputs = {"agent": agent_identity(agent, domain), "episodes": episodes, "seed": seed, "per_episode": True} | (
            {"world": world} if world else {}
        )
        if scenario is not None:
            inputs["scenario"] = domain.scenario_dict(scenario, world)
        found[agent, episodes] = (inputs, (evaluation_job, (domain.name, agent, episodes, seed, world, scenario)))
    return found


def evaluation_work(task: Task) -> Work:
    """An evaluation's size: its episodes, at its agent's pace."""
    _, (_, agent, episodes, *_) = task
    return Work(agent, episodes)


def run_name(spec: BuildSpec, agent: str, episodes: int) -> str:
    return agent if episodes == spec.eval_episodes else f"{agent} on {episodes} episodes"


def evaluation_job(
    domain: str, agent: str, episodes: int, seed: int, world: dict[str, Any], scenario: str | None
) -> tuple[dict[str, Any], float]:
    """One agent's evaluation and the seconds it took (in a worker process: the domain is found by name)."""
    started = time.perf_counter()
    result = domain_named(domain).evaluate_episodes(agent, episodes, seed, world, scenario) | {"agent": agent}
    return result, time.perf_counter() - started


def close_pairs(
    study: Study,
    pairs: list[tuple[str, str]],
    evaluations: dict[str, dict[str, Any]],
    cache: Cache,
    log: Log,
    backend: Backend = IN_THIS_PROCESS,
) -> dict[tuple[str, str], PairedComparison]:
    """The pairs shown together that the study's own episodes cannot tell apart, each compared on more paired
    episodes until decided or at the cap (`search.bundle.truth`), with a line each (a warning for an undecided
    one, naming agents only). Pairs decided on the study's episodes are left out: their truth is as before."""
    spec = study.spec
    if any("episode_rewards" not in evaluations[agent] for pair in pairs for agent in pair):
        return {}  # a world without per-episode rewards: mean rewards alone

    def rewards(wanted: set[tuple[str, int]]) -> dict[tuple[str, int], list[float]]:
        more = sorted(run for run in wanted if run[1] != spec.eval_episodes)  # the first look's are in hand
        found = evaluate_runs(study, cache, log, more, backend) if more else {}
        found |= {(agent, n): evaluations[agent] for agent, n in wanted if n == spec.eval_episodes}
        return {run: result["episode_rewards"] for run, result in found.items()}

    compared = compare_pairs(pairs, spec.eval_episodes, rewards)
    close = {pair: c for pair, c in compared.items() if c.episodes > spec.eval_episodes or not c.decided}
    for comparison in close.values():
        log(describe_close_pair(comparison))
    return close


def shown_pairs(jobs: list[ClipJob]) -> list[tuple[str, str]]:
    """Every pair of agents some clip shows together, once, in the order of the first clip showing it."""
    pairs: list[tuple[str, str]] = []
    for job in jobs:
        if job.pair not in pairs and job.pair[::-1] not in pairs:
            pairs.append(job.pair)
    return pairs


def without_episodes(evaluation: dict[str, Any]) -> dict[str, Any]:
    """An evaluation as `foil eval --json` prints it, for the manifest: without its per-episode rewards."""
    return {key: value for key, value in evaluation.items() if key != "episode_rewards"}


def better_agent(
    pair: tuple[str, str],
    evaluations: dict[str, dict[str, Any]],
    close: dict[tuple[str, str], PairedComparison] | None = None,
) -> str:
    """The ground truth: the agent with the higher mean test reward (the paper ranks its agents by it); for a close
    pair, over the most paired episodes it was evaluated on. A close pair the truth leaves undecided with no
    difference at all records its first agent: its questions rest on a coin toss, as every undecided pair's do."""
    comparison = (close or {}).get(pair) or (close or {}).get(pair[::-1])
    if comparison is not None:  # the mean paired difference, first minus second
        pair, (first, second) = comparison.agents, (comparison.difference, 0.0)
    else:
        first, second = (evaluations[a]["reward_mean"] for a in pair)
    if first == second and comparison is not None and not comparison.decided:
        return pair[0]  # no difference at all (a control: the same controller twice): any is a coin toss
    if first == second:
        raise BuildError(f"{pair[0]} and {pair[1]} have the same mean reward; no better agent to record")
    return pair[0] if first > second else pair[1]
