"""The crowd world's rollouts for the representative solver: every drawn state's rollouts stepped together in one
batched coupled simulator, each scored by what its clip visibly shows, read from the final state without a
replay (the crowd's fast path; `search.core.domain.Domain.roll_out` is the generic one)."""

from __future__ import annotations

import math

import numpy as np

from app.visible import VisibleClip, progress_towards
from search.core.contrast import Rollouts, visible_contrast
from search.core.outcomes import OUTCOME_NAMES
from search.core.prior import ActionPrior
from search.core.rollout import Tracker
from search.crowd.problem import concat_snapshots
from search.crowd.sim.coupled import CoupledSimulator
from search.crowd.sim.observation import Policy
from search.crowd.sim.scenarios import Scenario
from search.solvers.reward import DivergenceReward, RewardConfig


def roll_out(
    policies: list[Policy],
    scenarios: list[Scenario],
    reward_config: RewardConfig,
    pushes: int,
    rng: np.random.Generator,
    tracker: Tracker,
) -> Rollouts:
    """One rollout without pushes and ``pushes`` under uniform pushes from each scenario, all in one batch, each
    followed by its coda; scored by their visible contrast."""
    copies = pushes + 1
    sims = [CoupledSimulator(policies, scenario, batch=copies) for scenario in scenarios]
    sim, config = sims[0], sims[0].config
    sim.restore(concat_snapshots([s.snapshot() for s in sims]))
    rows_total, horizon, n = len(scenarios) * copies, reward_config.horizon, config.human_num
    prior = ActionPrior((n, 2), config.env_action_bound, "uniform")
    env = np.zeros((rows_total, horizon, n, 2))
    pushed = np.arange(rows_total) % copies != 0
    env[pushed] = rng.uniform(-config.env_action_bound, config.env_action_bound, (int(pushed.sum()), horizon, n, 2))
    events = DivergenceReward(reward_config, prior)
    searched = np.full(rows_total, horizon)  # steps until the search's end rule ended each rollout
    in_search = np.ones(rows_total, dtype=bool)
    final = {}  # row -> (outcome, event_time, min_clearance, robot_pos, time) when its clip ended
    rows = np.arange(rows_total)
    for t in range(1, horizon + 1):
        _, _, newly_done = sim.advance(np.where(in_search[rows, None, None], env[rows, t - 1], 0.0))
        tracker.count(rows.size)
        state = sim.state
        outcome, done = sim.gather(state.outcome), sim.gather(state.done)
        goal, end = events.events(newly_done, outcome, done.all(axis=1), np.full(rows.size, t))
        ended = in_search[rows] & (goal | end)
        searched[rows[ended]] = t
        in_search[rows[ended]] = False
        over = done.all(axis=1) | (t >= horizon)
        if over.any():
            event_time, clearance = sim.gather(state.event_time), sim.gather(state.min_clearance)
            robot_pos = sim.gather(state.robot_pos)
            for k in np.flatnonzero(over):
                final[int(rows[k])] = (
                    outcome[k].copy(),
                    event_time[k].copy(),
                    clearance[k].copy(),
                    robot_pos[k].copy(),
                    float(state.time[k]),
                )
        keep = np.flatnonzero(~over)
        if not keep.size:
            break
        sim.restore(sim.snapshot(keep))
        rows = rows[keep]
    contrast = np.array([visible_contrast(_clip(scenarios[row // copies], *final[row])) for row in range(rows_total)])
    return Rollouts(
        state=np.arange(rows_total) // copies,
        actions=[env[row, : searched[row]] for row in range(rows_total)],
        contrast=contrast,
    )


def shown(sim: CoupledSimulator, row: int, since_s: float = 0.0) -> float:
    """The visible contrast of a row's clip if it ended now, shown from ``since_s`` simulated seconds on: its
    summary's outcomes (times counted from there) and final positions."""
    state = sim.state
    return visible_contrast(
        _clip(
            sim.scenario,
            sim.gather(state.outcome)[row],
            np.maximum(sim.gather(state.event_time)[row] - since_s, 0.0),
            sim.gather(state.min_clearance)[row],
            sim.gather(state.robot_pos)[row],
            float(state.time[row]) - since_s,
        )
    )


def _clip(scenario: Scenario, outcome, event_time, min_clearance, robot_pos, end_s: float) -> VisibleClip:
    """What a rollout's clip shows, as `VisibleClip.of_summary` reads it from a summary."""
    outcomes = tuple(
        {
            "event": OUTCOME_NAMES[int(o)],
            "time": float(e) if math.isfinite(e) else None,
            "min_other_distance": float(c) if math.isfinite(c) else None,
        }
        for o, e, c in zip(outcome, event_time, min_clearance, strict=True)
    )
    progress = tuple(progress_towards(scenario.robot_start, scenario.robot_goal, end) for end in robot_pos.tolist())
    return VisibleClip(
        labels=tuple(str(k) for k in range(len(outcomes))), outcomes=outcomes, progress=progress, end_s=max(end_s, 1e-6)
    )
