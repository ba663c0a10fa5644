"""The divergence reward of the paper's adaptive scenario search, for N >= 2 agents in one coupled simulator.

Per step (step t = 1, 2, ... counts steps from the scenario's initial state):

- a **goal** step (some agent reached its goal on this step; with ``collision_is_goal`` a collision counts too)
  ends the trajectory with ``goal_bonus + alpha * d_s``, d_s the divergence of the agents' positions;
- an **end** step without a goal ends it with ``horizon_offset + beta * h``, h a heuristic (default: d_s again):
  t reached the horizon T, or the agents' episodes ended as ``finish`` says. With ``finish = "all"`` an agent
  that finished without reaching its goal waits and the trajectory goes on until every agent has finished; with
  ``finish = "first"`` (the paper's Algorithm 1, CrowdNav's ``done``) it ends as soon as any agent's episode
  ends, so a collision ends it too, without the goal's reward unless ``collision_is_goal``; with
  ``finish = "last"`` not even a goal ends it before every agent's episode has ended (or T), and the goal's
  reward is given only on that last step (the representative solver's rollouts: each agent is pushed until its
  own episode ends, whichever agent it is compared with); with ``goal_needs_contrast`` a step on which every
  agent has reached its goal is no goal step (nothing tells the agents apart there);
- any other step gives the action divergence d_a of the agents' actions;
- every step adds ``plausibility * log p(a_env)`` under the environment action prior (0 by default).

A divergence is the norm of a difference, plain (the paper's code) or squared (the paper's text), combined over
all agent pairs by their mean or their minimum (the pair that differs least decides). The paper's code amounts to
``alpha = 1, goal_bonus = 100`` and ``beta = 1e4, horizon_offset = -1e5``; the defaults here are the plain
``alpha = beta = 1`` of the paper's formula.

One compiled kernel computes every divergence: it scores a batch of search rollouts and a replayed trajectory
(summaries, ``foil verify``), step by step, so a summary's numbers are exactly the search's for the same simulated
steps. The tests hold the formula written with numpy arrays, as the reference the kernel must match bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from importlib import import_module
from typing import Protocol, cast

import numba
import numpy as np
import numpy.typing as npt

from search.core.outcomes import COLLISION, SUCCESS
from search.core.prior import PRIOR_KINDS, ActionPrior
from search.core.settings import ConfigTable

TERMS = ("action_divergence", "goal", "horizon", "plausibility")
FINISHES = ("all", "first", "last")  # what ends a trajectory besides its horizon (`RewardConfig.finish`)


@dataclass(frozen=True)
class RewardConfig(ConfigTable):
    """Everything that defines the search objective. Defaults: the paper's formula with plain norms and T = 100."""

    what = "reward"

    # the searched clip's length in steps; a study file or the command line gives it in seconds (horizon = 25.0),
    # or in steps (horizon_steps = 100), as every length of time (search.core.settings)
    horizon: int = field(default=100, metadata={"seconds": 25.0})
    norm: str = "plain"  # "plain" ||x|| (paper code) or "squared" ||x||^2 (paper text)
    combine: str = "mean"  # how pairwise divergences of N > 2 agents combine: "mean" or "min"
    alpha: float = 1.0
    goal_bonus: float = 0.0
    beta: float = 1.0
    horizon_offset: float = 0.0
    heuristic: str = "state_divergence"  # a name in HEURISTICS or module:attribute
    collision_is_goal: bool = False
    # the trajectory ends at a goal or when "all" agents have finished, when the "first" one has, or only when the
    # "last" one has (a goal included)
    finish: str = "all"
    goal_needs_contrast: bool = False  # no goal term when every agent reaches its goal (they arrive together)
    plausibility: float = 0.0
    prior: str = "uniform"  # environment action prior: "uniform" or "gaussian"
    prior_sigma: float = 0.1

    def __post_init__(self) -> None:
        checks = [
            (isinstance(self.horizon, int) and self.horizon >= 1, "horizon must be a whole number of steps >= 1"),
            (self.norm in ("plain", "squared"), "norm must be 'plain' or 'squared'"),
            (self.combine in ("mean", "min"), "combine must be 'mean' or 'min'"),
            (
                self.finish in FINISHES,
                "finish must be 'all' (a goal, or every agent finished, ends it), 'first' (the first finish ends "
                "it) or 'last' (only every agent finished ends it)",
            ),
            (self.prior in PRIOR_KINDS, f"prior must be one of {PRIOR_KINDS}"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid reward config: {message}")
        heuristic_function(self.heuristic)

    def with_horizon(self, horizon: int | None) -> RewardConfig:
        """This objective over ``horizon`` steps (itself for None): a summary that ends where its clip does."""
        return self if horizon is None or horizon == self.horizon else replace(self, horizon=int(horizon))


def pairwise_divergence(values: np.ndarray, norm: str, combine: str) -> np.ndarray:
    """Divergence of per-agent vectors in the plane (..., N, 2) over all agent pairs, as (...)."""
    out = np.empty(values.shape[:-2])
    _divergences(_rows(values), norm == "squared", combine == "min", out.reshape(-1))
    return out


def state_divergence(agent_pos: np.ndarray, other_pos: np.ndarray, config: RewardConfig) -> np.ndarray:
    """The default horizon heuristic: how far apart the agents ended up."""
    return pairwise_divergence(agent_pos, config.norm, config.combine)


# h(agent_pos (..., N, 2), other_pos (..., n, 2), config) -> (...)
Heuristic = Callable[[np.ndarray, np.ndarray, RewardConfig], np.ndarray]

HEURISTICS: dict[str, Heuristic] = {"state_divergence": state_divergence}


def heuristic_function(spec: str) -> Heuristic:
    """A heuristic ``h(agent_pos (..., N, 2), other_pos (..., n, 2), config) -> (...)`` by name or
    ``module:attribute``: ``other_pos`` holds the world's other movers."""
    if spec in HEURISTICS:
        return HEURISTICS[spec]
    if ":" in spec:
        module_name, _, attribute = spec.partition(":")
        try:
            return cast(Heuristic, getattr(import_module(module_name), attribute))
        except (ImportError, AttributeError) as error:
            raise ValueError(f"cannot load heuristic {spec!r}: {error}") from None
    raise ValueError(f"unknown heuristic {spec!r}: use one of {sorted(HEURISTICS)} or module:attribute")


class Replayed(Protocol):
    """A replayed trajectory as `DivergenceReward.trajectory` reads it (a world's, such as the crowd's
    ``coupled.Trajectory``): per step (T, ...) and per agent (N,)."""

    @property
    def time(self) -> np.ndarray: ...  # (T,)

    @property
    def event_time(self) -> np.ndarray: ...  # (N,), NaN where an agent's episode has not ended

    @property
    def outcome(self) -> np.ndarray: ...  # (N,)

    @property
    def agent_actions(self) -> np.ndarray: ...  # (T, N, 2)

    @property
    def agent_pos(self) -> np.ndarray: ...  # (T, N, 2)

    @property
    def other_pos(self) -> np.ndarray: ...  # (T, n, 2)

    @property
    def env_actions(self) -> np.ndarray: ...  # (T, n, 2)


class DivergenceReward:
    def __init__(self, config: RewardConfig, prior: ActionPrior) -> None:
        self.config = config
        self.prior = prior
        self.heuristic = heuristic_function(config.heuristic)

    def events(
        self, newly_done: np.ndarray, outcome: np.ndarray, all_done: np.ndarray, t: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(goal, end) flags (...) of a step from per-agent flags (..., N) and the step number t (...)."""
        goal_outcome = outcome == SUCCESS
        if self.config.collision_is_goal:
            goal_outcome = goal_outcome | (outcome == COLLISION)
        goal = (newly_done & goal_outcome).any(axis=-1)
        if self.config.goal_needs_contrast:
            goal &= ~goal_outcome.all(axis=-1)
        finished = newly_done.any(axis=-1) if self.config.finish == "first" else all_done
        over = (t >= self.config.horizon) | finished
        if self.config.finish == "last":
            goal &= over
        end = ~goal & over
        return goal, end

    def divergence(
        self,
        agent_actions: np.ndarray,
        agent_pos: np.ndarray,
        other_pos: np.ndarray,
        goal: np.ndarray,
        end: np.ndarray,
    ) -> np.ndarray:
        """Each step's divergence term (B,), from agent arrays (B, N, 2), the other movers (B, n, 2) and the
        step's events (B,): the goal term on a goal step, the end term on an end step, the action divergence
        otherwise."""
        c = self.config
        heuristic = _STATE_DIVERGENCE
        if self.heuristic is not state_divergence and end.any():
            heuristic = np.asarray(self.heuristic(agent_pos, other_pos, c), dtype=np.float64)
        reward = np.empty(len(goal))
        _step(
            agent_actions,
            agent_pos,
            goal,
            end,
            heuristic,
            c.norm == "squared",
            c.combine == "min",
            c.goal_bonus,
            c.alpha,
            c.horizon_offset,
            c.beta,
            reward,
        )
        return reward

    def step_terms(
        self,
        agent_actions: np.ndarray,
        agent_pos: np.ndarray,
        other_pos: np.ndarray,
        env_action: np.ndarray,
        goal: np.ndarray,
        end: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """Each reward term of one step (B,), from agent arrays (B, N, 2), the other movers (B, n, 2), the
        environment action (B, n, 2) and the step's events (B,)."""
        c = self.config
        divergence = self.divergence(agent_actions, agent_pos, other_pos, goal, end)
        return {
            "action_divergence": np.where(~goal & ~end, divergence, 0.0),
            "goal": np.where(goal, divergence, 0.0),
            "horizon": np.where(end, divergence, 0.0),
            "plausibility": c.plausibility * self.prior.log_prob(env_action)
            if c.plausibility
            else np.zeros(goal.shape),
        }

    def step(
        self,
        agent_actions: np.ndarray,
        agent_pos: np.ndarray,
        other_pos: np.ndarray,
        env_action: np.ndarray,
        goal: np.ndarray,
        end: np.ndarray,
    ) -> np.ndarray:
        """One step's reward (B,): the sum of its terms, of which only the divergence term and the plausibility
        term can be nonzero (a step is a goal, an end or neither)."""
        c = self.config
        reward = self.divergence(agent_actions, agent_pos, other_pos, goal, end)
        return reward + c.plausibility * self.prior.log_prob(env_action) if c.plausibility else reward

    def trajectory(self, trajectory: Replayed, dt: float) -> tuple[float, dict[str, float], np.ndarray]:
        """Total reward, per-term totals and per-step terminal flags of a replayed ``coupled.Trajectory``.

        Totals are summed step by step in order, exactly as a search accumulates them.
        """
        steps = len(trajectory.time)
        t = np.arange(1, steps + 1)
        event_step = np.where(np.isnan(trajectory.event_time), np.inf, np.rint(trajectory.event_time / dt))
        newly_done = event_step[None, :] == t[:, None]
        outcome = np.where(event_step[None, :] <= t[:, None], trajectory.outcome[None, :], 0)
        all_done = np.all(event_step[None, :] <= t[:, None], axis=1)
        goal, end = self.events(newly_done, outcome, all_done, t)
        terms = self.step_terms(
            trajectory.agent_actions, trajectory.agent_pos, trajectory.other_pos, trajectory.env_actions, goal, end
        )
        per_step = terms["action_divergence"] + terms["goal"] + terms["horizon"] + terms["plausibility"]
        return sequential_sum(per_step), {k: sequential_sum(v) for k, v in terms.items()}, goal | end


_STATE_DIVERGENCE = np.empty(0)  # _step's heuristic values when the heuristic is the state divergence


def _rows(values: npt.ArrayLike) -> np.ndarray:
    """Agent vectors (..., N, 2) as rows (B, N, 2) of float64, as the kernels take them (no copy if they are)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim < 2 or values.shape[-2] < 2 or values.shape[-1] != 2:
        raise ValueError(
            f"a divergence compares vectors in the plane of two or more agents (..., N >= 2, 2), "
            f"not an array of shape {values.shape}"
        )
    return values.reshape(-1, *values.shape[-2:])


@numba.njit(cache=True)
def _divergence(values: np.ndarray, row: int, squared: bool, minimum: bool) -> float:
    """The divergence of row ``row`` of agent vectors (B, N, 2): the plain or squared norm of each pair's
    difference, then their minimum or their mean (the pairs summed one by one, in the order (0, 1), (0, 2), ...,
    (1, 2), ...)."""
    agents, total, least = values.shape[1], 0.0, math.inf
    for i in range(agents):
        for j in range(i + 1, agents):
            dx, dy = values[row, i, 0] - values[row, j, 0], values[row, i, 1] - values[row, j, 1]
            d = dx * dx + dy * dy
            if not squared:
                d = np.sqrt(d)
            total += d
            least = min(least, d)
    return least if minimum else total / (agents * (agents - 1) // 2)


@numba.njit(cache=True)
def _divergences(values: np.ndarray, squared: bool, minimum: bool, out: np.ndarray) -> None:
    """``_divergence`` of every row of ``values`` (B, N, 2) into ``out`` (B,)."""
    for b in range(out.shape[0]):
        out[b] = _divergence(values, b, squared, minimum)


@numba.njit(cache=True)
def _step(
    agent_actions: np.ndarray,
    agent_pos: np.ndarray,
    goal: np.ndarray,
    end: np.ndarray,
    heuristic: np.ndarray,
    squared: bool,
    minimum: bool,
    goal_bonus: float,
    alpha: float,
    horizon_offset: float,
    beta: float,
    reward: np.ndarray,
) -> None:
    """Each row's divergence term into ``reward`` (B,): ``goal_bonus + alpha * d_s`` on a goal step,
    ``horizon_offset + beta * h`` on an end step (h: ``heuristic[b]``, or d_s where ``heuristic`` is empty), the
    action divergence d_a otherwise."""
    for b in range(reward.shape[0]):
        if goal[b]:
            reward[b] = goal_bonus + alpha * _divergence(agent_pos, b, squared, minimum)
        elif end[b]:
            h = heuristic[b] if heuristic.size else _divergence(agent_pos, b, squared, minimum)
            reward[b] = horizon_offset + beta * h
        else:
            reward[b] = _divergence(agent_actions, b, squared, minimum)


def sequential_sum(values: np.ndarray) -> float:
    """Left-to-right float sum (numpy's pairwise sum would differ from a step-by-step total in the last bits)."""
    total = 0.0
    for value in np.asarray(values, dtype=np.float64).tolist():
        total += value
    return total
