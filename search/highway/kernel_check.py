"""The kernel stepped beside highway-env itself, compared bit for bit at every step: the check behind the
kernel's exactness (tests/highway/test_kernel.py runs a few episodes, benchmarks/bench_highway_exact.py 1,000).

Each of B episodes runs in a real highway-env environment and in one row of a kernel from the same seed, under
the same ego actions and environment actions, until it ends; every step compares every vehicle's position,
heading, speed, lane, target lane, target speed, lane-change timer and crash, and the observation, reward,
terminated and truncated.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from search.highway.adapter import PERTURBED, HighwayAdapter
from search.highway.kernel import HighwayKernel, spec_of

Driver = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def random_driver(discrete: bool, steering: float = 0.1) -> Driver:
    """Uniform random ego actions (float32, as an agent's): meta-actions, or any acceleration with steering
    within +-``steering`` of its range (wider random steering leaves the road within a step or two)."""

    def act(observations: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        if discrete:
            return rng.integers(0, 5, len(observations))
        scale = np.array([1.0, steering])
        return (rng.uniform(-1, 1, (len(observations), 2)) * scale).astype(np.float32)

    return act


def env_state(env, discrete: bool) -> dict[str, np.ndarray]:
    """A highway-env environment's vehicles as the kernel's per-vehicle fields (the ego first). Fields a vehicle
    lacks (the ego's IDM values; a continuous ego's targets) read as the kernel's."""
    vehicles = env.unwrapped.road.vehicles
    ego = vehicles[0]
    values = {
        "x": [v.position[0] for v in vehicles],
        "y": [v.position[1] for v in vehicles],
        "heading": [v.heading for v in vehicles],
        "speed": [v.speed for v in vehicles],
        "lane": [v.lane_index[2] for v in vehicles],
        "crashed": [v.crashed for v in vehicles],
        "target_lane": [getattr(v, "target_lane_index", ego.lane_index)[2] for v in vehicles],
        "target_speed": [getattr(v, "target_speed", np.nan) for v in vehicles],
        "timer": [getattr(v, "timer", np.nan) for v in vehicles],
    }
    state = {name: np.asarray(column) for name, column in values.items()}
    if not discrete:
        state["target_lane"][0] = -1
        state["target_speed"][0] = np.nan
    state["timer"][0] = np.nan
    return state


@dataclass
class KernelComparison:
    """What a side-by-side run compared, and the first difference found (None: bit for bit)."""

    episodes: int = 0
    steps: int = 0
    crashes: int = 0
    first_difference: str | None = None


def _kernel_view(kernel: HighwayKernel, b: int | np.integer, discrete: bool) -> dict[str, np.ndarray]:
    state = kernel.state
    view = {name: state.arrays[name][b].copy() for name in ("x", "y", "heading", "speed", "lane", "crashed")}
    view["target_lane"] = state.target_lane[b].copy()
    view["target_speed"] = state.target_speed[b].copy()
    view["timer"] = state.timer[b].copy()
    if not discrete:
        view["target_lane"][0] = -1
        view["target_speed"][0] = np.nan
    view["timer"][0] = np.nan
    return view


def _difference(reference: dict[str, np.ndarray], kernel: dict[str, np.ndarray]) -> str | None:
    for name, values in reference.items():
        if not np.array_equal(values, kernel[name], equal_nan=values.dtype.kind == "f"):
            where = np.flatnonzero(~((values == kernel[name]) | (np.isnan(values) & np.isnan(kernel[name]))))
            first = where[0] if len(where) else 0
            return f"{name} of vehicle {first}: highway-env {values[first]!r}, kernel {kernel[name][first]!r}"
    return None


def compare(
    seeds: list[int],
    driver: Driver,
    settings: dict | None = None,
    env_action: str = "uniform",
    rng_seed: int = 0,
) -> KernelComparison:
    """Run one episode per seed in highway-env and in the kernel side by side. ``settings``: the adapter's
    (``discrete = False`` for continuous control, highway-env config keys); ``env_action``: "none", "uniform" (the
    searches' prior) or "extreme" (every entry +-1: every commanded lane change that can happen, speeds at their
    bounds)."""
    adapter = HighwayAdapter(settings)
    discrete = bool(adapter.settings.get("discrete", True))
    envs = [adapter.make() for _ in seeds]
    spec = spec_of(envs[0])
    if isinstance(spec, str):
        raise ValueError(f"the kernel does not cover {spec}")
    kernel = HighwayKernel(spec, len(seeds))
    rng = np.random.default_rng(rng_seed)
    observations = np.stack([env.reset(seed=seed)[0] for env, seed in zip(envs, seeds, strict=True)])
    result = KernelComparison(episodes=len(seeds))
    kernel_observations = kernel.reset(seeds)
    running = np.ones(len(seeds), bool)
    lengths = np.zeros(len(seeds), np.int64)

    def check(b: int | np.integer, what: str) -> bool:
        difference = _difference(env_state(envs[b], discrete), _kernel_view(kernel, b, discrete))
        if difference is None and not np.array_equal(observations[b], kernel_observations[b]):
            difference = f"observation {observations[b].tolist()} != {kernel_observations[b].tolist()}"
        if difference is not None:
            result.first_difference = f"seed {seeds[b]}, {what}: {difference}"
        return difference is None

    if not all(check(b, "after reset") for b in range(len(seeds))):
        return result
    while running.any():
        actions = driver(kernel_observations, rng)
        pushes = None
        if env_action != "none":
            pushes = rng.uniform(-1, 1, (len(seeds), PERTURBED, 2))
            if env_action == "extreme":
                pushes = np.sign(pushes)
            kernel.apply(pushes)
        kernel_observations, rewards, terminated, truncated = kernel.step(actions)
        for b in np.flatnonzero(running):
            if pushes is not None:
                adapter.apply(envs[b], pushes[b])
            observations[b], reward, done, cut, _ = envs[b].step(actions[b])
            lengths[b] += 1
            result.steps += 1
            if not check(b, f"step {lengths[b]}"):
                return result
            if (reward, done, cut) != (rewards[b], terminated[b], truncated[b]):
                result.first_difference = (
                    f"seed {seeds[b]}, step {lengths[b]}: reward/terminated/truncated highway-env "
                    f"{(reward, done, cut)}, kernel {(rewards[b], terminated[b], truncated[b])}"
                )
                return result
            if done or cut:
                running[b] = False
                result.crashes += bool(envs[b].unwrapped.vehicle.crashed)
    for env in envs:
        env.close()
    return result
