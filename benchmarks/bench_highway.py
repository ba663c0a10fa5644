"""Highway benchmarks: the batched kernel's steps per second against highway-env, the search's simulator steps per
second against Agent Disagreements-style branching, and the highway study's bundle build time.

    .venv/bin/python benchmarks/bench_highway.py                   # kernel and search speed (a few minutes)
    .venv/bin/python benchmarks/bench_highway.py --kernel-only     # the kernel's table alone
    .venv/bin/python benchmarks/bench_highway.py --bundle          # and a fresh build of studies/highway.toml

Kernel: environment steps per second (one ego decision, five simulation steps, observation and reward) of the
kernel (search.highway.kernel) at B = 1, 64 and 256 states per call, against highway-env stepped one environment
at a time, on one core, under the same load: random ego actions and uniform environment actions on the scenario's
traffic, an ended episode reset from a new seed (the kernel resets ended rows). Speeds are per second of this
process's CPU time (time.process_time; everything here runs on one thread), so that other work on a shared
machine slows both sides alike instead of whichever row it happens to overlap.

Speed: coupled simulator steps (one step of every agent's environment under one environment action, the unit of
a search budget) per second of the whole MCTS loop on highway-dense with highway-lo and highway-hi, against the
way Agent Disagreements branches: at every step a deep copy of each agent's environment (the branch) and one
environment stepped at a time, each agent acting on a single observation. Both run in the same process on the
same scenario and agents, with the same budget; the table gives the ratio.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from search.core.rollout import Tracker  # noqa: E402
from search.gym.agents import load_agent  # noqa: E402
from search.gym.problem import GymCoupledProblem  # noqa: E402
from search.highway.adapter import PERTURBED  # noqa: E402
from search.highway.batch import make_batch  # noqa: E402
from search.highway.coupled import KernelCoupledProblem  # noqa: E402
from search.highway.scenarios import SCENARIOS  # noqa: E402
from search.solvers.mcts import MCTSConfig, mcts  # noqa: E402
from search.solvers.reward import RewardConfig  # noqa: E402


def foil_search(agents, scenario, budget: int, batch: int, kernel: bool = False) -> float:
    """Coupled steps per second of MCTS (batched agents, snapshots at tree nodes), over highway-env instances or
    on the kernel (search.highway.coupled)."""
    problem = (KernelCoupledProblem if kernel else GymCoupledProblem)(agents, scenario, RewardConfig())
    tracker = Tracker(budget, 5)
    started = time.perf_counter()
    mcts(problem, tracker, np.random.default_rng(0), MCTSConfig(batch=batch))
    return tracker.steps / (time.perf_counter() - started)


def disagreement_branching(agents, scenario, budget: int) -> float:
    """Coupled steps per second when every step branches by deep copy and steps one environment at a time."""
    adapter = scenario.load_adapter()
    rng = np.random.default_rng(0)
    steps, started = 0, time.perf_counter()
    while steps < budget:
        envs, observations = [], []
        for _ in agents:
            env = adapter.make()
            observation, _ = env.reset(seed=scenario.seed)
            envs.append(env)
            observations.append(observation)
        running = [True] * len(agents)
        while any(running) and steps < budget:
            action = rng.uniform(-1.0, 1.0, adapter.env_action_shape)
            for k, agent in enumerate(agents):
                if not running[k]:
                    continue
                envs[k] = copy.deepcopy(envs[k])  # the branch
                adapter.apply(envs[k], action)
                observations[k], _, terminated, truncated, _ = envs[k].step(agent.act(observations[k][None])[0])
                running[k] = not (terminated or truncated)
            steps += 1
    return steps / (time.perf_counter() - started)


def _drive(rng: np.random.Generator, batch: int) -> tuple[np.ndarray, np.ndarray]:
    """Random ego meta-actions (the world's) and uniform environment actions."""
    ego = rng.integers(0, 5, batch)
    return ego, rng.uniform(-1, 1, (batch, PERTURBED, 2))


def highway_env_speed(scenario, seconds: float) -> float:
    """highway-env's environment steps per second, one environment at a time."""
    adapter = scenario.load_adapter()
    env, rng, seed = adapter.make(), np.random.default_rng(0), 0
    env.reset(seed=seed)
    steps, started = 0, time.process_time()
    while time.process_time() - started < seconds:
        ego, pushes = _drive(rng, 1)
        adapter.apply(env, pushes[0])
        _, _, terminated, truncated, _ = env.step(ego[0])
        steps += 1
        if terminated or truncated:
            seed += 1
            env.reset(seed=seed)
    return steps / (time.process_time() - started)


def kernel_speed(scenario, batch: int, seconds: float) -> float:
    """The kernel's environment steps per second with ``batch`` states per call."""
    kernel = make_batch(batch, scenario.settings)
    rng, seed = np.random.default_rng(0), batch
    kernel.reset(list(range(batch)))
    kernel.step(np.ones(batch, np.int64))  # compiled (numba caches it on disk)
    steps, started = 0, time.process_time()
    while time.process_time() - started < seconds:
        ego, pushes = _drive(rng, batch)
        kernel.apply(pushes)
        _, _, terminated, truncated = kernel.step(ego)
        steps += batch
        ended = np.flatnonzero(terminated | truncated)
        if len(ended):
            kernel.reset(list(range(seed, seed + len(ended))), ended)
            seed += len(ended)
    return steps / (time.process_time() - started)


def kernel_table(scenario_name: str, seconds: float) -> None:
    scenario = SCENARIOS[scenario_name]
    reference = highway_env_speed(scenario, seconds)
    print(f"\nEnvironment steps per CPU second on {scenario_name}, one core ({seconds:.0f} s per row):\n")
    print("| simulator | environment steps per CPU second | vs highway-env |")
    print("|---|---:|---:|")
    print(f"| highway-env, one environment at a time | {reference:,.1f} | 1 |")
    for batch in (1, 64, 256):
        speed = kernel_speed(scenario, batch, seconds)
        print(f"| kernel, B = {batch} | {speed:,.0f} | {speed / reference:,.0f}x |")


def bundle_build() -> float:
    from search.bundle.build import build_bundle

    study = Path(__file__).resolve().parent.parent / "studies" / "highway.toml"
    with tempfile.TemporaryDirectory() as out:
        started = time.perf_counter()
        build_bundle(study, out, log=lambda line: print(f"  {line}", flush=True))
        return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=600, help="coupled steps per measurement (default 600)")
    parser.add_argument("--batch", type=int, default=8, help="MCTS batch (default 8)")
    parser.add_argument(
        "--kernel-budget", type=int, default=20_000, help="coupled steps of the searches on the kernel (default 20000)"
    )
    parser.add_argument("--agents", default="highway-lo,highway-hi")
    parser.add_argument("--scenario", default="highway-dense")
    parser.add_argument("--bundle", action="store_true", help="also time a fresh build of studies/highway.toml")
    parser.add_argument("--kernel-only", action="store_true", help="only the kernel's table")
    parser.add_argument("--seconds", type=float, default=10.0, help="seconds per row of the kernel's table")
    args = parser.parse_args()
    print(f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    kernel_table(args.scenario, args.seconds)
    print(f"(load average {os.getloadavg()[0]:.1f} after the kernel's table)")
    if args.kernel_only:
        return
    scenario = SCENARIOS[args.scenario]
    adapter = scenario.load_adapter()
    agents = [load_agent(name, adapter) for name in args.agents.split(",")]
    reference = disagreement_branching(agents, scenario, args.budget)
    ours = foil_search(agents, scenario, args.budget, args.batch)
    on_kernel = {b: foil_search(agents, scenario, args.kernel_budget, b, kernel=True) for b in (args.batch, 64)}
    load = os.getloadavg()[0]
    print(
        f"\n{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, load average {load:.1f}; {args.agents} on "
        f"{args.scenario}, {args.budget} coupled steps each ({args.kernel_budget} on the kernel)\n"
    )
    print("| method | coupled steps/s | vs Agent Disagreements-style branching |")
    print("|---|---:|---:|")
    print(f"| deep copy at every branch, one environment at a time | {reference:,.1f} | 1.0 |")
    print(f"| Foil MCTS, batch {args.batch} | {ours:,.1f} | {ours / reference:.2f} |")
    for batch, speed in on_kernel.items():
        print(f"| Foil MCTS on the kernel, batch {batch} | {speed:,.1f} | {speed / reference:.1f} |")
    if args.bundle:
        print(f"\nfoil bundle studies/highway.toml from a fresh folder: {bundle_build() / 60:.1f} min")


if __name__ == "__main__":
    main()
