"""highway-env's ``highway-fast-v0`` for a batch of ``B`` traffic states stepped at once, exactly as highway-env
steps one.

Covered: one straight road of any number of lanes, the ego vehicle with continuous control (acceleration and
steering, ``ContinuousAction``) or meta-actions (``DiscreteMetaAction``), the other vehicles' IDM and MOBIL (with
Foil's environment action: search.highway.adapter), the bicycle model, collisions of the ego, leaving the road,
the Kinematics observation and the reward; a seed places the same traffic as highway-env's ``reset(seed=...)``
(its own generator, drawn from in its order). ``spec_of`` says what is not covered; search.highway.batch and
search.highway.coupled then run highway-env itself, with a one-line notice (``notice``).

Exactness: every step agrees bit for bit with highway-env on the same machine (tests/highway/test_kernel.py;
benchmarks/bench_highway_exact.py over 1,000 episodes), because every value is computed with the same
floating-point operations in the same order:

- numpy evaluates tan, arctan, arcsin and power with its own SIMD routines (SVML on AVX-512), which differ from
  the C library's by an ulp now and then; so every transcendental function is evaluated here by numpy's own
  ufuncs on the same float64 values (vectorised over the batch; numpy's result for a value does not depend on
  the array around it), and numba does the branchy logic with + - * / and sqrt only, which are exact;
- highway-env's two-element ``np.dot`` and ``np.linalg.norm`` go through BLAS, which fuses the last
  multiply-add on FMA hardware; ``FUSED`` probes that once and numba's ``_dot2`` does the same.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
from gymnasium.utils import seeding
from highway_env import utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.envs.common.action import ContinuousAction
from highway_env.envs.highway_env import HighwayEnvFast
from highway_env.road.lane import AbstractLane
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle, MDPVehicle
from highway_env.vehicle.kinematics import Vehicle
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from search.highway.adapter import LANE_THRESHOLD, PERTURBED, SPEED_RANGE, HighwayAdapter

_jit = numba.njit(cache=True, nogil=True)
_inline = numba.njit(cache=True, nogil=True, inline="always")  # helpers of the per-vehicle loops

# highway-env's constants, read from its classes
LENGTH, WIDTH = float(Vehicle.LENGTH), float(Vehicle.WIDTH)
DIAGONAL = float(np.sqrt(Vehicle.LENGTH**2 + Vehicle.WIDTH**2))
MAX_SPEED, MIN_SPEED = float(Vehicle.MAX_SPEED), float(Vehicle.MIN_SPEED)
LANE_WIDTH = float(AbstractLane.DEFAULT_WIDTH)
ROAD_LENGTH = 10000.0  # RoadNetwork.straight_road_network's default
VEHICLE_LENGTH = float(AbstractLane.VEHICLE_LENGTH)  # how far past its ends a lane still holds a vehicle
END = ROAD_LENGTH + VEHICLE_LENGTH
SPEED_LIMIT = 30.0  # HighwayEnv._create_road's
ACC_MAX = float(IDMVehicle.ACC_MAX)
COMFORT_ACC_MAX = float(IDMVehicle.COMFORT_ACC_MAX)
DISTANCE_WANTED = float(IDMVehicle.DISTANCE_WANTED)
TIME_WANTED = float(IDMVehicle.TIME_WANTED)
TWO_SQRT_AB = float(2 * np.sqrt(-IDMVehicle.COMFORT_ACC_MAX * IDMVehicle.COMFORT_ACC_MIN))
POLITENESS = float(IDMVehicle.POLITENESS)
MIN_ACC_GAIN = float(IDMVehicle.LANE_CHANGE_MIN_ACC_GAIN)
MAX_BRAKING_IMPOSED = float(IDMVehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED)
LANE_CHANGE_DELAY = float(IDMVehicle.LANE_CHANGE_DELAY)
MAX_STEERING = float(ControlledVehicle.MAX_STEERING_ANGLE)
PERCEPTION = float(AbstractEnv.PERCEPTION_DISTANCE)
IDM_TYPE = "highway_env.vehicle.behavior.IDMVehicle"
META_ACTIONS = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")  # DiscreteMetaAction.ACTIONS_ALL


@intrinsic
def _fma(typingctx, a, b, c):  # type: ignore[no-untyped-def]
    """a * b + c rounded once (LLVM's fma: the hardware instruction, or the C library's where there is none)."""

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        double = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(double, [double] * 3), "llvm.fma.f64")
        return builder.call(fn, args)

    return types.float64(types.float64, types.float64, types.float64), codegen


def _blas_fuses() -> bool:
    """Whether numpy's BLAS computes a two-element dot product with a fused multiply-add (OpenBLAS does on
    FMA-capable x86): then a0*b0 + a1*b1 is fma(a1, b1, a0*b0)."""
    a, b = np.array([1.0, 1.0 + 2.0**-30]), np.array([-1.0, 1.0 - 2.0**-30])
    return bool(np.dot(a, b) != 0.0)


FUSED = _blas_fuses()


@_inline
def _dot2(a0: float, a1: float, b0: float, b1: float, fused: bool) -> float:
    """numpy's np.dot of two 2-vectors, bit for bit."""
    if fused:
        return _fma(a1, b1, a0 * b0)  # type: ignore[call-arg]
    return a0 * b0 + a1 * b1


@dataclass(frozen=True)
class KernelSpec:
    """The highway-env settings a kernel runs (``spec_of`` reads them from an environment)."""

    lanes: int
    others: int
    density: float
    ego_spacing: float
    initial_lane: int | None
    frames: int  # simulation steps per decision
    dt: float
    duration: float
    time_step: float  # 1 / policy frequency: what env.time advances by per decision
    discrete: bool
    acceleration_range: tuple[float, float]
    steering_range: tuple[float, float]
    clip_action: bool
    target_speeds: tuple[float, ...]
    observed: int
    collision_reward: float
    right_lane_reward: float
    high_speed_reward: float
    on_road_reward: float
    reward_speed_range: tuple[float, float]
    normalize_reward: bool
    offroad_terminal: bool


def spec_of(env) -> KernelSpec | str:
    """The kernel's settings for a highway-env environment (its resolved config), or why the kernel does not
    cover it: only highway-fast-v0 checks the ego's collisions alone, as the kernel does."""
    if type(env.unwrapped) is not HighwayEnvFast:
        return f"the environment {type(env.unwrapped).__name__} (the kernel is highway-fast-v0's)"
    config = env.unwrapped.config
    observation, action = dict(config["observation"]), dict(config["action"])
    if observation.pop("type") != "Kinematics" or set(observation) - {"vehicles_count"}:
        return f"observation {config['observation']} (the kernel has the Kinematics observation's defaults)"
    kind = action.pop("type")
    defaults = {"longitudinal": True, "lateral": True, "dynamical": False, "speed_range": None}
    if kind == "ContinuousAction":
        extra = set(action) - {"acceleration_range", "steering_range", "clip"} - set(defaults)
    elif kind == "DiscreteMetaAction":
        extra = set(action) - {"target_speeds"} - set(defaults)
    else:
        extra = {"type"}
    if extra or any(action.get(key, value) != value for key, value in defaults.items()):
        return f"action {config['action']}"
    others = {
        "other_vehicles_type": IDM_TYPE,
        "controlled_vehicles": 1,
        "manual_control": False,
    }
    for key, value in others.items():
        if config[key] != value:
            return f"{key} {config[key]!r}"
    if int(observation.get("vehicles_count", 5)) < 2:
        return "an observation of the ego alone"
    if config["simulation_frequency"] % config["policy_frequency"]:
        return "a simulation frequency that is not a multiple of the policy frequency"
    ranges = {
        "acceleration_range": ContinuousAction.ACCELERATION_RANGE,
        "steering_range": ContinuousAction.STEERING_RANGE,
    }
    return KernelSpec(
        lanes=int(config["lanes_count"]),
        others=int(config["vehicles_count"]),
        density=config["vehicles_density"],
        ego_spacing=config["ego_spacing"],
        initial_lane=config["initial_lane_id"],
        frames=int(config["simulation_frequency"] // config["policy_frequency"]),
        dt=1 / config["simulation_frequency"],
        duration=config["duration"],
        time_step=1 / config["policy_frequency"],
        discrete=kind == "DiscreteMetaAction",
        acceleration_range=tuple(action.get("acceleration_range") or ranges["acceleration_range"]),  # type: ignore[arg-type]
        steering_range=tuple(action.get("steering_range") or ranges["steering_range"]),  # type: ignore[arg-type]
        clip_action=bool(action.get("clip", True)),
        target_speeds=tuple(float(s) for s in (action.get("target_speeds") or MDPVehicle.DEFAULT_TARGET_SPEEDS)),
        observed=int(observation.get("vehicles_count", 5)),
        collision_reward=config["collision_reward"],
        right_lane_reward=config["right_lane_reward"],
        high_speed_reward=config["high_speed_reward"],
        on_road_reward=config.get("on_road_reward", 0),
        reward_speed_range=tuple(config["reward_speed_range"]),  # type: ignore[arg-type]
        normalize_reward=bool(config["normalize_reward"]),
        offroad_terminal=bool(config["offroad_terminal"]),
    )


def adapter_spec(adapter: HighwayAdapter) -> KernelSpec | str:
    """The kernel's settings for a highway adapter's environment, or why the kernel does not cover it."""
    env = adapter.make()
    spec = spec_of(env)
    env.close()
    return spec


FIELDS = {  # per vehicle, (B, N); vehicle 0 is the ego, the others in highway-env's creation order
    "x": np.float64,
    "y": np.float64,
    "heading": np.float64,
    "speed": np.float64,
    "lane": np.int64,  # the closest lane (lane_index[2])
    "target_lane": np.int64,
    "target_speed": np.float64,
    "own_target_speed": np.float64,  # the target speed before any environment action (Foil's adapter)
    "delta": np.float64,  # IDM's velocity exponent
    "timer": np.float64,
    "crashed": np.bool_,
    "impact_x": np.float64,
    "impact_y": np.float64,
    "impacted": np.bool_,  # an impact is pending (applied, and the vehicle crashed, on its next move)
    "steering": np.float64,  # the stored action (highway-env repeats it, and clip_actions edits it in place)
    "acceleration": np.float64,
}


class HighwayState:
    """B traffic states as plain arrays (FIELDS, and env.time per state): copying one is a snapshot, assigning
    it back a restore."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    lane: np.ndarray
    target_lane: np.ndarray
    target_speed: np.ndarray
    own_target_speed: np.ndarray
    delta: np.ndarray
    timer: np.ndarray
    crashed: np.ndarray
    impact_x: np.ndarray
    impact_y: np.ndarray
    impacted: np.ndarray
    steering: np.ndarray
    acceleration: np.ndarray

    def __init__(self, arrays: dict[str, np.ndarray], time: np.ndarray):
        for name in FIELDS:
            setattr(self, name, arrays[name])
        self.time = time

    @classmethod
    def empty(cls, batch: int, vehicles: int) -> HighwayState:
        return cls({name: np.zeros((batch, vehicles), dtype) for name, dtype in FIELDS.items()}, np.zeros(batch))

    @property
    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in FIELDS}

    def copy(self) -> HighwayState:
        return HighwayState({k: v.copy() for k, v in self.arrays.items()}, self.time.copy())

    def take(self, rows: np.ndarray | list[int]) -> HighwayState:
        return HighwayState({k: v[rows] for k, v in self.arrays.items()}, self.time[rows])

    def assign(self, rows: np.ndarray | list[int], other: HighwayState) -> None:
        for name, values in self.arrays.items():
            values[rows] = getattr(other, name)
        self.time[rows] = other.time

    def equals(self, other: HighwayState) -> bool:
        """Bit for bit (NaN-free states)."""
        same = all(np.array_equal(v, getattr(other, k)) for k, v in self.arrays.items())
        return same and np.array_equal(self.time, other.time)


def _not_zero(x: np.ndarray, eps: float = 1e-2) -> np.ndarray:
    """highway_env.utils.not_zero over an array."""
    return np.where(np.abs(x) > eps, x, np.where(x >= 0, eps, -eps))


def _wrap_to_pi(x: np.ndarray) -> np.ndarray:
    return ((x + np.pi) % (2 * np.pi)) - np.pi


def closest_lanes(x: np.ndarray, y: np.ndarray, heading: np.ndarray, lanes: int) -> np.ndarray:
    """RoadNetwork.get_closest_lane_index on the straight road: L1 distance plus heading, first minimum."""
    angle = 1.0 * np.abs(_wrap_to_pi(heading - 0.0))
    outside = np.where(x - ROAD_LENGTH > 0, x - ROAD_LENGTH, 0.0)
    before = np.where(0 - x > 0, 0 - x, 0.0)
    distances = [((np.abs(y - LANE_WIDTH * k) + outside) + before) + angle for k in range(lanes)]
    return np.argmin(np.stack(distances, axis=-1), axis=-1)


def _clip(x: np.ndarray, low: float, high: float) -> np.ndarray:
    """np.clip without its wrapper's overhead (the same values: no NaN here)."""
    return np.minimum(np.maximum(x, low), high)


def steering_control(state: HighwayState) -> np.ndarray:
    """ControlledVehicle.steering_control of every vehicle towards its target lane (IDMVehicle.act clips it
    again to the same range, which changes nothing)."""
    speed = _not_zero(state.speed)
    lateral = state.y - LANE_WIDTH * state.target_lane
    lateral_speed_command = -ControlledVehicle.KP_LATERAL * lateral
    heading_command = np.arcsin(_clip(lateral_speed_command / speed, -1, 1))
    heading_ref = 0.0 + _clip(heading_command, -np.pi / 4, np.pi / 4)
    heading_rate_command = ControlledVehicle.KP_HEADING * _wrap_to_pi(heading_ref - state.heading)
    slip_angle = np.arcsin(_clip(LENGTH / 2 / speed * heading_rate_command, -1, 1))
    return _clip(np.arctan(2 * np.tan(slip_angle)), -MAX_STEERING, MAX_STEERING)


@_inline
def _neighbours(x: np.ndarray, y: np.ndarray, b: int, i: int, lane: int) -> tuple[int, int]:
    """Road.neighbour_vehicles: the vehicles just ahead of and just behind vehicle i on a lane (-1: none)."""
    s = x[b, i]
    front, rear = -1, -1
    s_front, s_rear = 0.0, 0.0
    for v in range(x.shape[1]):
        if v == i:
            continue
        s_v = x[b, v]
        if not (abs(y[b, v] - LANE_WIDTH * lane) <= LANE_WIDTH / 2 + 1 and -VEHICLE_LENGTH <= s_v < END):
            continue
        if s <= s_v and (front < 0 or s_v <= s_front):
            s_front, front = s_v, v
        if s_v < s and (rear < 0 or s_v > s_rear):
            s_rear, rear = s_v, v
    return front, rear


@_inline
def _desired_gap(
    x: np.ndarray, speed: np.ndarray, cos_h: np.ndarray, sin_h: np.ndarray, b: int, i: int, f: int, fused: bool
) -> float:
    """IDMVehicle.desired_gap (projected)."""
    dvx = speed[b, i] * cos_h[b, i] - speed[b, f] * cos_h[b, f]
    dvy = speed[b, i] * sin_h[b, i] - speed[b, f] * sin_h[b, f]
    dv = _dot2(dvx, dvy, cos_h[b, i], sin_h[b, i], fused)
    return DISTANCE_WANTED + speed[b, i] * TIME_WANTED + speed[b, i] * dv / TWO_SQRT_AB


@_inline
def _acceleration(
    x: np.ndarray,
    speed: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    power: tuple[np.ndarray, np.ndarray, np.ndarray],
    b: int,
    me: int,
    ego: int,
    front: int,
    fused: bool,
) -> float:
    """IDMVehicle.acceleration as vehicle ``me`` computes it for vehicle ``ego`` behind ``front`` (-1: none).
    IDM's power of ego's speed ratio to me's exponent comes from numpy (``_powers``)."""
    if ego < 0:
        return 0.0
    own, table, column = power
    acceleration = COMFORT_ACC_MAX * (1 - (own[b, me] if ego == me else table[column[b, me], ego]))
    if front >= 0:
        d = x[b, front] - x[b, ego]
        if abs(d) <= 1e-2:
            d = 1e-2 if d >= 0 else -1e-2
        gap = _desired_gap(x, speed, cos_h, sin_h, b, ego, front, fused) / d
        acceleration -= COMFORT_ACC_MAX * (gap * gap)
    return acceleration


@_inline
def _mobil(
    x: np.ndarray,
    y: np.ndarray,
    speed: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    lane: np.ndarray,
    power: tuple[np.ndarray, np.ndarray, np.ndarray],
    b: int,
    i: int,
    candidate: int,
    fused: bool,
) -> bool:
    """IDMVehicle.mobil for a vehicle without a route."""
    new_preceding, new_following = _neighbours(x, y, b, i, candidate)
    new_following_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, new_following, new_preceding, fused)
    new_following_pred_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, new_following, i, fused)
    if new_following_pred_a < -MAX_BRAKING_IMPOSED:
        return False
    old_preceding, old_following = _neighbours(x, y, b, i, lane[b, i])
    self_pred_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, i, new_preceding, fused)
    self_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, i, old_preceding, fused)
    old_following_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, old_following, i, fused)
    old_following_pred_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, old_following, old_preceding, fused)
    jerk = (
        self_pred_a
        - self_a
        + POLITENESS * (new_following_pred_a - new_following_a + old_following_pred_a - old_following_a)
    )
    return not jerk < MIN_ACC_GAIN


@_jit
def _decide(
    x: np.ndarray,
    y: np.ndarray,
    speed: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    lane: np.ndarray,
    target_lane: np.ndarray,
    crashed: np.ndarray,
    timer: np.ndarray,
    power: tuple[np.ndarray, np.ndarray, np.ndarray],
    ego_controlled: bool,
    lanes: int,
    fused: bool,
    acceleration: np.ndarray,
) -> None:
    """IDMVehicle.act of every other vehicle, in road order: MOBIL's lane decision (or the abort of a lane
    change someone else is making into the same lane), then IDM's acceleration. Steering comes after (numpy)."""
    n_worlds, n = x.shape
    for b in range(n_worlds):
        for i in range(1, n):
            if crashed[b, i]:
                continue
            if lane[b, i] != target_lane[b, i]:
                for v in range(n):
                    if (
                        v != i
                        and lane[b, v] != target_lane[b, i]
                        and (v > 0 or ego_controlled)
                        and target_lane[b, v] == target_lane[b, i]
                    ):
                        d = x[b, v] - x[b, i]
                        if 0 < d < _desired_gap(x, speed, cos_h, sin_h, b, i, v, fused):
                            target_lane[b, i] = lane[b, i]
                            break
            elif LANE_CHANGE_DELAY < timer[b, i]:
                timer[b, i] = 0.0
                for candidate in (lane[b, i] - 1, lane[b, i] + 1):
                    if candidate < 0 or candidate >= lanes:
                        continue
                    if not (abs(y[b, i] - LANE_WIDTH * candidate) <= 2 * LANE_WIDTH and 0 <= x[b, i] < END):
                        continue
                    if abs(speed[b, i]) < 1:
                        continue
                    if _mobil(x, y, speed, cos_h, sin_h, lane, power, b, i, candidate, fused):
                        target_lane[b, i] = candidate
            front, _ = _neighbours(x, y, b, i, lane[b, i])
            a = _acceleration(x, speed, cos_h, sin_h, power, b, i, i, front, fused)
            if lane[b, i] != target_lane[b, i]:
                front, _ = _neighbours(x, y, b, i, target_lane[b, i])
                target_a = _acceleration(x, speed, cos_h, sin_h, power, b, i, i, front, fused)
                if target_a < a:
                    a = target_a
            acceleration[b, i] = min(max(a, -ACC_MAX), ACC_MAX)


@_inline
def _corners(x: float, y: float, c: float, s: float, out: np.ndarray) -> None:
    """RoadObject.polygon: the rectangle's corners, the first repeated (c, s: cos and sin of the heading). Exact as
    numpy's matrix product computes them: one product of each sum is by WIDTH / 2 = 1, so fusing changes nothing."""
    for m, (px, py) in enumerate(
        ((-LENGTH / 2, -WIDTH / 2), (-LENGTH / 2, WIDTH / 2), (LENGTH / 2, WIDTH / 2), (LENGTH / 2, -WIDTH / 2))
    ):
        out[m, 0] = (c * px + -s * py) + x
        out[m, 1] = (s * px + c * py) + y
    out[4] = out[0]


@_inline
def _project(polygon: np.ndarray, nx: float, ny: float, fused: bool) -> tuple[float, float]:
    """utils.project_polygon."""
    low = high = _dot2(polygon[0, 0], polygon[0, 1], nx, ny, fused)
    for m in range(1, 5):
        projected = _dot2(polygon[m, 0], polygon[m, 1], nx, ny, fused)
        if projected < low:
            low = projected
        if projected > high:
            high = projected
    return low, high


@_inline
def _interval_distance(min_a: float, max_a: float, min_b: float, max_b: float) -> float:
    return min_b - max_a if min_a < min_b else min_a - max_b


@_jit
def _polygons_intersecting(
    a: np.ndarray, b: np.ndarray, move_x: float, move_y: float, fused: bool
) -> tuple[bool, bool, float, float]:
    """utils.are_polygons_intersecting (separating axes, with A's move relative to B's), bit for bit: (are
    intersecting, will intersect, the translation that separates them when they will)."""
    intersecting = will_intersect = True
    min_distance = np.inf
    axis_x = axis_y = 0.0
    for polygon in (a, b):
        for m in range(4):
            nx, ny = -polygon[m + 1, 1] + polygon[m, 1], polygon[m + 1, 0] - polygon[m, 0]
            norm = np.sqrt(_dot2(nx, ny, nx, ny, fused))
            nx, ny = nx / norm, ny / norm
            min_a, max_a = _project(a, nx, ny, fused)
            min_b, max_b = _project(b, nx, ny, fused)
            if _interval_distance(min_a, max_a, min_b, max_b) > 0:
                intersecting = False
            velocity_projection = _dot2(nx, ny, move_x, move_y, fused)
            if velocity_projection < 0:
                min_a += velocity_projection
            else:
                max_a += velocity_projection
            distance = _interval_distance(min_a, max_a, min_b, max_b)
            if distance > 0:
                will_intersect = False
            if not intersecting and not will_intersect:
                break
            if abs(distance) < min_distance:
                min_distance = abs(distance)
                dx = (((a[0, 0] + a[1, 0]) + a[2, 0]) + a[3, 0]) / 4 - (((b[0, 0] + b[1, 0]) + b[2, 0]) + b[3, 0]) / 4
                dy = (((a[0, 1] + a[1, 1]) + a[2, 1]) + a[3, 1]) / 4 - (((b[0, 1] + b[1, 1]) + b[2, 1]) + b[3, 1]) / 4
                axis_x, axis_y = (nx, ny) if _dot2(dx, dy, nx, ny, fused) > 0 else (-nx, -ny)
    if not will_intersect:
        return intersecting, False, 0.0, 0.0
    return intersecting, True, min_distance * axis_x, min_distance * axis_y


@_jit
def _collide(
    x: np.ndarray,
    y: np.ndarray,
    speed: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    dt: float,
    fused: bool,
    crashed: np.ndarray,
    impacted: np.ndarray,
    impact_x: np.ndarray,
    impact_y: np.ndarray,
) -> None:
    """Road.step's collision checks after the moves: in highway-fast only the ego checks its collisions, against
    every other vehicle in road order (RoadObject.handle_collisions: a quick distance test, then the polygons).
    A pair that will intersect gets the separating translation as an impact, half each; intersecting crashes
    both."""
    ego, other = np.empty((5, 2)), np.empty((5, 2))
    for b in range(x.shape[0]):
        for j in range(1, x.shape[1]):
            dx, dy = x[b, j] - x[b, 0], y[b, j] - y[b, 0]
            if np.sqrt(_dot2(dx, dy, dx, dy, fused)) > (DIAGONAL + DIAGONAL) / 2 + speed[b, 0] * dt:
                continue
            _corners(x[b, 0], y[b, 0], cos_h[b, 0], sin_h[b, 0], ego)
            _corners(x[b, j], y[b, j], cos_h[b, j], sin_h[b, j], other)
            move_x = speed[b, 0] * cos_h[b, 0] * dt - speed[b, j] * cos_h[b, j] * dt
            move_y = speed[b, 0] * sin_h[b, 0] * dt - speed[b, j] * sin_h[b, j] * dt
            intersecting, will_intersect, tx, ty = _polygons_intersecting(ego, other, move_x, move_y, fused)
            if will_intersect:
                impact_x[b, 0], impact_y[b, 0] = tx / 2, ty / 2
                impact_x[b, j], impact_y[b, j] = -tx / 2, -ty / 2
                impacted[b, 0] = impacted[b, j] = True
            if intersecting:
                crashed[b, 0] = crashed[b, j] = True


@_jit
def _observe(
    x: np.ndarray,
    y: np.ndarray,
    speed: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    y_range: float,
    fused: bool,
    out: np.ndarray,
) -> None:
    """KinematicObservation (presence, x, y, vx, vy; relative to the ego, normalised and clipped): the ego, then
    the nearest vehicles not more than 2 lengths behind and within the perception distance, by longitudinal
    distance (ties in road order), zeros for the missing."""
    n_worlds, n = x.shape
    observed = out.shape[1]
    order = np.empty(n, np.int64)
    key = np.empty(n)
    ranges = ((-5.0 * 40.0, 5.0 * 40.0), (-y_range, y_range), (-2 * 40.0, 2 * 40.0), (-2 * 40.0, 2 * 40.0))
    row = np.empty(4)
    for b in range(n_worlds):
        out[b] = 0
        count = 0
        for v in range(1, n):
            dx, dy = x[b, v] - x[b, 0], y[b, v] - y[b, 0]
            if np.sqrt(_dot2(dx, dy, dx, dy, fused)) < PERCEPTION and -2 * LENGTH < dx:
                k = count  # insertion sort, stable
                while k > 0 and key[k - 1] > abs(dx):
                    key[k], order[k] = key[k - 1], order[k - 1]
                    k -= 1
                key[k], order[k] = abs(dx), v
                count += 1
        count = min(count, observed - 1)
        for r in range(count + 1):
            v = 0 if r == 0 else order[r - 1]
            row[0], row[1] = x[b, v], y[b, v]
            row[2], row[3] = speed[b, v] * cos_h[b, v], speed[b, v] * sin_h[b, v]
            if r > 0:
                row[0] -= x[b, 0]
                row[1] -= y[b, 0]
                row[2] -= speed[b, 0] * cos_h[b, 0]
                row[3] -= speed[b, 0] * sin_h[b, 0]
            out[b, r, 0] = 1.0
            for f in range(4):
                low, high = ranges[f]
                value = -1 + (row[f] - low) * 2 / (high - low)
                out[b, r, f + 1] = min(max(value, -1.0), 1.0)


class HighwayKernel:
    """B highway-env traffic states stepped together: ``reset`` from seeds, ``apply`` an environment action,
    ``step`` the ego actions; the state is plain arrays (``state``), so snapshots are copies."""

    def __init__(self, spec: KernelSpec, batch: int):
        self.spec, self.batch = spec, batch
        self.state = HighwayState.empty(batch, spec.others + 1)
        self.rngs: list[np.random.Generator | None] = [None] * batch

    # --- reset -----------------------------------------------------------------------------------------------

    def reset(self, seeds: Sequence[int | None] | np.ndarray, rows: np.ndarray | list[int] | None = None) -> np.ndarray:
        """highway-env's reset(seed=...) of each row (all rows by default); a seed of None continues that row's
        generator, as reset() without a seed does. Returns the observations of the reset rows."""
        rows = np.arange(self.batch) if rows is None else np.asarray(rows)
        for b, seed in zip(rows, seeds, strict=True):
            if seed is not None or self.rngs[b] is None:
                self.rngs[b] = seeding.np_random(None if seed is None else int(seed))[0]
            self._place(int(b), self.rngs[b])
        state = self.state
        state.lane[rows] = closest_lanes(state.x[rows], state.y[rows], state.heading[rows], self.spec.lanes)
        state.target_lane[rows] = state.lane[rows]
        if self.spec.discrete:
            speeds = np.array(self.spec.target_speeds)
            state.target_speed[rows, 0] = speeds[_speed_index(speeds, state.target_speed[rows, 0])]
        state.time[rows] = 0
        return self.observe()[rows]

    def _place(self, b: int, rng: np.random.Generator) -> None:
        """HighwayEnv._create_vehicles: Vehicle.create_random's draws from the generator, in their order (its
        choices of road draw nothing: there is one road; ``uniform(low, high)`` is ``low + (high - low) *
        random()``, so the draws are taken as random() and scaled together), then their arithmetic, vectorised.
        Every vehicle is placed ahead of the last one, so the farthest vehicle so far is the last one."""
        spec, state = self.spec, self.state
        n = spec.others + 1
        lanes, draws = np.empty(n, np.int64), np.zeros((n, 3))  # per vehicle: speed, gap, IDM exponent
        integers, random = rng.integers, rng.random
        for v in range(n):
            if v == 0:
                lanes[0] = spec.initial_lane if spec.initial_lane is not None else integers(spec.lanes)
                draws[0, 1] = random()
            else:
                lanes[v] = integers(spec.lanes)
                draws[v] = random(), random(), random()
        low, high = (
            np.array([[0.7 * SPEED_LIMIT, 0.9, IDMVehicle.DELTA_RANGE[0]]]).T,
            np.array([[0.8 * SPEED_LIMIT, 1.1, IDMVehicle.DELTA_RANGE[1]]]).T,
        )
        speeds, gaps, deltas = low + (high - low) * draws.T
        speeds[0], deltas[0] = 25.0, 0.0
        spacing = np.full(n, 1 / spec.density)
        spacing[0] = spec.ego_spacing
        offsets = spacing * (12 + 1.0 * speeds) * np.exp(-5 / 40 * spec.lanes)
        steps = offsets * gaps
        steps[0] += 3 * offsets[0]
        x = np.cumsum(steps)
        y = LANE_WIDTH * lanes
        for values in state.arrays.values():
            values[b] = 0
        state.x[b], state.y[b], state.speed[b], state.delta[b] = x, y, speeds, deltas
        state.target_speed[b] = state.own_target_speed[b] = speeds
        state.timer[b, 1:] = ((x + y) * np.pi)[1:] % LANE_CHANGE_DELAY

    # --- environment action ----------------------------------------------------------------------------------

    def apply(self, env_action: np.ndarray, rows: np.ndarray | list[int] | None = None) -> None:
        """Foil's environment action (search.highway.adapter), (B, PERTURBED, 2) in [-1, 1], on the first
        PERTURBED other vehicles: target speed = own + SPEED_RANGE * [0]; [1] beyond +-LANE_THRESHOLD commands a
        lane change right (+) or left (-) where there is a lane and none is under way."""
        state = self.state
        rows = np.arange(self.batch) if rows is None else np.asarray(rows)
        action = np.asarray(env_action, dtype=np.float64).reshape(len(rows), -1, 2)
        k = min(action.shape[1], PERTURBED, self.spec.others)
        cols = np.arange(1, k + 1)
        grid = np.ix_(rows, cols)
        state.target_speed[grid] = state.own_target_speed[grid] + SPEED_RANGE * action[:, :k, 0]
        lane = state.lane[grid]
        wanted = lane + np.where(action[:, :k, 1] > 0, 1, -1)
        change = (np.abs(action[:, :k, 1]) > LANE_THRESHOLD) & (lane == state.target_lane[grid])
        change &= (wanted >= 0) & (wanted < self.spec.lanes)
        state.target_lane[grid] = np.where(change, wanted, state.target_lane[grid])

    # --- step ------------------------------------------------------------------------------------------------

    def step(
        self, actions: np.ndarray, rows: np.ndarray | list[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """env.step(action) of every state, or of ``rows`` only (the others stay as they are: an episode that
        has ended is not stepped on): (observations (R, V, 5) float32, rewards, terminated, truncated)."""
        if rows is None:
            return self._step(np.asarray(actions))
        rows = np.asarray(rows)
        whole, self.state = self.state, self.state.take(rows)
        try:
            return self._step(np.asarray(actions))
        finally:
            part, self.state = self.state, whole
            self.state.assign(rows, part)

    def _step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        spec, state = self.spec, self.state
        state.time += spec.time_step
        self._ego_act(actions)
        for _ in range(spec.frames):
            self._frame()
        observation = self.observe()
        reward, on_road = self._reward()
        terminated = state.crashed[:, 0] | (spec.offroad_terminal & ~on_road)
        return observation, reward, terminated, state.time >= spec.duration

    def _ego_act(self, actions: np.ndarray) -> None:
        """The action type's act(action), before the first frame."""
        spec, state = self.spec, self.state
        if not spec.discrete:
            if spec.clip_action:
                actions = np.clip(actions, -1, 1)
            state.acceleration[:, 0] = utils.lmap(actions[:, 0], [-1, 1], spec.acceleration_range)
            state.steering[:, 0] = utils.lmap(actions[:, 1], [-1, 1], spec.steering_range)
            return
        names = np.array(META_ACTIONS)[actions.astype(np.int64)]
        speeds = np.array(spec.target_speeds)
        index = _speed_index(speeds, state.speed[:, 0]) + np.where(names == "FASTER", 1, -1)
        index = np.clip(index, 0, speeds.size - 1)
        longitudinal = (names == "FASTER") | (names == "SLOWER")
        state.target_speed[:, 0] = np.where(longitudinal, speeds[index], state.target_speed[:, 0])
        side = np.where(names == "LANE_RIGHT", 1, np.where(names == "LANE_LEFT", -1, 0))
        wanted = np.clip(state.target_lane[:, 0] + side, 0, spec.lanes - 1)
        reachable = (np.abs(state.y[:, 0] - LANE_WIDTH * wanted) <= 2 * LANE_WIDTH) & (0 <= state.x[:, 0])
        reachable &= state.x[:, 0] < END
        state.target_lane[:, 0] = np.where((side != 0) & reachable, wanted, state.target_lane[:, 0])

    def _frame(self) -> None:
        """One simulation step: road.act() (every vehicle decides), road.step(dt) (every vehicle moves, then the
        ego's collisions)."""
        spec, state = self.spec, self.state
        cos_h, sin_h = np.cos(state.heading), np.sin(state.heading)
        power = self._powers()
        _decide(
            state.x,
            state.y,
            state.speed,
            cos_h,
            sin_h,
            state.lane,
            state.target_lane,
            state.crashed,
            state.timer,
            power,
            spec.discrete,
            spec.lanes,
            FUSED,
            state.acceleration,
        )
        steered = ~state.crashed
        if not spec.discrete:
            steered[:, 0] = False
        state.steering[:] = np.where(steered, steering_control(state), state.steering)
        if spec.discrete:
            state.acceleration[:, 0] = ControlledVehicle.KP_A * (state.target_speed[:, 0] - state.speed[:, 0])
        self._move()
        cos_h, sin_h = np.cos(state.heading), np.sin(state.heading)
        _collide(
            state.x,
            state.y,
            state.speed,
            cos_h,
            sin_h,
            spec.dt,
            FUSED,
            state.crashed,
            state.impacted,
            state.impact_x,
            state.impact_y,
        )

    def _powers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """numpy's power of each vehicle's IDM speed ratio to the exponents _decide needs: each vehicle's own
        (own[b, v]), and, for the vehicles that run MOBIL in this frame (their lane-change timer is up), every
        vehicle's to theirs (table[column[b, v], u]: they judge their followers with their own exponent)."""
        state = self.state
        target = np.minimum(np.maximum(state.target_speed, 0), SPEED_LIMIT)
        if not self.spec.discrete:
            target[:, 0] = 0.0  # a Vehicle has no target speed: IDM reads 0
        ratio = np.where(state.speed < 0, 0.0, state.speed) / np.abs(_not_zero(target))
        own = np.power(ratio, state.delta)
        deciders = (state.lane == state.target_lane) & (LANE_CHANGE_DELAY < state.timer) & ~state.crashed
        deciders[:, 0] = False
        rows, vehicles = np.nonzero(deciders)
        column = np.full(ratio.shape, -1, np.int64)
        column[rows, vehicles] = np.arange(len(rows))
        exponents = np.repeat(state.delta[rows, vehicles], ratio.shape[1]).reshape(len(rows), ratio.shape[1])
        return own, np.power(ratio[rows], exponents), column

    def _move(self) -> None:
        """Vehicle.step(dt) of every vehicle (IDMVehicle's timer included)."""
        spec, state = self.spec, self.state
        dt = spec.dt
        state.timer[:, 1:] += dt
        crashed = state.crashed
        state.steering[crashed] = 0
        state.acceleration[crashed] = -1.0 * state.speed[crashed]
        fast, slow = state.speed > MAX_SPEED, state.speed < MIN_SPEED
        limit = np.where(fast, 1.0 * (MAX_SPEED - state.speed), 1.0 * (MIN_SPEED - state.speed))
        acc = state.acceleration
        state.acceleration[:] = np.where(fast & (limit < acc), limit, np.where(slow & (limit > acc), limit, acc))
        beta = np.arctan(1 / 2 * np.tan(state.steering))
        state.x += state.speed * np.cos(state.heading + beta) * dt
        state.y += state.speed * np.sin(state.heading + beta) * dt
        hit = state.impacted
        state.x[hit] += state.impact_x[hit]
        state.y[hit] += state.impact_y[hit]
        state.crashed |= hit
        hit[:] = False
        state.heading += state.speed * np.sin(beta) / (LENGTH / 2) * dt
        state.speed += state.acceleration * dt
        state.lane[:] = closest_lanes(state.x, state.y, state.heading, self.spec.lanes)

    # --- observation and reward --------------------------------------------------------------------------------

    def observe(self) -> np.ndarray:
        """The Kinematics observation of every state, (B, V, 5) float32."""
        state = self.state
        out = np.empty((len(state.x), self.spec.observed, 5))
        y_range = LANE_WIDTH * self.spec.lanes
        _observe(state.x, state.y, state.speed, np.cos(state.heading), np.sin(state.heading), y_range, FUSED, out)
        return out.astype(np.float32)

    def on_road(self) -> np.ndarray:
        """The ego is on its closest lane (Vehicle.on_road)."""
        state = self.state
        x, lateral = state.x[:, 0], state.y[:, 0] - LANE_WIDTH * state.lane[:, 0]
        return (np.abs(lateral) <= LANE_WIDTH / 2) & (-VEHICLE_LENGTH <= x) & (x < END)

    def _reward(self) -> tuple[np.ndarray, np.ndarray]:
        """HighwayEnv._reward: speed, right lane and collision terms, normalised, times on-road."""
        spec, state = self.spec, self.state
        on_road = self.on_road()
        lane = state.target_lane[:, 0] if spec.discrete else state.lane[:, 0]
        forward_speed = state.speed[:, 0] * np.cos(state.heading[:, 0])
        scaled_speed = utils.lmap(forward_speed, spec.reward_speed_range, [0, 1])
        terms = (
            (spec.collision_reward, state.crashed[:, 0].astype(np.float64)),
            (spec.right_lane_reward, lane / max(spec.lanes - 1, 1)),
            (spec.high_speed_reward, np.clip(scaled_speed, 0, 1)),
            (spec.on_road_reward, on_road.astype(np.float64)),
        )
        reward = np.zeros(len(state.x))
        for weight, term in terms:
            reward = reward + weight * term
        if spec.normalize_reward:
            best = spec.high_speed_reward + spec.right_lane_reward
            reward = utils.lmap(reward, [spec.collision_reward, best], [0, 1])
        return reward * on_road.astype(np.float64), on_road


def _speed_index(speeds: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """MDPVehicle.speed_to_index."""
    x = (speed - speeds[0]) / (speeds[-1] - speeds[0])
    return np.clip(np.round(x * (speeds.size - 1)), 0, speeds.size - 1).astype(np.int64)


def notice(reason: str) -> None:
    """The one line that says a highway setting runs in highway-env itself, not in the kernel."""
    print(f"highway kernel: {reason} is not covered; stepping highway-env itself", file=sys.stderr)
