"""What a study's representative clips and ground truth will say, known before the build (`foil bundle --pilot`).

For each pair the representative scheme shows, the pilot votes as the build's search will: the same drawn states,
pushes and budget at the study's clip length, so a vote it calls weak the build's will be too (its replays and
clips are left out). Where that vote is weak, it votes again at each longer length the world allows (twice the
study's, and so on up to an episode), each on the scheme's whole budget, and says which length decides it and the
`longest` setting that lets the search choose it; where none does, roughly how many states would, from the spread
of the states' weights. For each pair it also compares the two agents on a few paired test episodes
(`PILOT_EPISODES`), as the build's ground truth does on the study's episodes and more: a pair those cannot tell
apart may rest on a coin toss in the study. It costs a search's rollouts per pair and length, a few test episodes
per agent: seconds to minutes, against the build's evaluations, searches, checks and clips."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from scipy.stats import norm

from search.bundle.build import Prepared
from search.bundle.evaluations import evaluate_runs
from search.bundle.searches import search_pools
from search.bundle.steps import Cache
from search.bundle.truth import paired_comparison
from search.core.contrast import ALPHA, describe_vote
from search.core.domain import domain_for
from search.core.rollout import Tracker
from search.solvers.pool import Pool
from search.solvers.representative import RepresentativeConfig, Tried, clip_lengths, vote_lengths
from search.solvers.reward import RewardConfig
from search.solvers.runner import Backend, SearchJob

PILOT_EPISODES = 20  # paired test episodes per pair (at most the study's)
POWER = 0.8  # the chance of deciding that "about N states" aims at


def pilot_lines(prepared: Prepared, cache: Cache, backend: Backend) -> Iterator[str]:
    """The pilot's lines, a pair at a time: each representative search's vote at the study's length (and longer
    where it is weak), then each shown pair's ground truth on a few paired episodes."""
    searches = {
        (search.agents, search.scenario, search.seed, search.budget): search
        for search in prepared.searches
        if search.solver == "representative"
    }
    if not searches:
        yield "pilot: no representative scheme to vote; ground truth only"
    for search, pool in zip(searches.values(), search_pools(list(searches.values())), strict=True):
        yield from vote_lines(search, pool)
    yield from truth_lines(prepared, cache, backend)


def vote_lines(search: SearchJob, pool: Pool) -> Iterator[str]:
    """One search's votes as it will take them (read from ``pool``), and where they are weak, what would decide
    them: the longest clip (up to an episode) with which the search's own votes decide, or roughly how many states
    would."""
    domain = domain_for(search.agents, search.scenario, search.world)
    world = domain.search_settings(search.agents, search.world_settings, search.scenario)
    step = domain.step_seconds(search.scenario, world)
    config: RepresentativeConfig = search.solver_config
    horizon = RewardConfig.from_dict(search.reward_settings).horizon
    episode = domain.episode_seconds(search.scenario, world)
    agents = list(search.agents)
    yield (
        f"pilot {search.solver} {agents[0]} vs {agents[1]} from {search.scenario} ({search.budget:,} steps, seed "
        f"{search.seed}):"
    )
    own = clip_lengths(horizon, config.longest)
    tried = pilot_votes(search, pool, own)
    for length, *_, record in tried:
        mark = " (the study's)" if length == horizon else ""
        yield f"  at {length * step:.1f} s{mark}: {verdict(record, agents)}"
    if any(one[4]["decided"] for one in tried):
        return
    longest = round(episode / step) if episode is not None else 2 * own[-1]
    for more in clip_lengths(horizon, longest)[len(own) :]:
        if (config.pushes + 1) * more > search.budget:
            yield f"  with longest = {more * step:g}: one state's rollouts would take more than the budget"
            break
        longer = pilot_votes(search, pool, clip_lengths(horizon, more))
        chosen = longer[-1]
        yield f"  with longest = {more * step:g}, at {chosen[0] * step:.1f} s: {verdict(chosen[4], agents)}"
        tried += longer
        if chosen[4]["decided"]:
            yield (
                f"  -> longest = {more * step:g} in the scheme's settings lets its search choose "
                f"{chosen[0] * step:.1f}-s clips where the study's {horizon * step:.1f} s leave the vote weak "
                "(docs/search.md)"
            )
            return
    best = max(tried, key=lambda one: lean(one[3].state_weights))
    states = states_needed(best[3].state_weights, best[4]["looks"])
    if states is None:
        yield "  -> its states show no difference on the whole: these agents may look alike in any clip"
        return
    cost = (config.pushes + 1) * best[0]
    yield (
        f"  -> no clip up to an episode decides it at this budget; about {states} states would at "
        f"{best[0] * step:.1f} s (states = {states}, a budget of about {states * cost:,} steps; the vote stops early "
        "once decided)"
    )


def verdict(record: dict[str, Any], agents: list[str]) -> str:
    """A vote's verdict and its states in words."""
    line = describe_vote(agents, [record["for_first"], record["for_second"]], record["no_majority"], record["p"])
    if not record["decided"]:
        return f"weak: {line}"
    return f"decided for {agents[0] if record['direction'] > 0 else agents[1]}: {line}"


def lean(weights: np.ndarray) -> float:
    """How far states' weights lean, over their spread (0 where they do not)."""
    mean, spread = abs(float(np.mean(weights))), float(np.std(weights))
    return mean / spread if spread else math.inf if mean else 0.0


def pilot_votes(search: SearchJob, pool: Pool, lengths: list[int]) -> list[Tried]:
    """The votes the search's representative solver takes at ``lengths`` (steps, `vote_lengths`): the same states,
    pushes, budget and looks (read from ``pool``, which draws as the search's own), without the replays of its
    clips."""
    agents = list(search.agents)
    config: RepresentativeConfig = search.solver_config
    return vote_lengths(lambda n: pool.rollouts(agents, n), pool.draw, Tracker(search.budget, 1), config, lengths)


def states_needed(weights: np.ndarray, looks: int) -> int | None:
    """Roughly how many states a vote needs to decide, with chance `POWER`, a lean as large as these weights' (their
    mean over their spread), tested at ``ALPHA / looks``: the normal approximation of the sign-flip test; where every
    state leans alike, the fewest whose unanimous sign test decides. None where they lean nowhere."""
    mean, spread = float(np.mean(weights)), float(np.std(weights, ddof=1)) if len(weights) > 1 else 0.0
    if mean == 0:
        return None
    if spread == 0:  # n alike: p = 2 / 2**n
        return math.floor(1 + math.log2(looks / ALPHA)) + 1
    z = float(norm.ppf(1 - ALPHA / looks / 2) + norm.ppf(POWER))
    return math.ceil((z * spread / abs(mean)) ** 2)


def truth_lines(prepared: Prepared, cache: Cache, backend: Backend) -> Iterator[str]:
    """Each pair some clip shows, compared on a few paired test episodes at the study's evaluation seed."""
    spec = prepared.study.spec
    pairs = list(dict.fromkeys(tuple(job.pair) for job in prepared.jobs))
    episodes = min(PILOT_EPISODES, spec.eval_episodes)
    agents = sorted({agent for pair in pairs for agent in pair})
    found = evaluate_runs(prepared.study, cache, lambda line: None, [(agent, episodes) for agent in agents], backend)
    if any("episode_rewards" not in found[agent, episodes] for agent in agents):
        yield "pilot ground truth: this world gives no per-episode rewards to compare pairs on"
        return
    for first, second in pairs:
        compared = paired_comparison(
            (first, second),
            found[first, episodes]["episode_rewards"],
            found[second, episodes]["episode_rewards"],
            looks=1,
        )
        low, high = compared.ci95
        numbers = f"{first} - {second} {compared.difference:.2f} reward, 95% interval {low:.2f} to {high:.2f}"
        if compared.decided:
            better = first if compared.difference > 0 else second
            verdict = f"{better} is better"
        else:
            verdict = (
                f"undecided: the build compares them on {spec.eval_episodes} paired episodes and more while "
                "undecided; a pair it cannot decide rests on a coin toss"
            )
        yield f"pilot ground truth {first} vs {second} on {episodes} paired episodes: {verdict} ({numbers})"
