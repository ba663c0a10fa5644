"""Pairs of snapshots whose test success rates differ by at most a few points: the close-pairs benchmark's agents.

    python benchmarks/close_pairs/pick_pairs.py AGENT... [--scenario FILE] [--episodes 300] [--seed 1] [--jobs 2]

Each candidate is evaluated as `foil eval` evaluates it (the same test episodes for every agent: the crowd's
drawn starting states, a Gymnasium world's reset seeds), at a seed other than the benchmark's ground truth's, so
choosing the pairs does not choose the episodes that judge them. Prints each candidate's success rate and mean
reward, then every pair within ``--points`` success points, with the paired t-test of their rewards.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time

from search.bundle.truth import paired_comparison
from search.core.domain import domain_for
from search.solvers.runner import in_processes


def evaluated(agent: str, episodes: int, seed: int, scenario: str | None) -> dict:
    """One candidate's evaluation with its per-episode rewards (in a worker process)."""
    domain = domain_for([agent], scenario)
    world = domain.agents_settings([agent])
    return domain.evaluate_episodes(agent, episodes, seed, world, scenario)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("agents", nargs="+")
    parser.add_argument("--scenario", help="the scenario or distribution the agents act in (a Gymnasium world)")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--points", type=float, default=5.0, help="the most success points a close pair differs by")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", help="write every evaluation (without per-episode rewards) to this file")
    args = parser.parse_args()
    started = time.perf_counter()
    tasks = {agent: (evaluated, (agent, args.episodes, args.seed, args.scenario)) for agent in args.agents}
    found = dict(in_processes(tasks, args.jobs))
    for agent in args.agents:
        e = found[agent]
        print(f"{agent}: success {e['success_rate']:.3f}, reward {e['reward_mean']:.2f}", flush=True)
    print(f"\npairs within {args.points:g} success points ({args.episodes} episodes, seed {args.seed}):")
    for first, second in itertools.combinations(args.agents, 2):
        a, b = found[first], found[second]
        if abs(a["success_rate"] - b["success_rate"]) * 100 <= args.points + 1e-9:
            c = paired_comparison((first, second), a["episode_rewards"], b["episode_rewards"], looks=1)
            print(
                f"  {first} {a['success_rate']:.3f} - {second} {b['success_rate']:.3f}: reward difference "
                f"{c.difference:+.2f} [{c.ci95[0]:+.2f}, {c.ci95[1]:+.2f}], p {c.p:.2g}"
            )
    print(f"\n{time.perf_counter() - started:.0f} s")
    if args.json:
        rows = {a: {k: v for k, v in e.items() if k != "episode_rewards"} for a, e in found.items()}
        with open(args.json, "w") as out:
            json.dump(rows, out, indent=1)


if __name__ == "__main__":
    main()
