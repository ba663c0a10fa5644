"""The crowd world's rollouts for the representative solver: every drawn state's rollouts of every robot stepped
together in one batched coupled simulator, each robot's clip read from the state it finished in without a replay
(the crowd's fast path; `search.core.domain.Domain.play_states` is the generic one)."""

from __future__ import annotations

import math

import numpy as np

from app.visible import VisibleClip, progress_towards
from search.core.contrast import Played, visible_contrast
from search.core.outcomes import OUTCOME_NAMES
from search.core.prior import ActionPrior
from search.crowd.problem import concat_snapshots
from search.crowd.sim.coupled import CoupledSimulator
from search.crowd.sim.observation import Policy
from search.crowd.sim.scenarios import Scenario
from search.solvers.reward import DivergenceReward, RewardConfig


def play(
    policies: list[Policy],
    scenarios: list[Scenario],
    reward_config: RewardConfig,
    pushes: int,
    rng: np.random.Generator,
) -> Played:
    """Every policy's rollouts: one without pushes and ``pushes`` under uniform pushes from each scenario, all in
    one batch, each until every robot has finished or the horizon (the reward's ``finish = "last"``); each robot
    read as it finished."""
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
    ends = np.zeros((rows_total, len(policies)), dtype=np.int64)  # the step each robot finished on (0: it ran on)
    final = {}  # row -> (outcome, event_time, min_clearance, robot_pos, time) when its rollout ended
    rows = np.arange(rows_total)
    for t in range(1, horizon + 1):
        _, _, newly_done = sim.advance(env[rows, t - 1])
        state = sim.state
        outcome, done = sim.gather(state.outcome), sim.gather(state.done)
        ends[rows] = np.where(newly_done, t, ends[rows])
        goal, end = events.events(newly_done, outcome, done.all(axis=1), np.full(rows.size, t))
        over = goal | end
        searched[rows[over]] = t
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
    return Played(
        state=np.arange(rows_total) // copies,
        env=[env[row, : searched[row]] for row in range(rows_total)],
        ends=ends,
        clips=[_clip(scenarios[row // copies], *final[row]) for row in range(rows_total)],
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
