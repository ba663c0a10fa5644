"""What a crowd clip shows, read from a summary.json (`app.formats`): robots and humans over time, starts, goals,
outcomes.

The crowd's renderer needs only this much of a summary, checked here with errors that say which part of the file
is wrong, so a bad or truncated summary fails before any frame is drawn. A summary's ``window`` and ``follow``
(`search.clips.windows`) pick the states shown and the agents drawn.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.formats import SUMMARY_FORMAT, load_summary
from search.clips.windows import SummaryError, follow_of, window_of
from search.core.outcomes import OUTCOME_NAMES
from search.crowd.sim.scenarios import Scenario


@dataclass(frozen=True)
class Scene:
    """Positions at ``times`` (the initial state first), one crowd per panel: shared (1) or one per agent."""

    agents: tuple[str, ...]  # real names: for the researcher, never drawn
    times: np.ndarray  # (T,)
    robots: np.ndarray  # (T, N, 2)
    humans: np.ndarray  # (T, P, n, 2)
    starts: np.ndarray  # (N, 2)
    goals: np.ndarray  # (N, 2)
    outcomes: tuple[tuple[str, float], ...]  # (event, time) per agent
    robot_radius: float
    human_radius: float
    dt: float
    shown: tuple[int, ...] | None = None  # the summary's agents drawn, by index (None: all); a leader alone: one
    leader: int | None = None  # the agent the others followed (an index into the drawn agents)
    parting: float | None = None  # when agents that followed a leader part: a disagreement clip's moment
    clock: float = 0.0  # the run's seconds before the first state shown (a window's start): what the clock adds

    @property
    def n_agents(self) -> int:
        return self.robots.shape[1]

    @property
    def n_panels(self) -> int:
        return self.humans.shape[1]

    @property
    def n_humans(self) -> int:
        return self.humans.shape[2]

    @property
    def end_time(self) -> float:
        return float(self.times[-1])

    def event_times(self) -> list[float]:
        return [when for event, when in self.outcomes if event != "running"]

    def extent(self, margin: float = 0.9, minimum: float = 13.0) -> tuple[np.ndarray, np.ndarray]:
        """A square around everything that is ever shown, at least ``minimum`` metres across (the paper's
        12 m arena plus a border) so clips of one study share a scale."""
        points = np.concatenate([self.robots.reshape(-1, 2), self.humans.reshape(-1, 2), self.starts, self.goals])
        low, high = points.min(axis=0) - margin, points.max(axis=0) + margin
        centre = (low + high) / 2
        half = max(float(np.max(high - low)), minimum) / 2
        return centre - half, centre + half


def _points(value, shape_tail: tuple[int, ...], where: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SummaryError(f"{where} must be a list of [x, y] pairs") from None
    if array.shape[-len(shape_tail) :] != shape_tail or array.ndim < len(shape_tail):
        raise SummaryError(f"{where} has shape {array.shape}, expected (..., {', '.join(map(str, shape_tail))})")
    if not np.all(np.isfinite(array)):
        raise SummaryError(f"{where} contains NaN or infinite numbers")
    return array


def scene_from_summary(summary: dict, source: str = "summary") -> Scene:
    """The scene of a parsed summary.json, or SummaryError naming what is missing or malformed."""

    def fail(message: str):
        raise SummaryError(f"{source}: {message}")

    if not isinstance(summary, dict):
        fail("expected a JSON object")
    if summary.get("format") != SUMMARY_FORMAT:
        fail(f"format is {summary.get('format')!r}, expected {SUMMARY_FORMAT!r} (is this a summary.json?)")
    missing = [key for key in ("agents", "scenario", "steps", "outcomes") if key not in summary]
    if missing:
        fail(f"missing key(s) {missing}")
    agents = summary["agents"]
    if not isinstance(agents, list) or len(agents) < 2 or not all(isinstance(a, dict) and "name" in a for a in agents):
        fail("agents must be a list of at least two {name, source} objects")
    n_agents = len(agents)
    try:
        scenario = Scenario.from_dict(summary["scenario"], source=f"{source}: scenario")
        config = scenario.config()
    except (ValueError, TypeError, AttributeError) as error:
        fail(f"scenario is not a valid initial state: {error}")
    n = config.human_num
    panels = n_agents if config.robot_visible else 1

    steps = summary["steps"]
    if not isinstance(steps, list) or not steps:
        fail("steps must be a non-empty list")
    times = [0.0]
    robots = [np.tile(np.asarray(scenario.robot_start, dtype=np.float64), (n_agents, 1))]
    humans = [np.tile(np.asarray(scenario.human_positions, dtype=np.float64).reshape(n, 2), (panels, 1, 1))]
    for i, step in enumerate(steps):
        where = f"steps[{i}]"
        if not isinstance(step, dict) or not {"t", "other_positions", "agent_positions"} <= set(step):
            fail(f"{where} must be an object with t, other_positions and agent_positions")
        t = step["t"]
        if not isinstance(t, int | float) or isinstance(t, bool) or not math.isfinite(t):
            fail(f"{where}.t must be a number, got {t!r}")
        if i == 0 and t == 0:  # a summary that records the initial state itself: use it instead
            times, robots, humans = [], [], []
        elif t <= times[-1]:
            fail(f"{where}.t = {t} does not come after {times[-1]}; steps must be in time order")
        try:
            robot = _points(step["agent_positions"], (2,), f"{where}.agent_positions")
            crowd = (
                _points(step["other_positions"], (2,), f"{where}.other_positions") if n else np.zeros((panels, 0, 2))
            )
        except SummaryError as error:
            fail(str(error))
        if robot.shape != (n_agents, 2):
            fail(
                f"{where}.agent_positions has {robot.shape[0] if robot.ndim == 2 else '?'} positions, expected one per "
                f"agent ({n_agents})"
            )
        if crowd.shape == (n, 2) and panels == 1:
            crowd = crowd[None]
        elif crowd.shape == (n, 2):
            fail(
                f"{where}.other_positions holds one crowd, but the robots are visible (robot_visible = true), so "
                f"each of the {panels} agents has its own crowd: the summary must record one crowd per agent"
            )
        if crowd.shape != (panels, n, 2):
            per = f"{n} humans" + (f" for each of the {panels} agents' crowds" if panels > 1 else "")
            fail(f"{where}.other_positions has shape {crowd.shape}, expected {per}")
        times.append(float(t))
        robots.append(robot)
        humans.append(crowd)
    if len(times) < 2:
        fail("steps must hold at least one step after the initial state")
    first, last = window_of(summary, len(times) - 1, source)
    follow = follow_of(summary, n_agents, source)

    outcomes = summary["outcomes"]
    if not isinstance(outcomes, list) or len(outcomes) != n_agents:
        fail(f"outcomes must be a list with one entry per agent ({n_agents})")
    parsed = []
    for k, outcome in enumerate(outcomes):
        event = outcome.get("event") if isinstance(outcome, dict) else None
        if event not in OUTCOME_NAMES:
            fail(f"outcomes[{k}].event must be one of {list(OUTCOME_NAMES)}, got {event!r}")
        when = outcome.get("time")
        if event == "running":
            when = times[-1]
        elif not isinstance(when, int | float) or isinstance(when, bool) or not 0 <= when <= times[-1] + 1e-6:
            fail(f"outcomes[{k}].time must be a time within the steps (0 to {times[-1]} s), got {when!r}")
        parsed.append((str(event), float(when)))

    # the window: its times count from its first state, which the clock shows at the run's time (``clock``); an
    # outcome after its last is still running there, one before its first is shown from the start
    t0, t1 = times[first], times[last]
    parsed = [("running", t1 - t0) if e == "running" or w > t1 + 1e-6 else (e, max(w - t0, 0.0)) for e, w in parsed]
    shown, leader, parting = None, None, None
    if follow is not None and follow[1] >= len(times) - 1:  # followed throughout: the leader alone
        shown, leader = (follow[0],), 0
    elif follow is not None:
        leader = follow[0]
        parting = times[follow[1]] - t0 if first <= follow[1] <= last else None
    drawn = list(shown) if shown is not None else list(range(n_agents))
    robots_shown = np.stack(robots)[first : last + 1, drawn]
    humans_shown = np.stack(humans)[first : last + 1]
    if panels > 1:
        humans_shown = humans_shown[:, drawn]
    return Scene(
        agents=tuple(str(a["name"]) for a in agents),
        times=np.asarray(times[first : last + 1]) - t0,
        robots=robots_shown,
        humans=humans_shown,
        starts=np.tile(np.asarray(scenario.robot_start, dtype=np.float64), (len(drawn), 1)),
        goals=np.tile(np.asarray(scenario.robot_goal, dtype=np.float64), (len(drawn), 1)),
        outcomes=tuple(parsed[k] for k in drawn),
        robot_radius=config.robot_radius,
        human_radius=config.human_radius,
        dt=config.dt,
        shown=shown,
        leader=leader,
        parting=parting,
        clock=float(t0),
    )


def load_scene(path: str | os.PathLike) -> Scene:
    """The scene of a summary file."""
    return scene_from_summary(dict(load_summary(Path(path))), source=str(path))
