"""HIGHLIGHTS (Amir & Amir, AAMAS 2018) and HIGHLIGHTS-DIV (Amir, Doshi-Velez & Sarne 2019), in any world: each
agent's summary is a reel of the most important moments of its own episodes.

1. Each agent plays the episodes (`search.solvers.episodes`) on its own: every instance follows it
   (`search.solvers.follow`), so what the clip shows is that agent alone.
2. A state's importance is how much it matters what the agent does there. From the agent's action values Q
   (a DQN, or any agent with ``action_values``): ``max_min`` = max Q - min Q (HIGHLIGHTS), or ``second_best`` =
   max Q - the second largest. An agent with no action values (a continuous policy, a scripted one) gets the
   stand-in ``rollouts``, measured from the simulator: from a snapshot of the state, each alternative action (every
   discrete action; for Box actions the agent's own and each coordinate at either end of its range) is taken once
   and the agent's policy goes on for ``lookahead`` steps; the importance is the spread (max - min) of the agent's
   own discounted returns over the alternatives.
3. Greedy selection: the most important states first, each kept if it lies at least ``gap`` steps (and the
   ``context``, so moments never overlap) from the states already kept in its episode, until ``highlights`` are
   kept. Each shows ``context`` steps around its state.
4. HIGHLIGHTS-DIV also skips a state that is closer than ``diversity`` to one already kept, in a true distance:
   the root mean square difference of the states' features (what the clip shows: positions and velocities of
   the agent and the others, or the agent's observation), each feature standardised over the agent's states.
   The original compared the sum of the frames' pixels, which calls two different scenes alike whenever their
   pixel sums are close (a known defect).

The summaries come out per agent (the first agent's, then the second's), each agent's in the order of its
episodes. Each is one moment: it replays its episode with every agent following the reel's agent and shows the
``window`` around the state. Budget: each agent gets half the simulator steps (playing, then measuring
importance); where the stand-in's rollouts of every state do not fit, an evenly spaced share of the states is
measured and only those can be chosen. In a world without a batched fast path the starting states' episodes play
over worker processes (`search.solvers.episodes.in_turn`), with the same reels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, cast

import numpy as np

from search.core.problem import ActionValues, AgentRewards, Alternatives, Features, Follows, provides
from search.core.rollout import Tracker
from search.solvers.episodes import Episodes, Source, continuing, in_turn, play
from search.solvers.follow import ALWAYS, Follow
from search.solvers.reward import RewardConfig
from search.solvers.solver import Comparison, held, register
from search.solvers.watching import Summarize, Watching, spread_source

IMPORTANCE = ("auto", "max_min", "second_best", "rollouts")


@dataclass(frozen=True)
class HighlightsConfig:
    episodes: int = 3  # episodes each agent plays
    highlights: int = 5  # moments in each agent's reel (k)
    # steps each moment shows, its important state in the middle; given in seconds (search.core.settings)
    context: int = field(default=10, metadata={"seconds": 2.5})
    # fewest steps between two moments' states in one episode (never fewer than the context); given in seconds
    gap: int = field(default=10, metadata={"seconds": 2.5})
    importance: str = "auto"  # "max_min", "second_best" (action values), "rollouts"; "auto": max_min where it can
    lookahead: int = 5  # the stand-in's steps after each alternative action
    discount: float = 0.99  # of the stand-in's returns
    diversity: float = 0.0  # HIGHLIGHTS-DIV: the smallest feature distance between two moments (0: HIGHLIGHTS)
    # per agent (in the search's order), its reels a study shows before this one in the same part (a bundle's plan
    # sets it): this reel shows the moments the selection keeps after theirs, so it shows other moments
    earlier: tuple[int, int] = (0, 0)

    def __post_init__(self) -> None:
        checks = [
            (self.episodes >= 1 and self.highlights >= 1, "episodes and highlights must be >= 1"),
            (self.context >= 2, "context must be >= 2 steps"),
            (self.gap >= 0 and self.diversity >= 0, "gap and diversity must be >= 0"),
            (len(self.earlier) == 2 and min(self.earlier) >= 0, "earlier must be two reel counts >= 0"),
            (self.lookahead >= 1, "lookahead must be >= 1"),
            (0 < self.discount <= 1, "discount must be in (0, 1]"),
            (self.importance in IMPORTANCE, f"importance must be one of {IMPORTANCE}"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid highlights setting: {message}")


@dataclass(frozen=True)
class HighlightsDivConfig(HighlightsConfig):
    diversity: float = 0.5


def q_importance(values: np.ndarray, kind: str) -> np.ndarray:
    """HIGHLIGHTS' state importance from action values (B, A): max - min, or max - second best."""
    ordered = np.sort(values, axis=1)
    importance: np.ndarray = ordered[:, -1] - (ordered[:, 0] if kind == "max_min" else ordered[:, -2])
    return importance


@dataclass
class Moment:
    episode: int  # index among all episodes
    step: int  # steps the agent had taken: the state is s_step
    length: int  # steps its episode lasted (or was played)
    importance: float
    features: np.ndarray

    def window(self, context: int) -> tuple[int, int]:
        first = max(0, self.step - context // 2)
        return first, min(self.length, first + context)


@dataclass(frozen=True)
class Forced:
    """Every agent takes ``actions`` (one per row) on the step each row takes from ``at`` steps, and follows
    ``leader`` on every other step: one alternative action, then the agent's own policy."""

    leader: int
    at: np.ndarray  # (B,)
    actions: np.ndarray  # (B, ...)

    def __call__(self, proposed: list[np.ndarray], taken: np.ndarray) -> list[np.ndarray]:
        executed = Follow(self.leader, ALWAYS)(proposed, taken)
        forced = np.asarray(taken) == self.at
        for action in executed:
            action[forced] = self.actions[forced].astype(action.dtype)
        return executed


def importance_kind(problem: object, agent: int, config: HighlightsConfig) -> str:
    has_q = provides(problem, ActionValues) and cast(ActionValues, problem).action_values(agent) is not None
    if config.importance in ("max_min", "second_best") and not has_q:
        raise ValueError(f"{config.importance} importance needs the agent's action values; it has none")
    if config.importance == "auto":
        return "max_min" if has_q else "rollouts"
    return config.importance


# A state the agent played: (step, running rows, features, importance or None, snapshot or None, proposed action).
Played = tuple[int, np.ndarray, np.ndarray, np.ndarray | None, Any, np.ndarray]


def play_agent(
    group: Episodes, agent: int, tracker: Tracker, config: HighlightsConfig, budget: int
) -> tuple[str, list[Played], np.ndarray]:
    """The agent's episodes of one group: per state the episode row, step, features, Q importance (where used)
    and a snapshot and proposed action (for the stand-in); and each row's length."""
    problem = group.coupled.problem
    problem.reset(len(group.env))
    problem.override = Follow(agent, ALWAYS)
    kind = importance_kind(problem, agent, config)
    states: list[Played] = []
    lengths = np.zeros(len(group.env), dtype=np.int64)
    running = np.ones(len(group.env), dtype=bool)
    for t in range(group.env.shape[1]):
        if tracker.steps + running.sum() > budget:
            break
        features = problem.features()
        q = None if kind == "rollouts" else q_importance(problem.action_values(agent), kind)
        before = problem.snapshot() if kind == "rollouts" else None
        _, terminal = problem.step(group.env[:, t])
        tracker.count(int(running.sum()))
        lengths[running] = t + 1
        states.append((t, running.copy(), features, q, before, np.asarray(problem.proposed[agent]).copy()))
        running &= ~np.asarray(terminal, dtype=bool)
        if not running.any():
            break
    return kind, states, lengths


def measured(states: int, left: int, cost: int) -> int:
    """How many of ``states`` the stand-in measures with ``left`` steps to spend, ``cost`` steps each: as many as
    fit, at least one."""
    return min(states, max(1, left // cost))


def rollout_importance(
    group: Episodes, agent: int, states: list[Played], tracker: Tracker, config: HighlightsConfig, budget: int
) -> tuple[dict[tuple[int, int], float], int]:
    """The stand-in importance of the states (step, rows) whose rollouts fit before the tracker reaches ``budget``
    steps (at least one state's): {(row, step): importance}; and the steps of one state's rollouts."""
    problem = group.coupled.problem
    every = [(i, row) for i, (t, running, *_rest) in enumerate(states) for row in np.flatnonzero(running)]
    if not every:
        return {}, 0
    alternatives = len(problem.alternatives(states[0][5][:1]))
    cost = alternatives * config.lookahead
    count = measured(len(every), budget - tracker.steps, cost)
    chosen = [every[j] for j in np.linspace(0, len(every) - 1, count).round().astype(int)]
    parts, at, actions, env = [], [], [], []
    for i, row in chosen:
        t, _, _, _, before, proposed = states[i]
        problem.restore(before)
        parts.append(problem.snapshot([row] * alternatives))
        actions += [a[0] for a in problem.alternatives(proposed[row : row + 1])]
        at += [t] * alternatives
        env += [continuing(group.env[row], t, config.lookahead)] * alternatives
    problem.restore(problem.concat(parts))
    problem.override = Forced(agent, np.array(at), np.array(actions))
    returns = np.zeros(len(at))

    def add(t: int, running: np.ndarray) -> None:
        returns[running] += config.discount ** (t - 1) * problem.agent_rewards[running, agent]

    play(problem, np.stack(env), tracker, add)
    spread = returns.reshape(len(chosen), alternatives)
    scores = {(int(row), states[i][0]): float(s.max() - s.min()) for (i, row), s in zip(chosen, spread, strict=True)}
    return scores, cost


def select(moments: list[Moment], config: HighlightsConfig, earlier: int = 0) -> list[Moment]:
    """Greedy: most important first, at least ``gap`` steps from the kept ones of its episode and (DIV) no closer
    than ``diversity`` to any kept one; the kept ones in episode order. After ``earlier`` reels of the agent, the
    greedy goes on past their moments: this reel's are the next it keeps, as far from theirs as from each other."""
    if not moments:
        return []
    features = np.stack([m.features for m in moments])
    scale = features.std(axis=0)
    scale[scale == 0] = 1.0
    standard = (features - features.mean(axis=0)) / scale
    kept: list[int] = []
    gap = max(config.gap, config.context)
    for i in sorted(range(len(moments)), key=lambda i: -moments[i].importance):
        m = moments[i]
        if any(moments[j].episode == m.episode and abs(moments[j].step - m.step) < gap for j in kept):
            continue
        if config.diversity and any(
            np.sqrt(np.mean((standard[i] - standard[j]) ** 2)) < config.diversity for j in kept
        ):
            continue
        kept.append(i)
        if len(kept) == config.highlights * (earlier + 1):
            break
    if earlier and len(kept) <= config.highlights * earlier:
        raise ValueError(
            f"highlights: the agent's episodes hold {len(kept)} moments far enough apart, too few for "
            f"{earlier + 1} reels of {config.highlights}: give more episodes, a larger budget or fewer highlights, "
            'or let a study\'s reels repeat in a part (reels = "repeat" in its scheme, docs/clips.md)'
        )
    return sorted((moments[i] for i in kept[config.highlights * earlier :]), key=lambda m: (m.episode, m.step))


@dataclass
class Scored:
    """An agent's scored states of one group of episodes, with what its budget checks went by."""

    kind: str  # the importance
    moments: list[Moment]
    played: int  # steps played: one per state scored (or to score)
    cost: int  # steps of one state's rollouts (the stand-in's; 0: none were played)


def group_moments(group: Episodes, tracker: Tracker, agent: int, config: HighlightsConfig, share: int) -> Scored:
    """The agent's scored states of one group, played until the tracker reaches ``share`` steps."""
    start = tracker.steps
    kind, states, lengths = play_agent(group, agent, tracker, config, share)
    played, cost = tracker.steps - start, 0
    if kind == "rollouts":
        scores, cost = rollout_importance(group, agent, states, tracker, config, share)
    else:  # every state has its Q importance
        scores = {
            (int(row), t): float(cast(np.ndarray, q)[row])
            for t, running, _, q, _, _ in states
            for row in np.flatnonzero(running)
        }
    moments = [
        Moment(group.first + int(row), t, int(lengths[row]), scores[(int(row), t)], features[row])
        for t, running, features, *_ in states
        for row in np.flatnonzero(running)
        if (int(row), t) in scores
    ]
    return Scored(kind, moments, played, cost)


def agent_moments(
    groups: list[Episodes],
    agent: int,
    tracker: Tracker,
    config: HighlightsConfig,
    budget: int,
    source: Source | None = None,
) -> tuple[list[Moment], str]:
    """Every scored state of the agent's episodes, and the importance used; the steps left until ``budget`` are
    shared out evenly over the groups of episodes (starting states). With a ``source`` the groups play over worker
    processes."""
    start = tracker.steps
    shares = [start + (budget - start) * (g + 1) // len(groups) for g in range(len(groups))]
    if source is None:
        scored = [
            group_moments(group, tracker, agent, config, share) for group, share in zip(groups, shares, strict=True)
        ]
    else:

        def same(arguments: tuple[Any, ...], found: Scored, steps: int, played_from: int, now: int) -> bool:
            """Played from ``now``: the same play within the share, the same count of states measured, rollouts
            within the budget."""
            share = arguments[-1]
            if now + found.played > share:
                return False
            left = share - found.played
            return not found.cost or (
                measured(found.played, left - now, found.cost) == measured(found.played, left - played_from, found.cost)
                and now + steps <= tracker.budget
            )

        tasks = [(agent, config, share) for share in shares]
        scored = [found for _, found in in_turn(group_moments, source, groups, tasks, tracker, same)]
    return [m for found in scored for m in found.moments], scored[-1].kind


def highlights(
    groups: list[Episodes],
    tracker: Tracker,
    config: HighlightsConfig,
    summarize: Callable[[Episodes, int, Moment], dict[str, Any]],
    source: Source | None = None,
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Both agents' reels as summaries (the first agent's moments, then the second's) and the search's record.
    ``summarize(group, agent, moment)`` builds a moment's summary; with a ``source`` the groups play over worker
    processes."""
    by_episode = {group.first + e: group for group in groups for e in range(len(group.env))}
    summaries, record = [], {}
    for agent in (0, 1):
        moments, kind = agent_moments(groups, agent, tracker, config, tracker.budget * (agent + 1) // 2, source)
        kept = select(moments, config, config.earlier[agent])
        summaries += [summarize(by_episode[m.episode], agent, m) for m in kept]
        record[f"agent_{agent}"] = {
            "importance": kind,
            "states": len(moments),
            "earlier": config.earlier[agent],
            "chosen": [{"episode": m.episode, "step": m.step, "importance": m.importance} for m in kept],
        }
    return summaries, record


class Highlights(Watching):
    name = "highlights"
    config_class: type = HighlightsConfig
    reels = True
    needs = (Follows, Features, Alternatives, AgentRewards)

    def held_to_clip(
        self, config: HighlightsConfig, reward: RewardConfig, steps: int, given: dict[str, Any]
    ) -> tuple[HighlightsConfig, RewardConfig]:
        """Each reel is half of a question's clip (two reels per question), shared by its highlights."""
        context = steps // 2 // config.highlights
        if context < 2:
            raise ValueError(
                f"{steps} steps of clip leave less than two steps for each of {config.highlights} highlights in "
                "each reel: give fewer highlights or more clip_seconds"
            )
        return replace(config, context=held(given, "settings", "context", context)), reward

    def watch(
        self,
        groups: list[Episodes],
        tracker: Tracker,
        config: HighlightsConfig,
        summary: Summarize,
        comparison: Comparison,
    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        agents = comparison.agents

        def of_moment(group: Episodes, agent: int, m: Moment) -> dict[str, Any]:
            first, end = m.window(config.context)
            note = {"reel": agents[agent], "episode": m.episode, "state_step": m.step, "importance": m.importance}
            return summary(group, m.episode, end, Follow(agent, end), (first, end), note)

        return highlights(groups, tracker, config, of_moment, spread_source(comparison, groups))


class HighlightsDiv(Highlights):
    name = "highlights-div"
    config_class = HighlightsDivConfig


register(Highlights())
register(HighlightsDiv())
