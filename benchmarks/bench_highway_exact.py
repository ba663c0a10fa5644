"""The highway kernel against highway-env over 1,000 episodes: every step of every episode compared bit for bit.

    .venv/bin/python benchmarks/bench_highway_exact.py              # 1,000 episodes (about 15 minutes on 2 cores)
    .venv/bin/python benchmarks/bench_highway_exact.py --episodes 80

Eight kinds of run share the episodes: random ego actions (continuous control and meta-actions) and each shipped
agent, under no environment action, the searches' uniform prior, or every entry at +-1 (every commanded lane
change that can happen, target speeds at their bounds), in each shipped scenario's traffic. Each episode runs in a
real highway-env environment and in a kernel row from the same seed (search.highway.kernel_check) until it ends.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from search.gym.agents import load_agent  # noqa: E402
from search.highway.adapter import HighwayAdapter  # noqa: E402
from search.highway.kernel_check import compare, random_driver  # noqa: E402
from search.highway.scenarios import SCENARIOS  # noqa: E402

DENSE, LIGHT, FOUR = (SCENARIOS[name].settings for name in ("highway-dense", "highway-light", "highway-four-lanes"))
RUNS = [  # (ego driver, settings, environment action)
    ("random continuous", {"discrete": False, **DENSE}, "none"),
    ("random continuous", {"discrete": False, **FOUR}, "extreme"),
    ("random meta-actions", LIGHT, "uniform"),
    ("highway-lo", DENSE, "uniform"),
    ("highway-med", LIGHT, "uniform"),
    ("highway-hi", FOUR, "uniform"),
    ("highway-hi", DENSE, "extreme"),
    ("highway-med", {}, "none"),
]


def driver(name: str):
    if name.startswith("random"):
        return random_driver("meta" in name)
    agent = load_agent(name, HighwayAdapter())
    return lambda observations, rng: agent.act(observations)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=25, help="episodes stepped side by side at once")
    args = parser.parse_args()
    per_run = args.episodes // len(RUNS)
    started, total_steps, total_crashes, failures = time.perf_counter(), 0, 0, 0
    print(f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}\n")
    print("| ego | settings | environment action | episodes | steps compared | ego crashes | first difference |")
    print("|---|---|---|---:|---:|---:|---|")
    for k, (name, settings, env_action) in enumerate(RUNS):
        act, steps, crashes, difference = driver(name), 0, 0, None
        for start in range(0, per_run, args.batch):
            seeds = [10_000 * k + s for s in range(start, min(start + args.batch, per_run))]
            result = compare(seeds, act, settings, env_action, rng_seed=k * 1000 + start)
            steps, crashes = steps + result.steps, crashes + result.crashes
            difference = difference or result.first_difference
        failures += difference is not None
        total_steps, total_crashes = total_steps + steps, total_crashes + crashes
        shown = ", ".join(f"{key} {value}" for key, value in settings.items()) or "Foil's defaults"
        print(f"| {name} | {shown} | {env_action} | {per_run} | {steps:,} | {crashes} | {difference or 'none'} |")
    minutes = (time.perf_counter() - started) / 60
    print(
        f"\n{per_run * len(RUNS)} episodes, {total_steps:,} steps compared, {total_crashes} ego crashes, "
        f"{failures} runs with a difference; {minutes:.1f} min, load average {os.getloadavg()[0]:.1f}"
    )
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
