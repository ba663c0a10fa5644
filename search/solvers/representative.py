"""The representative solver: a clip that shows what usually happens between two agents, chosen without any ground
truth (no evaluation result and no agent's identity is read).

1. Draw M starting states from a scenario distribution (seeded).
2. Roll each out once without pushes and R times under environment actions drawn uniformly within their bound,
   pushed until both agents' episodes have ended or the horizon (``finish = "last"``): so each agent's rollout is
   its own, played once for every pair and part that reads it (`search.solvers.pool`).
3. Score each clip's visible contrast with the viewer's rule (`app.visible.Observer`, no perception noise): the
   first agent's visible score minus the second's, none (0) under the observer's tie margin (by a world's visible
   score: where the two sums read the same on screen).
4. Each state weighs in by how plainly its clips show a difference: the mean over its rollouts of a viewer's
   expected vote (`app.visible.Observer.expected_vote`, the bots' rule: a crash against lasting counts almost
   fully, a readout a viewer barely tells apart almost nothing); the direction is the sign of the summed weights.
   States are rolled out a batch at a time until the vote is decided (`weighted_test`, Bonferroni over its planned
   looks), the budget fits no further state at the most steps one can take, or every drawn state has voted: the
   budget is never overspent.
5. Candidates are the rollouts that agree with the direction, from states that voted that way, largest contrast
   first. The clip is the first candidate whose exact replay (batch size 1, as `foil verify` replays it) is still a
   non-tie in that direction; the top-K are the first K such.

A tied vote is reported and falls back to the largest contrast in either direction; so does a vote none of whose
candidates survives its replay. A vote that ends undecided is reported as weak: its clip may show either agent as
the better one.

Why: a divergence search leans towards rare states where the worse agent looks better; the paper's fixed study
scenarios can be the least representative states there are. Voting over the task's distribution shows the
contrast that most states show (docs/search.md, "The representative solver").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from app.formats import ClipVote
from app.visible import one_decimal
from search.core.contrast import ALPHA, RollOut, Rollouts, Vote, describe_vote, vote
from search.core.rollout import Tracker
from search.core.workers import workers
from search.solvers.pool import Pool
from search.solvers.reward import RewardConfig
from search.solvers.solver import Comparison, OwnSummaries, register

Replay = TypeVar("Replay")  # what a candidate's replay gives (a summary)


@dataclass(frozen=True)
class RepresentativeConfig:
    states: int = 64  # starting states drawn from the distribution (M): the most that vote
    pushes: int = 32  # rollouts per state under uniform pushes (R), besides the one without pushes
    batch_states: int = 8  # states rolled out together
    alpha: float = ALPHA  # the vote is decided (no more states rolled out) once its test's p < alpha / looks
    # the longest clip it may choose where the vote at the reward's horizon is weak (`clip_lengths`); no longer than
    # the horizon (the default): the horizon's alone
    longest: int = field(default=0, metadata={"seconds": 0.0})
    # clips of the same pair that a study shows before this one from the same vote (the ranking part's after the
    # pairwise part's): this one comes from other states
    earlier: int = 0

    def __post_init__(self) -> None:
        if self.states < 1 or self.pushes < 0 or self.batch_states < 1 or self.longest < 0 or self.earlier < 0:
            raise ValueError(
                "invalid representative setting: states and batch_states must be >= 1, pushes, longest and earlier >= 0"
            )
        if not 0 < self.alpha < 1:
            raise ValueError("invalid representative setting: alpha must lie between 0 and 1")


def candidates(rollouts: Rollouts, result: Vote) -> list[int]:
    """Rollouts in the voted direction from states that voted that way, largest contrast first (ties: draw order);
    with a tied vote, every non-tie rollout, largest contrast first."""
    signs = np.sign(rollouts.contrast)
    if result.direction:
        chosen = (signs == result.direction) & (result.state_votes[rollouts.state] == result.direction)
    else:
        chosen = signs != 0
    index = np.flatnonzero(chosen)
    order: list[int] = index[np.argsort(-np.abs(rollouts.contrast[index]), kind="stable")].tolist()
    return order


def choose(
    order: list[int],
    direction: int,
    replayed: Callable[[list[int]], list[tuple[float, Replay]]],
    top_k: int,
    ahead: int = 1,
) -> list[tuple[int, Replay]]:
    """The first ``top_k`` candidates whose exact replay is a non-tie in ``direction`` (any direction when it is
    0), as (rollout, replay). ``replayed(candidates)`` gives each one's replay contrast and the replay itself;
    it is asked for ``ahead`` candidates at a time (over worker processes), in order, so the choice is the one a
    replay at a time makes."""
    kept: list[tuple[int, Replay]] = []
    for start in range(0, len(order), ahead):
        chunk = order[start : start + ahead]
        for i, (contrast, replay) in zip(chunk, replayed(chunk), strict=True):
            if contrast != 0 and (direction == 0 or np.sign(contrast) == direction):
                kept.append((i, replay))
                if len(kept) == top_k:
                    return kept
    return kept


def roll_out_states(
    roll_out: RollOut,
    scenarios: list[Any],
    config: RepresentativeConfig,
    tracker: Tracker,
    state_cost: int,
    enough: Callable[[Rollouts, int], bool] | None = None,
) -> tuple[Rollouts, int, str]:
    """``roll_out`` over the scenarios in order, a batch of states at a time: each batch only as many states as
    fit in what is left of the budget at ``state_cost``, the most steps one state's rollouts can take, so the
    budget is never overspent (the steps a state took so far are no bound: the next may take more). Stops early
    once ``enough(rollouts, states)``. The rollouts, how many states they cover, and why it stopped ("decided",
    "budget": no further state fits, "states": every state has been rolled out)."""
    parts: list[Rollouts] = []
    done_states, stopped = 0, "states"
    while done_states < len(scenarios):
        count = min(config.batch_states, len(scenarios) - done_states, tracker.remaining // state_cost)
        if count < 1:
            stopped = "budget"
            break
        part = roll_out(scenarios[done_states : done_states + count], tracker)
        part.state += done_states
        parts.append(part)
        done_states += count
        if enough is not None and enough(Rollouts.join(parts), done_states):
            stopped = "decided"
            break
    return Rollouts.join(parts), done_states, stopped


def how_representative(
    drawn: Rollouts, states: int, fixed: list[tuple[str, Rollouts]], alpha: float = ALPHA
) -> list[dict[str, Any]]:
    """How representative each fixed scenario is of the distribution whose ``states`` drawn states' rollouts are
    ``drawn``, for two agents: how often each agent looks better there under nominal pushes (its rollouts: one
    without pushes, the others under uniform pushes), what the distribution's states vote, and the scenario's
    percentile among those states by the share of rollouts that agree with the vote (ties with a state count half:
    50 where every state agrees as often). Whether its rollouts decide that it shows something else than the vote
    is a test, not a majority: the exact one-sided binomial test that fewer than half of them agree with the vote
    (``agreeing_p``, ``decided`` below ``alpha``); a few rollouts that disagree leave it undecided."""
    result = vote(drawn, states)
    signs = np.sign(drawn.contrast)
    agreement = np.array([(signs[drawn.state == s] == result.direction).mean() for s in range(states)])
    reports: list[dict[str, Any]] = []
    for name, rollouts in fixed:
        own = np.sign(rollouts.contrast)
        share = float((own == result.direction).mean()) if result.direction else None
        percentile = None
        if share is not None:
            percentile = float(100 * ((agreement < share).mean() + 0.5 * (agreement == share).mean()))
        agreeing_p = fewer_than_half(int((own == result.direction).sum()), len(own)) if result.direction else 1.0
        reports.append(
            {
                "scenario": name,
                "rollouts": len(own),
                "first_looks_better": float((own > 0).mean()),
                "second_looks_better": float((own < 0).mean()),
                "no_difference": float((own == 0).mean()),
                "majority": int(np.sign(own.sum())),
                "distribution_vote": result.record(drawn, alpha),
                "percentile": percentile,
                "disagrees": bool(result.direction and np.sign(own.sum()) != result.direction),
                "agreeing_p": agreeing_p,
                "decided": agreeing_p < alpha,
            }
        )
    return reports


def fewer_than_half(agreeing: int, rollouts: int) -> float:
    """The exact one-sided binomial test's p that a scenario's rollouts agree with a vote less often than half the
    time: the chance of ``agreeing`` or fewer of ``rollouts`` were each as likely to agree as not."""
    return float(sum(math.comb(rollouts, k) for k in range(agreeing + 1)) / 2**rollouts)


def weak_vote(record: dict[str, Any], agents: Sequence[str]) -> str | None:
    """The warning for a vote that ended undecided (None for a decided one): its clips may show either agent as the
    better one. Where longer clips were tried, each one's vote; where none were, that a longer clip may decide it."""
    if record["decided"]:
        return None
    why = {
        "budget": "the budget fits no further state",
        "states": f"all {record.get('drawn', record['states'])} drawn states voted (raise states)",
    }.get(record.get("stopped", ""), "")
    level = f"{record['alpha']} / {record['looks']} looks" if record["looks"] > 1 else f"{record['alpha']}"
    vote_line = describe_vote(agents, [record["for_first"], record["for_second"]], record["no_majority"], record["p"])
    longer = "; a longer clip may decide it (longest, docs/search.md)"
    if "lengths" in record:
        longer = "; " + "; ".join(
            f"at {one_decimal(one['seconds'])} s: {describe_length(one, agents)}" for one in record["lengths"][1:]
        )
    return (
        f"weak vote: {vote_line}, not below {level}{'; ' + why if why else ''}{longer}: its clips may show either "
        f"agent as the one that usually looks better"
    )


def describe_length(vote: dict[str, Any], agents: Sequence[str]) -> str:
    """One length's vote in short: ``8 highway-med, 30 highway-hi, p < 0.001, decided``."""
    p = "< 0.001" if vote["p"] < 0.001 else f"= {vote['p']:.2g}"
    decided = ", decided" if vote["decided"] else ""
    return f"{vote['for_first']} {agents[0]}, {vote['for_second']} {agents[1]}, p {p}{decided}"


def longer_clip(record: dict[str, Any], agents: Sequence[str]) -> str | None:
    """Where the vote chose a longer clip than the reward's horizon (the study's clip length), that it did and
    why, so a study comparing schemes at one clip length says where one differs."""
    lengths = record.get("lengths", [])
    if not lengths or record["horizon"] == lengths[0]["horizon"]:
        return None
    first, chosen = lengths[0], next(one for one in lengths if one["horizon"] == record["horizon"])
    return (
        f"longer clip: {one_decimal(chosen['seconds'])} s, not {one_decimal(first['seconds'])} s: at "
        f"{one_decimal(first['seconds'])} s the vote was weak ({describe_length(first, agents)}); at "
        f"{one_decimal(chosen['seconds'])} s {describe_length(chosen, agents)}"
    )


def representative(
    roll_out: Callable[[int], RollOut],
    draw: Callable[[int], list[Any]],
    tracker: Tracker,
    config: RepresentativeConfig,
    replay: Callable[[int], Callable[[list[tuple[object, np.ndarray]]], list[tuple[float, Replay]]]],
    lengths: Sequence[int],
    ahead: int = 1,
) -> tuple[list[Replay], dict[str, Any]]:
    """Vote at each clip length of ``lengths`` in turn (in steps, shortest first), each on the states ``draw(n)``
    draws for it, until a vote is decided or the budget fits no state of the next length (`vote_states`); then
    choose the top-K clips of the first decided vote, or of the first length's where none is (`choose_clips`),
    from states other than those of the ``config.earlier`` clips chosen before from the same vote. Every look at
    every length is planned before any state is drawn and tested at ``alpha`` over all of them, so trying a longer
    clip holds the test as one vote does. ``roll_out(n)`` rolls out states to ``n`` steps; ``replay(n)([(scenario,
    actions), ...])`` gives each exact replay's contrast and the replay (a summary) at ``n`` steps, ``ahead`` at a
    time, not counted against the budget, as no solver counts its summaries' replays. Returns the chosen replays
    in order and the record of the vote for run.json."""
    tried = vote_lengths(roll_out, draw, tracker, config, lengths)
    n, scenarios, rollouts, result, record = next((one for one in tried if one[4]["decided"]), tried[0])
    shown: set[int] = set()  # the states of the clips chosen before this one
    for _ in range(config.earlier):
        before, _, _ = choose_clips(rollouts, result, scenarios, replay(n), tracker.queue.k, ahead, shown)
        shown |= {int(rollouts.state[i]) for i, _ in before}
    chosen, record["candidates"], record["selection"] = choose_clips(
        rollouts, result, scenarios, replay(n), tracker.queue.k, ahead, shown
    )
    if config.earlier:
        record["earlier_states"] = sorted(shown)
    record["chosen"] = [
        {"state": int(rollouts.state[i]), "rollout": i, "contrast": float(rollouts.contrast[i])} for i, _ in chosen
    ]
    if len(lengths) > 1:  # the length chosen, and every length's vote
        record["horizon"] = n
        record["lengths"] = [{"horizon": one[0]} | {key: one[4][key] for key in STRENGTH} for one in tried]
    return [summary for _, summary in chosen], record


Tried = tuple[int, list[Any], Rollouts, Vote, dict[str, Any]]  # a length, its states, rollouts, vote and record


def vote_lengths(
    roll_out: Callable[[int], RollOut],
    draw: Callable[[int], list[Any]],
    tracker: Tracker,
    config: RepresentativeConfig,
    lengths: Sequence[int],
) -> list[Tried]:
    """The votes `representative` takes: at each length in turn, on the states drawn for it, until one is decided
    or the budget fits no state of the next length, every look of every length planned first and tested
    together."""
    fitting = [n for n in lengths if (config.pushes + 1) * n <= tracker.budget] or list(lengths[:1])
    looks = [planned_looks(config.states, tracker, config, n) for n in fitting]
    tried: list[Tried] = []
    for n, own in zip(fitting, looks, strict=True):
        if tried and tracker.remaining < (config.pushes + 1) * n:
            break
        scenarios = draw(n)
        tried.append((n, scenarios, *vote_states(roll_out(n), scenarios, tracker, config, n, own, sum(looks))))
        if tried[-1][4]["decided"]:
            break
    return tried


STRENGTH = ("states", "for_first", "for_second", "no_majority", "weight", "p", "decided")  # a vote in short


def clip_lengths(horizon: int, longest: int) -> list[int]:
    """The clip lengths a vote may try, in steps: the reward's ``horizon``, then twice as long and so on up to
    ``longest`` (which is tried last); only the horizon where ``longest`` is no longer."""
    lengths = [horizon]
    while lengths[-1] < longest:
        lengths.append(min(2 * lengths[-1], longest))
    return lengths


def planned_looks(states: int, tracker: Tracker, config: RepresentativeConfig, horizon: int) -> int:
    """How often a vote at ``horizon`` may be looked at: after each full batch of the states the budget surely fits
    (at most ``states``), the last where it stops. Refuses a budget that fits no state."""
    state_cost = (config.pushes + 1) * horizon
    if state_cost > tracker.budget:
        raise ValueError(
            f"a budget of {tracker.budget} steps fits no starting state: one state's rollouts take up to "
            f"{state_cost} steps ((pushes + 1) x a horizon of {horizon} steps); raise --budget or lower pushes. A "
            "horizon written as steps before lengths of time became seconds now asks for that many seconds: give "
            "it in seconds (horizon = S), or in steps as horizon_steps = N"
        )
    return math.ceil(min(states, tracker.remaining // state_cost) / config.batch_states)


def vote_states(
    roll_out: RollOut,
    scenarios: list[Any],
    tracker: Tracker,
    config: RepresentativeConfig,
    horizon: int,
    looks: int,
    all_looks: int,
) -> tuple[Rollouts, Vote, dict[str, Any]]:
    """The vote of the drawn ``scenarios``, rolled out a batch of states at a time until it is decided or the budget
    fits no further state: looked at after each of its ``looks`` planned batches, each look at
    ``alpha / all_looks`` (`strength`), ``all_looks`` being every look planned before any state was drawn (of
    every clip length tried), so the test holds however the states vote."""
    state_cost = (config.pushes + 1) * horizon

    def decided(found: Rollouts, states: int) -> bool:
        early = states % config.batch_states == 0 and states < looks * config.batch_states
        return early and vote(found, states).p < config.alpha / all_looks

    rollouts, done_states, stopped = roll_out_states(roll_out, scenarios, config, tracker, state_cost, decided)
    result = vote(rollouts, done_states)
    record = result.record(rollouts, config.alpha, all_looks) | {"stopped": stopped, "drawn": len(scenarios)}
    return rollouts, result, record


def choose_clips(
    rollouts: Rollouts,
    result: Vote,
    scenarios: list[Any],
    replay: Callable[[list[tuple[object, np.ndarray]]], list[tuple[float, Replay]]],
    top_k: int,
    ahead: int,
    shown: Collection[int] = (),
) -> tuple[list[tuple[int, Replay]], int, str]:
    """The vote's top-K clips (`candidates`, `choose`) as (rollout, replay), from states not ``shown`` before, how
    many candidates it had, and how they were chosen: a tied vote, or one none of whose candidates survives its
    replay, falls back to the largest contrast either way."""

    def unshown(order: list[int]) -> list[int]:
        return [i for i in order if int(rollouts.state[i]) not in shown]

    order, how = unshown(candidates(rollouts, result)), "voted direction"

    def replayed(chosen: list[int]) -> list[tuple[float, Replay]]:
        return replay([(scenarios[rollouts.state[i]], rollouts.actions[i]) for i in chosen])

    chosen = choose(order, result.direction, replayed, top_k, ahead)
    if not chosen:
        how = (
            "largest contrast (tied vote)"
            if not result.direction
            else "largest contrast (no candidate of the vote survived its replay)"
        )
        everything = unshown(candidates(rollouts, Vote(result.state_weights, 0)))
        chosen = choose(everything, 0, replayed, top_k, ahead)
    if not chosen:  # no rollout shows any visible difference: the nominal rollout of the first state
        how = "no visible contrast anywhere: the first state without pushes"
        chosen = [(0, replayed([0])[0][1])]
    return chosen, len(order), how


def search_pool(
    comparison: Comparison, agents: Sequence[str], config: RepresentativeConfig, rng: np.random.Generator
) -> Pool:
    """The pool of rollouts a search's votes read: its own pair's, or a study's agents' (the same draws for the
    pair, `search.solvers.pool`), from the seed of ``rng``."""
    return Pool(
        comparison.domain,
        agents,
        comparison.scenario,
        comparison.world_settings,
        comparison.reward_settings,
        config.states,
        config.pushes,
        config.batch_states,
        rng,
    )


class Representative(OwnSummaries):
    """The representative solver: it draws its own starting states and records its vote under ``vote``."""

    name = "representative"
    # 2: states weigh in by how plainly their clips show a difference; 3: every agent is pushed until each one's
    # episode has ended (`search.solvers.pool`), each clip length's draws its own
    rules = 3
    pooled = True
    config_class = RepresentativeConfig
    starts = "distribution"
    record_key = "vote"

    def choose(
        self, comparison: Comparison, tracker: Tracker, rng: np.random.Generator, config: RepresentativeConfig
    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """The summaries (in its order: the chosen clip first) and the record of its vote. Each summary's scenario
        is the starting state it was drawn as; its solver entry says which state and what contrast the search
        saw."""
        domain, scenario, reward_settings = comparison.domain, comparison.scenario, comparison.reward_settings
        if not domain.is_distribution(scenario):
            raise ValueError(
                f"the representative solver draws starting states from a distribution (such as "
                f"'training'); {scenario!r} is one fixed scenario"
            )
        agents = comparison.pair(self.name, "solver votes which of two agents looks better")
        world = comparison.world_settings
        pool = comparison.pool or search_pool(comparison, agents, config, rng)
        if not {*agents} <= {*pool.agents} or (pool.scenario, pool.world) != (scenario, world):
            raise ValueError(
                f"a pool of {pool.agents} from {pool.scenario!r} holds no rollouts of {agents} from {scenario!r}"
            )
        played_before = pool.played_steps

        # a world without a batched fast path replays a candidate per worker at a time (Domain.replays)
        ahead = 1 if domain.batched else workers()

        def replay(horizon: int) -> Callable[[list[tuple[object, np.ndarray]]], list[tuple[float, dict[str, Any]]]]:
            reward = pool.reward | {"horizon": horizon}
            return lambda candidates: domain.replays(agents, candidates, reward, comparison.entry)

        lengths = clip_lengths(RewardConfig.from_dict(reward_settings).horizon, config.longest)
        summaries, vote = representative(
            lambda n: pool.rollouts(agents, n), pool.draw, tracker, config, replay, lengths, ahead
        )
        vote["played_steps"] = pool.played_steps - played_before  # what its agents played for it, each agent's own
        for entry in vote.get("lengths", []):  # each length tried, in seconds too, as the study gave them
            entry["seconds"] = entry["horizon"] * domain.step_seconds(scenario, world)
        warning = weak_vote(vote, agents)
        if warning:
            vote["warning"] = warning
        strength = {key: vote[key] for key in STRENGTH}
        longer = longer_clip(vote, agents)
        for summary, chosen in zip(summaries, vote["chosen"], strict=True):
            summary["solver"] = summary["solver"] | {
                "budget_used": tracker.steps,
                "state": chosen["state"],
                "search_contrast": chosen["contrast"],
                "vote": strength,
            }
            if longer:
                summary["solver"]["longer_clip"] = longer
        return summaries, vote

    def warnings(self, record: dict[str, Any]) -> list[str]:
        """A weak vote's warning (`weak_vote`), and a clip longer than the study's (`longer_clip`)."""
        vote = record.get(self.record_key, {})
        found = [vote.get("warning"), longer_clip(vote, record["agents"]) if vote else None]
        return [line for line in found if line]

    def longest_clip(self, config: RepresentativeConfig, horizon: int) -> int:
        """The horizon, or ``longest`` where the vote may choose a longer clip."""
        return max(horizon, config.longest)

    def clip_warnings(self, entry: dict[str, Any]) -> list[str]:
        """A clip longer than the study's (`longer_clip`)."""
        return [entry["longer_clip"]] if "longer_clip" in entry else []

    def clip_vote(self, entry: dict[str, Any]) -> ClipVote | None:
        """The vote's strength as the summary's entry records it."""
        vote = entry.get(self.record_key)
        if vote is None:
            return None
        return ClipVote(
            states=vote["states"],
            won=[vote["for_first"], vote["for_second"]],
            no_majority=vote["no_majority"],
            p=vote["p"],
            decided=vote["decided"],
            weight=vote["weight"],
        )


register(Representative())
