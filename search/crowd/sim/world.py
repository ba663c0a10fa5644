"""The crowd-navigation world: robots crossing a crowd, stepped for a batch of worlds in one vectorised call.

A state holds ``W`` worlds. Each world has ``n`` humans and ``R`` robots. Robots are invisible to humans by
default (as in the paper), so several robots can share one crowd: the coupled simulator puts every agent under
comparison into the same world that way. A visible robot changes its crowd, so then each world holds one robot.

Step order (CrowdNav_DSRNN's, except where marked):
  1. human velocities from the pre-move state (ORCA or social force, plus the environment action),
  2. robots move, then humans move, time advances,
  3. collision, success and timeout are judged on the move that just happened (CrowdNav judges the state
     *before* the move, so it reports every terminal event one step late; we do not copy that),
  4. reward: -20 collision, +10 success, 0 timeout, discomfort (d - 0.25) * 10 * dt when closer than 0.25 m,
     otherwise 2 * progress towards the goal;
  5. humans' goal changes, when the world has them (CrowdNav_DSRNN's random and end-of-path goal changes).
A robot that has finished stays where it is; the crowd goes on.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike

from search.core.outcomes import COLLISION, RUNNING, SUCCESS, TIMEOUT
from search.core.settings import ConfigTable
from search.crowd.sim.orca import crowd_velocities, orca_velocities
from search.crowd.sim.social_force import social_force_velocities

UNICYCLE_MOTIONS = ("straight", "arc")
ROBOT_STARTS = ("square", "circle")
HUMAN_RADIUS_RANGE = (0.3, 0.5)  # CrowdNav's randomised human attributes
HUMAN_V_PREF_RANGE = (0.5, 1.5)

ENV_ACTION_MODES = ("preferred", "velocity", "observation")
"""How the environment action (an (x, y) per human) acts on the world:

- ``preferred``: added to each human's preferred velocity before ORCA; humans still avoid each other and keep
  their speed limit, so the action steers the crowd within its habits.
- ``velocity``: added to each human's velocity after ORCA (the default): the action pushes humans directly,
  at up to v_pref + bound, and may make them collide with each other.
- ``observation``: the crowd is untouched; the action is added to the human positions every robot observes
  (the paper's OBSERVATION_NOISE mode).
"""


@dataclass(frozen=True)
class WorldConfig(ConfigTable):
    """Everything that defines a world apart from its initial state. Defaults: the paper's setting."""

    what = "world"

    human_num: int = 10
    human_radius: float = 0.3
    human_v_pref: float = 0.15
    human_policy: str = "orca"
    robot_radius: float = 0.3
    robot_v_pref: float = 1.0
    robot_visible: bool = False
    kinematics: str = "holonomic"
    dt: float = 0.25
    time_limit: float = 50.0
    # ORCA as CrowdNav configures RVO2
    neighbor_dist: float = 10.0
    max_neighbors: int = 10
    time_horizon: float = 5.0
    safety_space: float = 0.15
    # social force (CrowdNav)
    sf_a: float = 2.0
    sf_b: float = 1.0
    sf_ki: float = 1.0
    # unicycle limits per step (CrowdNav_DSRNN)
    unicycle_max_dv: float = 0.1
    unicycle_max_dtheta: float = 0.1
    # reward (CrowdNav_DSRNN)
    success_reward: float = 10.0
    collision_penalty: float = -20.0
    discomfort_dist: float = 0.25
    discomfort_factor: float = 10.0
    progress_factor: float = 2.0
    # environment action
    env_action_mode: str = "velocity"
    env_action_bound: float = 0.25
    clip_env_actions: bool = False
    # random training distribution
    circle_radius: float = 6.0
    min_start_goal_distance: float = 6.0
    robot_start: str = "square"  # "square": start uniform in it, heading pi/2; "circle": CrowdNav's unicycle start
    # CrowdNav_DSRNN's world variations (all off by default; see docs/agents.md)
    randomize_attributes: bool = False  # human radius ~ U(0.3, 0.5) m and v_pref ~ U(0.5, 1.5) m/s
    goal_change_chance: float = 0.0  # every goal_change_interval seconds, each human's chance of a new goal
    goal_change_interval: float = 5.0
    end_goal_change_chance: float = 0.0  # a human's chance of a new goal on reaching its goal
    robot_fov: float = 360.0  # degrees; humans outside the robot's view are not observed
    human_fov: float = 360.0  # degrees; humans avoid only the humans in their view
    unicycle_motion: str = "straight"  # "straight": turn, then move; "arc": CrowdNav's differential drive
    crowd_seed: int = 0  # seeds a fixed scenario's random attributes and goal changes

    def __post_init__(self) -> None:
        checks = [
            (self.human_num >= 0, "human_num must be >= 0"),
            (self.human_policy in ("orca", "social_force"), "human_policy must be 'orca' or 'social_force'"),
            (self.kinematics in ("holonomic", "unicycle"), "kinematics must be 'holonomic' or 'unicycle'"),
            (self.env_action_mode in ENV_ACTION_MODES, f"env_action_mode must be one of {ENV_ACTION_MODES}"),
            (self.dt > 0 and self.time_limit > 0, "dt and time_limit must be positive"),
            (self.env_action_bound >= 0, "env_action_bound must be >= 0"),
            (self.human_radius > 0 and self.robot_radius > 0, "radii must be positive"),
            (
                0 <= self.goal_change_chance <= 1 and 0 <= self.end_goal_change_chance <= 1,
                "goal_change_chance and end_goal_change_chance must be between 0 and 1",
            ),
            (self.goal_change_interval > 0, "goal_change_interval must be positive"),
            (
                0 < self.robot_fov <= 360 and 0 < self.human_fov <= 360,
                "robot_fov and human_fov must be in degrees, above 0 and at most 360",
            ),
            (
                self.human_fov == 360 or (self.human_policy == "orca" and not self.robot_visible),
                "human_fov below 360 needs ORCA humans and an invisible robot",
            ),
            (self.unicycle_motion in UNICYCLE_MOTIONS, f"unicycle_motion must be one of {UNICYCLE_MOTIONS}"),
            (self.robot_start in ROBOT_STARTS, f"robot_start must be one of {ROBOT_STARTS}"),
            (0 <= self.crowd_seed < 2**63, "crowd_seed must be between 0 and 2**63 - 1"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid world config: {message}")

    def with_(self, **changes: Any) -> WorldConfig:
        return replace(self, **changes)

    @property
    def random_crowd(self) -> bool:
        """Whether the crowd draws random numbers while it walks (goal changes)."""
        return self.goal_change_chance > 0 or self.end_goal_change_chance > 0


STATE_FIELDS = (
    "human_pos",
    "human_vel",
    "human_goal",
    "human_radius",
    "human_v_pref",
    "robot_pos",
    "robot_vel",
    "robot_theta",
    "robot_speed",
    "robot_goal",
    "time",
    "done",
    "outcome",
    "event_time",
    "path_length",
    "min_clearance",
    "rng",
)


class WorldState:
    """The worlds' arrays, world axis first:

    - humans: ``human_pos``, ``human_vel``, ``human_goal`` (W, n, 2); ``human_radius``, ``human_v_pref`` (W, n);
    - robots: ``robot_pos``, ``robot_vel``, ``robot_goal`` (W, R, 2); ``robot_theta`` (heading) and
      ``robot_speed`` (signed forward speed, unicycle) (W, R);
    - ``time`` (W,); ``done`` (W, R) bool; ``outcome`` (W, R) int8: RUNNING, SUCCESS, COLLISION, TIMEOUT;
      ``event_time`` (W, R), nan while running; ``path_length`` (W, R); ``min_clearance`` (W, R), the smallest
      surface distance to any human so far;
    - ``rng`` (W,) uint64: the state of the world's own random stream (splitmix64), which the crowd's random
      events draw from, so a snapshot or a copied world carries its future random numbers with it.

    Every field is a view into one buffer with a row of bytes per world (``rows``), so copying, taking or
    overwriting worlds is one array operation, however many fields (a search branches and refills worlds many
    times per step). Fields are therefore written in place (``state.time[...] = t``); rebinding one is an error.
    """

    __slots__ = ("rows", "layout", *STATE_FIELDS)
    rows: np.ndarray
    layout: _Layout

    def __init__(self, **values: ArrayLike) -> None:
        """Worlds from every field of STATE_FIELDS, given by name, each copied into the rows (``rng`` may be
        left out: zero, as states saved before it existed had)."""
        values.setdefault("rng", np.zeros(np.shape(values.get("time", ())), np.uint64))
        if values.keys() != set(STATE_FIELDS):
            raise TypeError(
                f"WorldState takes every field by name: missing {sorted(set(STATE_FIELDS) - values.keys())}"
                f", unknown {sorted(values.keys() - set(STATE_FIELDS))}"
            )
        human_pos, robot_pos = np.asarray(values["human_pos"]), np.asarray(values["robot_pos"])
        layout = _layout(human_pos.shape[1], robot_pos.shape[1])
        object.__setattr__(self, "layout", layout)
        object.__setattr__(self, "rows", np.zeros((human_pos.shape[0], layout.row_bytes), np.uint8))
        for name, value in values.items():
            getattr(self, name)[...] = value

    @classmethod
    def of_rows(cls, rows: np.ndarray, layout: _Layout) -> WorldState:
        """A state over a buffer of world rows (used as it is, not copied)."""
        state = cls.__new__(cls)
        object.__setattr__(state, "layout", layout)
        object.__setattr__(state, "rows", rows)
        return state

    def __getattr__(self, name: str) -> np.ndarray:
        """The field views, made on first use (a snapshot that is only copied or assigned never needs them)."""
        if name not in STATE_FIELDS:
            raise AttributeError(name)
        rows, worlds = self.rows, self.rows.shape[0]
        for field, (offset, dtype, shape, strides) in self.layout.fields.items():
            view = (
                np.ndarray((worlds, *shape), dtype, rows, offset, (rows.strides[0], *strides))
                if worlds
                else np.empty((0, *shape), dtype)
            )  # no worlds: nothing to share
            object.__setattr__(self, field, view)
        asked: np.ndarray = object.__getattribute__(self, name)
        return asked

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(
            f"WorldState fields are views into its rows: write into them in place "
            f"(state.{name}[...] = value) instead of rebinding them"
        )

    def __reduce__(self) -> tuple[Callable[[np.ndarray, int, int], WorldState], tuple[np.ndarray, int, int]]:
        return _state_of_rows, (self.rows, self.layout.humans, self.layout.robots)

    @property
    def n_worlds(self) -> int:
        return int(self.rows.shape[0])

    @property
    def n_robots(self) -> int:
        return self.layout.robots

    def copy(self) -> WorldState:
        return WorldState.of_rows(self.rows.copy(), self.layout)

    def take(self, worlds: ArrayLike) -> WorldState:
        """A new state made of the given worlds (indices may repeat: one node branched into many)."""
        return WorldState.of_rows(self.rows.take(np.asarray(worlds, dtype=np.int64), axis=0), self.layout)

    def assign(self, worlds: ArrayLike | list[int], other: WorldState) -> None:
        """Overwrite the given worlds (an index array or list) with ``other``'s (e.g. fresh episodes for
        finished worlds)."""
        if not isinstance(worlds, list):
            worlds = np.asarray(worlds, dtype=np.int64).reshape(-1).tolist()
        assign_rows(self.row_pairs(other), worlds)

    def row_pairs(self, other: WorldState) -> list[tuple[np.ndarray, np.ndarray]]:
        """(this state's world rows, ``other``'s), as ``assign_rows`` takes them."""
        if other.layout is not self.layout:
            raise ValueError(
                f"worlds of {self.layout.humans} humans and {self.layout.robots} robot(s) cannot be "
                f"overwritten by worlds of {other.layout.humans} humans and {other.layout.robots}"
            )
        return [(self.rows, other.rows)]

    def fields(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in STATE_FIELDS}

    def equals(self, other: WorldState) -> bool:
        return all(np.array_equal(getattr(self, name), getattr(other, name), equal_nan=True) for name in STATE_FIELDS)


@dataclass(frozen=True, eq=False)
class _Layout:
    """Where each field lies in a world's row: (byte offset, dtype, shape and strides after the world axis). One
    object per size of world (``_layout``), so states with the same layout hold the same object."""

    humans: int
    robots: int
    fields: dict[str, tuple[int, np.dtype, tuple[int, ...], tuple[int, ...]]]
    row_bytes: int


def _state_of_rows(rows: np.ndarray, humans: int, robots: int) -> WorldState:
    """Unpickling: the state over its rows, with the one layout object of its sizes."""
    return WorldState.of_rows(rows, _layout(humans, robots))


@cache
def _layout(humans: int, robots: int) -> _Layout:
    shapes = {
        "human_pos": (humans, 2),
        "human_vel": (humans, 2),
        "human_goal": (humans, 2),
        "human_radius": (humans,),
        "human_v_pref": (humans,),
        "robot_pos": (robots, 2),
        "robot_vel": (robots, 2),
        "robot_theta": (robots,),
        "robot_speed": (robots,),
        "robot_goal": (robots, 2),
        "time": (),
        "done": (robots,),
        "outcome": (robots,),
        "event_time": (robots,),
        "path_length": (robots,),
        "min_clearance": (robots,),
        "rng": (),
    }
    dtypes = {"done": np.dtype(np.bool_), "outcome": np.dtype(np.int8), "rng": np.dtype(np.uint64)}
    fields, offset = {}, 0
    for name in sorted(STATE_FIELDS, key=lambda name: -dtypes.get(name, np.dtype(np.float64)).itemsize):
        dtype = dtypes.get(name, np.dtype(np.float64))  # widest first: every field stays aligned
        fields[name] = (offset, dtype, shapes[name], np.empty(shapes[name], dtype).strides)
        offset += dtype.itemsize * math.prod(shapes[name])
    return _Layout(humans, robots, fields, -(-offset // 8) * 8)


def assign_rows(pairs: list[tuple[np.ndarray, np.ndarray]], rows: list[int]) -> None:
    """``target[rows] = values`` for every (target, values) pair; a few rows by plain row assignment, which costs
    far less than fancy indexing (a search refills one row at a time, in a few dozen arrays)."""
    if len(rows) == 1:
        row = rows[0]
        for target, values in pairs:
            target[row] = values[0]
    elif len(rows) <= 4:
        for target, values in pairs:
            for j, row in enumerate(rows):
                target[row] = values[j]
    else:
        for target, values in pairs:
            target[rows] = values


def new_state(
    human_pos: ArrayLike,
    human_goal: ArrayLike,
    robot_pos: ArrayLike,
    robot_goal: ArrayLike,
    robot_theta: ArrayLike,
    config: WorldConfig,
    human_radius: ArrayLike | None = None,
    human_v_pref: ArrayLike | None = None,
    rng: ArrayLike | None = None,
) -> WorldState:
    """A state at time 0 with resting agents, from (W, n, 2) humans and (W, R, 2) robots.

    Human radii and preferred speeds are the config's unless given (W, n). ``rng`` (W,) seeds each world's random
    stream; by default every world's comes from ``config.crowd_seed``, and with ``randomize_attributes`` the
    attributes not given are drawn from it."""
    human_pos = np.array(human_pos, dtype=np.float64)
    robot_pos = np.array(robot_pos, dtype=np.float64)
    w, n = human_pos.shape[:2]
    r = robot_pos.shape[1]
    if config.robot_visible and r != 1:
        raise ValueError("a visible robot changes its crowd, so each world can hold only one robot")
    rng = np.full(w, seed_stream(config.crowd_seed), np.uint64) if rng is None else np.array(rng, np.uint64)
    if config.randomize_attributes and (human_radius is None or human_v_pref is None):
        drawn = np.empty((w, n, 2))
        _draw_attributes(rng, drawn)
        human_v_pref = drawn[..., 0] if human_v_pref is None else human_v_pref
        human_radius = drawn[..., 1] if human_radius is None else human_radius
    return WorldState(
        human_pos=human_pos,
        human_vel=np.zeros((w, n, 2)),
        human_goal=np.array(human_goal, dtype=np.float64),
        human_radius=np.full((w, n), config.human_radius) if human_radius is None else human_radius,
        human_v_pref=np.full((w, n), config.human_v_pref) if human_v_pref is None else human_v_pref,
        robot_pos=robot_pos,
        robot_vel=np.zeros((w, r, 2)),
        robot_theta=np.array(np.broadcast_to(robot_theta, (w, r)), dtype=np.float64),
        robot_speed=np.zeros((w, r)),
        robot_goal=np.array(robot_goal, dtype=np.float64),
        time=np.zeros(w),
        done=np.zeros((w, r), dtype=bool),
        outcome=np.full((w, r), RUNNING, dtype=np.int8),
        event_time=np.full((w, r), np.nan),
        path_length=np.zeros((w, r)),
        min_clearance=np.full((w, r), np.inf),
        rng=rng,
    )


def seed_stream(seed: int) -> np.uint64:
    """A random stream's starting state from a seed (one splitmix64 output, so nearby seeds start far apart)."""
    state = np.array([seed], np.uint64)
    return np.uint64(_next_random(state, 0) * 2.0**53)


@numba.njit(cache=True, nogil=True)
def _next_random(rng: np.ndarray, w: int) -> float:
    """The next uniform number in [0, 1) of world ``w``'s splitmix64 stream, advancing ``rng[w]``."""
    state = rng[w] + np.uint64(0x9E3779B97F4A7C15)
    rng[w] = state
    z = (state ^ (state >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, nogil=True)
def _draw_attributes(rng: np.ndarray, out: np.ndarray) -> None:
    """CrowdNav's randomised humans: (v_pref, radius) per human, uniform over their ranges, from each world's
    stream."""
    for w in range(out.shape[0]):
        for h in range(out.shape[1]):
            v_low, v_high = HUMAN_V_PREF_RANGE
            r_low, r_high = HUMAN_RADIUS_RANGE
            out[w, h, 0] = v_low + (v_high - v_low) * _next_random(rng, w)
            out[w, h, 1] = r_low + (r_high - r_low) * _next_random(rng, w)


def check_env_action(env_action: ArrayLike, n_worlds: int, config: WorldConfig) -> np.ndarray:
    """The environment action as (W, n, 2), after the checks that keep bad input out of the world."""
    n = config.human_num
    action = np.asarray(env_action, dtype=np.float64)
    if action.shape in ((n_worlds, n * 2), (n_worlds, n, 2)):
        action = action.reshape(n_worlds, n, 2)
    else:
        raise ValueError(
            f"environment action must have shape ({n_worlds}, {n * 2}) or ({n_worlds}, {n}, 2) "
            f"(an (x, y) per human per world), got {action.shape}"
        )
    bound = config.env_action_bound
    if np.abs(action).max(initial=0.0) <= bound:  # the usual case, in two array operations
        return action
    if not np.all(np.isfinite(action)):
        raise ValueError("environment action contains NaN or infinite values")
    if np.any(np.abs(action) > bound):
        if not config.clip_env_actions:
            worst = float(np.max(np.abs(action)))
            raise ValueError(
                f"environment action {worst:.4g} is outside the bound ±{bound}; pass actions inside "
                "the bound, or set clip_env_actions = true to clip them"
            )
        action = np.clip(action, -bound, bound)
    return action


def preferred_velocities(state: WorldState) -> np.ndarray:
    """CrowdNav's ORCA preferred velocity: the vector to the goal, normalised only when longer than 1 m."""
    to_goal = state.human_goal - state.human_pos
    length = np.linalg.norm(to_goal, axis=-1, keepdims=True)
    preferred: np.ndarray = np.where(length > 1.0, to_goal / np.maximum(length, 1e-300), to_goal)
    return preferred


def human_velocities(state: WorldState, config: WorldConfig, env_action: np.ndarray | None) -> np.ndarray:
    """The humans' next velocities (W, n, 2) from the current state and the environment action."""
    if config.human_num == 0:
        return np.zeros_like(state.human_vel)
    mode = config.env_action_mode
    padding = 0.01 + config.safety_space
    offset = env_action if env_action is not None and mode == "preferred" else np.zeros_like(state.human_pos)
    if config.human_fov < 360:
        velocity = _crowd_velocities_in_view(state, config, offset, padding)
    elif config.human_policy == "orca" and not config.robot_visible:
        velocity = crowd_velocities(
            state.human_pos,
            state.human_vel,
            state.human_goal,
            state.human_radius,
            state.human_v_pref,
            offset,
            padding=padding,
            neighbor_dist=config.neighbor_dist,
            max_neighbors=config.max_neighbors,
            time_horizon=config.time_horizon,
            dt=config.dt,
        )
    elif config.human_policy == "orca":
        # The visible robot is one more agent in the humans' ORCA (its own velocity as its preference).
        pref = preferred_velocities(state) + offset
        pos = np.concatenate([state.human_pos, state.robot_pos], axis=1)
        vel = np.concatenate([state.human_vel, state.robot_vel], axis=1)
        pref = np.concatenate([pref, state.robot_vel], axis=1)
        rad = np.concatenate([state.human_radius, np.full((state.n_worlds, 1), config.robot_radius)], axis=1)
        speed = np.concatenate([state.human_v_pref, np.full((state.n_worlds, 1), config.robot_v_pref)], axis=1)
        velocity = orca_velocities(
            pos,
            vel,
            pref,
            rad + padding,
            speed,
            neighbor_dist=config.neighbor_dist,
            max_neighbors=config.max_neighbors,
            time_horizon=config.time_horizon,
            dt=config.dt,
            n_ego=config.human_num,
        )
    else:
        goals = state.human_goal
        if env_action is not None and mode == "preferred":
            goals = state.human_pos + preferred_velocities(state) + env_action
        others = (
            (state.robot_pos, np.full(state.robot_pos.shape[:2], config.robot_radius))
            if config.robot_visible
            else (None, None)
        )
        velocity = social_force_velocities(
            state.human_pos,
            state.human_vel,
            goals,
            state.human_radius,
            state.human_v_pref,
            A=config.sf_a,
            B=config.sf_b,
            KI=config.sf_ki,
            dt=config.dt,
            others_pos=others[0],
            others_radius=others[1],
        )
    if env_action is not None and mode == "velocity":
        velocity = velocity + env_action
    return velocity


DUMMY_HUMAN_POSITION = (7.0, 7.0)  # where CrowdNav puts a human that another one does not see


def in_view(heading: np.ndarray, offsets: np.ndarray, fov_degrees: float) -> np.ndarray:
    """Whether each offset (..., m, 2) lies within ``fov_degrees`` centred on ``heading`` (...), as CrowdNav's
    ``detect_visible`` decides it (an offset of zero length is not seen)."""
    direction = np.stack([np.cos(heading), np.sin(heading)], axis=-1)[..., None, :]
    length = np.linalg.norm(offsets, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = np.sum(direction * offsets, axis=-1) / length
        seen: np.ndarray = np.arccos(np.clip(cosine, -1.0, 1.0)) <= np.radians(fov_degrees) / 2
        return seen


def _crowd_velocities_in_view(state: WorldState, config: WorldConfig, offset: np.ndarray, padding: float) -> np.ndarray:
    """ORCA humans that see only the humans within ``human_fov`` of their walking direction: as CrowdNav, each
    human solves its own program in which a human it does not see stands still at DUMMY_HUMAN_POSITION."""
    w, n = state.human_pos.shape[:2]
    heading = np.arctan2(state.human_vel[..., 1], state.human_vel[..., 0])
    seen = in_view(heading, state.human_pos[:, None, :, :] - state.human_pos[:, :, None, :], config.human_fov)
    order = np.array([[a, *(b for b in range(n) if b != a)] for a in range(n)])  # each human first, then the rest
    pos = state.human_pos[:, order]  # (W, n, n, 2): world, ego, agents
    seen = np.take_along_axis(seen, order[None], axis=2)
    seen[:, :, 0] = True
    pos = np.where(seen[..., None], pos, DUMMY_HUMAN_POSITION)
    vel = np.where(seen[..., None], state.human_vel[:, order], 0.0)
    radii = np.where(seen, state.human_radius[:, order], config.human_radius) + padding
    pref = (preferred_velocities(state) + offset)[:, order]
    speed = state.human_v_pref[:, order]
    velocity = orca_velocities(
        *(a.reshape(w * n, *a.shape[2:]) for a in (pos, vel, pref, radii, speed)),
        neighbor_dist=config.neighbor_dist,
        max_neighbors=config.max_neighbors,
        time_horizon=config.time_horizon,
        dt=config.dt,
        n_ego=1,
    )
    return velocity.reshape(w, n, 2)


def robot_velocities(state: WorldState, config: WorldConfig, robot_action: ArrayLike) -> np.ndarray:
    """Apply the robots' kinematics to their actions: the velocities (W, R, 2) they have after this step.

    Holonomic: the action is a velocity, rescaled to at most v_pref. Unicycle: the action is (dv, dtheta),
    each clipped to its per-step limit; speed accumulates within ±v_pref and the robot turns, then moves
    (``unicycle_motion`` "straight") or turns while it moves ("arc", see ``arc_velocities``).
    Updates heading and speed in place.
    """
    action = np.asarray(robot_action, dtype=np.float64)
    if action.shape != state.robot_pos.shape:
        raise ValueError(f"robot action must have shape {state.robot_pos.shape} (W, R, 2), got {action.shape}")
    if config.kinematics == "holonomic":  # one compiled pass, the finiteness check included
        velocity, turns = np.empty_like(action), np.empty(state.done.shape, dtype=np.bool_)
        if not _holonomic(action, float(config.robot_v_pref), state.done, velocity, turns):
            raise ValueError("robot action contains NaN or infinite values")
        np.copyto(state.robot_theta, np.arctan2(velocity[..., 1], velocity[..., 0]), where=turns)
        return velocity
    if not np.isfinite(action).all():
        raise ValueError("robot action contains NaN or infinite values")
    active = ~state.done
    dv = np.clip(action[..., 0], -config.unicycle_max_dv, config.unicycle_max_dv)
    dtheta = np.clip(action[..., 1], -config.unicycle_max_dtheta, config.unicycle_max_dtheta)
    speed = np.clip(state.robot_speed + dv, -config.robot_v_pref, config.robot_v_pref)
    theta = np.mod(state.robot_theta + dtheta, 2 * np.pi)
    state.robot_speed[...] = np.where(active, speed, state.robot_speed)
    state.robot_theta[...] = np.where(active, theta, state.robot_theta)
    velocity = speed[..., None] * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    return np.where(active[..., None], velocity, 0.0)


def arc_velocities(
    state: WorldState, config: WorldConfig, robot_action: ArrayLike, heading_before: np.ndarray, velocity: np.ndarray
) -> np.ndarray:
    """The unicycle's move over one step on an arc, as a velocity (W, R, 2): CrowdNav_DSRNN's differential drive
    turns at the constant rate dtheta / dt while moving at the new speed, so the robot moves along the chord
    v / dtheta * (sin(theta + dtheta) - sin(theta), cos(theta) - cos(theta + dtheta)). A turn under 1e-4 rad
    moves straight (CrowdNav does not move the robot at all then; a policy trained there rarely turns that
    little). ``velocity`` is ``robot_velocities``' result, ``heading_before`` the heading before it."""
    dtheta = np.clip(
        np.asarray(robot_action, np.float64)[..., 1], -config.unicycle_max_dtheta, config.unicycle_max_dtheta
    )
    turning = np.abs(dtheta) >= 1e-4
    rate = state.robot_speed / np.where(turning, dtheta, 1.0)
    chord = np.stack(
        [
            np.sin(heading_before + dtheta) - np.sin(heading_before),
            np.cos(heading_before) - np.cos(heading_before + dtheta),
        ],
        axis=-1,
    )
    moved = np.where(turning[..., None], rate[..., None] * chord, velocity)
    return np.where(state.done[..., None], 0.0, moved)


@numba.njit(cache=True, nogil=True)
def _holonomic(action: np.ndarray, v_pref: float, done: np.ndarray, velocity: np.ndarray, turns: np.ndarray) -> bool:
    """Each action as a velocity rescaled to at most ``v_pref`` (``action * (v_pref / max(speed, 1e-300))`` where
    the speed is over it, bit for bit as the tests' numpy formula computes it); a robot that has finished stands
    still, and one that moves turns to its velocity. Returns whether every action was finite."""
    finite = True
    for w in range(action.shape[0]):
        for r in range(action.shape[1]):
            x, y = action[w, r, 0], action[w, r, 1]
            finite = finite and math.isfinite(x) and math.isfinite(y)
            speed = np.sqrt(x * x + y * y)
            scale = v_pref / max(speed, 1e-300) if speed > v_pref else 1.0
            if done[w, r]:
                velocity[w, r, 0], velocity[w, r, 1] = 0.0, 0.0
            else:
                velocity[w, r, 0], velocity[w, r, 1] = (x * scale, y * scale) if speed > v_pref else (x, y)
            turns[w, r] = speed > 0 and not done[w, r]
    return finite


def step(
    state: WorldState, config: WorldConfig, robot_action: ArrayLike, env_action: ArrayLike | None = None
) -> np.ndarray:
    """Advance every world by one step in place and return each robot's reward (W, R).

    ``env_action`` is None (an unperturbed crowd) or (W, n, 2)/(W, 2n) within the configured bound; in
    ``observation`` mode it does not touch the world (the robots' observation applies it).
    """
    action = None if env_action is None else check_env_action(env_action, state.n_worlds, config)
    return advance(state, config, robot_action, human_velocities(state, config, action))


def advance(state: WorldState, config: WorldConfig, robot_action: ArrayLike, new_human_vel: np.ndarray) -> np.ndarray:
    """``step`` with the humans' new velocities already computed (``human_velocities``)."""
    arc = config.kinematics == "unicycle" and config.unicycle_motion == "arc"
    heading_before = state.robot_theta.copy() if arc else None
    new_robot_vel = robot_velocities(state, config, robot_action)
    moved = new_robot_vel
    if heading_before is not None:
        moved = arc_velocities(state, config, robot_action, heading_before, new_robot_vel)
    reward = np.empty(state.done.shape)
    _move_and_judge(
        state.robot_pos,
        state.robot_goal,
        state.human_pos,
        state.human_radius,
        moved,
        new_human_vel,
        state.time,
        state.done,
        state.outcome,
        state.event_time,
        state.path_length,
        state.min_clearance,
        float(config.dt),
        float(config.robot_radius),
        float(config.time_limit),
        float(config.discomfort_dist),
        float(config.discomfort_factor),
        float(config.progress_factor),
        float(config.success_reward),
        float(config.collision_penalty),
        reward,
    )
    state.robot_vel[...] = new_robot_vel
    state.human_vel[...] = new_human_vel
    if config.random_crowd:
        _change_goals(
            state.human_pos,
            state.human_goal,
            state.human_radius,
            state.human_v_pref,
            state.robot_goal,
            state.time,
            state.rng,
            float(config.goal_change_chance),
            float(config.goal_change_interval),
            float(config.end_goal_change_chance),
            float(config.circle_radius),
            float(config.robot_radius),
            float(config.discomfort_dist),
        )
    return reward


@numba.njit(cache=True, nogil=True)
def _change_goals(
    human_pos: np.ndarray,
    human_goal: np.ndarray,
    human_radius: np.ndarray,
    human_v_pref: np.ndarray,
    robot_goal: np.ndarray,
    time: np.ndarray,
    rng: np.ndarray,
    chance: float,
    interval: float,
    end_chance: float,
    circle_radius: float,
    robot_radius: float,
    discomfort_dist: float,
) -> None:
    """CrowdNav_DSRNN's goal changes, after a move: every ``interval`` seconds each walking human takes a new
    goal with ``chance``; then each human within its radius of its goal takes one with ``end_chance``. A new goal
    lies on the circle (plus noise scaled by the human's v_pref), clear of the other humans' positions and goals
    and of the robots' goals. Unlike CrowdNav it need not be clear of the robots' positions: an invisible
    robot must not change its crowd (several robots share one)."""
    for w in range(human_pos.shape[0]):
        periods = time[w] / interval
        if chance > 0 and abs(periods - np.round(periods)) < 1e-9:
            for h in range(human_pos.shape[1]):
                if human_v_pref[w, h] != 0 and _next_random(rng, w) <= chance:
                    _new_goal(
                        human_pos,
                        human_goal,
                        human_radius,
                        human_v_pref,
                        robot_goal,
                        rng,
                        w,
                        h,
                        circle_radius,
                        robot_radius,
                        discomfort_dist,
                    )
        if end_chance > 0:
            for h in range(human_pos.shape[1]):
                dx, dy = human_goal[w, h, 0] - human_pos[w, h, 0], human_goal[w, h, 1] - human_pos[w, h, 1]
                if (
                    human_v_pref[w, h] != 0
                    and np.sqrt(dx * dx + dy * dy) < human_radius[w, h]
                    and _next_random(rng, w) <= end_chance
                ):
                    _new_goal(
                        human_pos,
                        human_goal,
                        human_radius,
                        human_v_pref,
                        robot_goal,
                        rng,
                        w,
                        h,
                        circle_radius,
                        robot_radius,
                        discomfort_dist,
                    )


@numba.njit(cache=True, nogil=True)
def _new_goal(
    human_pos: np.ndarray,
    human_goal: np.ndarray,
    human_radius: np.ndarray,
    human_v_pref: np.ndarray,
    robot_goal: np.ndarray,
    rng: np.ndarray,
    w: int,
    h: int,
    circle_radius: float,
    robot_radius: float,
    discomfort_dist: float,
) -> None:
    """Draw human ``h``'s new goal as CrowdNav does, retrying while it is too close to another agent (at most
    1000 tries; the last one stands)."""
    for _ in range(1000):
        angle = _next_random(rng, w) * 2 * np.pi
        gx = circle_radius * np.cos(angle) + (_next_random(rng, w) - 0.5) * human_v_pref[w, h]
        gy = circle_radius * np.sin(angle) + (_next_random(rng, w) - 0.5) * human_v_pref[w, h]
        clear = True
        for r in range(robot_goal.shape[1]):
            min_dist = human_radius[w, h] + robot_radius + discomfort_dist
            if np.hypot(gx - robot_goal[w, r, 0], gy - robot_goal[w, r, 1]) < min_dist:
                clear = False
        for other in range(human_pos.shape[1]):
            if other != h:
                min_dist = human_radius[w, h] + human_radius[w, other] + discomfort_dist
                if (
                    np.hypot(gx - human_pos[w, other, 0], gy - human_pos[w, other, 1]) < min_dist
                    or np.hypot(gx - human_goal[w, other, 0], gy - human_goal[w, other, 1]) < min_dist
                ):
                    clear = False
        if clear:
            break
    human_goal[w, h, 0], human_goal[w, h, 1] = gx, gy


@numba.njit(cache=True, nogil=True)
def _move_and_judge(
    robot_pos: np.ndarray,
    robot_goal: np.ndarray,
    human_pos: np.ndarray,
    human_radius: np.ndarray,
    robot_vel: np.ndarray,
    human_vel: np.ndarray,
    time: np.ndarray,
    done: np.ndarray,
    outcome: np.ndarray,
    event_time: np.ndarray,
    path_length: np.ndarray,
    min_clearance: np.ndarray,
    dt: float,
    robot_radius: float,
    time_limit: float,
    discomfort_dist: float,
    discomfort_factor: float,
    progress_factor: float,
    success_reward: float,
    collision_penalty: float,
    reward: np.ndarray,
) -> None:
    """Robots move, then humans, time advances; each robot's move is judged (collision, success, timeout) and
    rewarded; the state's arrays are updated in place. The float operations are those of the formulas written
    with numpy arrays in the tests, in the same order, so the results are bit-identical to them: closest approach
    along the relative motion of this step, surface distance, discomfort below ``discomfort_dist``, otherwise
    progress towards the goal."""
    worlds, robots, humans = robot_pos.shape[0], robot_pos.shape[1], human_pos.shape[1]
    threshold = time_limit - 1e-9
    before = np.empty((humans, 2))  # a world's humans before their move
    for w in range(worlds):
        for h in range(humans):
            before[h, 0], before[h, 1] = human_pos[w, h, 0], human_pos[w, h, 1]
            human_pos[w, h, 0] = before[h, 0] + human_vel[w, h, 0] * dt
            human_pos[w, h, 1] = before[h, 1] + human_vel[w, h, 1] * dt
        now = time[w] + dt
        time[w] = now
        for r in range(robots):
            x, y = robot_pos[w, r, 0], robot_pos[w, r, 1]
            gx, gy = robot_goal[w, r, 0] - x, robot_goal[w, r, 1] - y
            prev_goal_dist = np.sqrt(gx * gx + gy * gy)
            mx, my = robot_vel[w, r, 0] * dt, robot_vel[w, r, 1] * dt
            nx, ny = x + mx, y + my
            robot_pos[w, r, 0], robot_pos[w, r, 1] = nx, ny
            path_length[w, r] = path_length[w, r] + np.sqrt(mx * mx + my * my)
            clearance = np.inf
            for h in range(humans):
                ax, ay = x - before[h, 0], y - before[h, 1]
                sx, sy = (nx - human_pos[w, h, 0]) - ax, (ny - human_pos[w, h, 1]) - ay
                seg_sq = sx * sx + sy * sy
                t = 0.0
                if seg_sq > 0:
                    t = min(max(-(ax * sx + ay * sy) / seg_sq, 0.0), 1.0)
                cx, cy = ax + t * sx, ay + t * sy
                surface = np.sqrt(cx * cx + cy * cy) - human_radius[w, h] - robot_radius
                clearance = min(clearance, surface)
            gx, gy = robot_goal[w, r, 0] - nx, robot_goal[w, r, 1] - ny
            goal_dist = np.sqrt(gx * gx + gy * gy)
            active = not done[w, r]
            collision = active and clearance < 0
            success = active and not collision and goal_dist < robot_radius
            timeout = active and not collision and not success and now >= threshold
            if not active:
                value = 0.0
            elif collision:
                value = collision_penalty
            elif success:
                value = success_reward
            elif timeout:
                value = 0.0
            elif clearance < discomfort_dist:
                value = (clearance - discomfort_dist) * discomfort_factor * dt
            else:
                value = progress_factor * (prev_goal_dist - goal_dist)
            reward[w, r] = value
            if active:
                min_clearance[w, r] = min(min_clearance[w, r], clearance)
            finished = collision or success or timeout
            if finished:
                outcome[w, r] = COLLISION if collision else SUCCESS if success else TIMEOUT
                event_time[w, r] = now
                done[w, r] = True
