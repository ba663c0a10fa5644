"""CrowdNav_DSRNN's published example model run by `foil eval` in the world of its own config, against the
test result CrowdNav_DSRNN published for it (500 episodes: success 0.90, collision 0.10, timeout 0.00, mean
navigation time 10.06 s, in 102 s on the original code and its machine).

The model folder (CrowdNav_DSRNN's `data/example_model`, with `checkpoints/27776.pt` and `configs/config.py`) comes
from `--model DIR` or the FOIL_CROWDNAV_MODEL variable; without one the benchmark says so and stops. A mean-rate
difference within 0.05 is one that two samples of 500 episodes allow.

    .venv/bin/python benchmarks/bench_crowdnav.py --model DIR [--episodes 500] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from datetime import date
from pathlib import Path

from search.crowd.agents.evaluate import evaluate
from search.crowd.agents.policies import comparison_world, load_policy
from search.crowd.sim.world import WorldConfig

PUBLISHED = {"success_rate": 0.90, "collision_rate": 0.10, "timeout_rate": 0.00, "nav_time_mean": 10.06}
PUBLISHED_WALL_S = 102.0  # the published log's first to last line, original code, its own machine


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--model",
        type=Path,
        default=os.environ.get("FOIL_CROWDNAV_MODEL"),
        help="a CrowdNav_DSRNN model folder (default: FOIL_CROWDNAV_MODEL)",
    )
    args = parser.parse_args()
    if args.model is None:
        print("no CrowdNav_DSRNN model folder given: nothing to measure; pass --model DIR or set FOIL_CROWDNAV_MODEL")
        return 0
    checkpoint = args.model / "checkpoints" / "27776.pt"
    if not checkpoint.is_file():
        print(
            f"no CrowdNav_DSRNN example model at {args.model} (expected checkpoints/27776.pt and configs/config.py):"
            " nothing to measure; put the published model there or pass --model DIR"
        )
        return 0
    started = time.perf_counter()
    policy = load_policy(str(checkpoint))
    config = WorldConfig.from_dict(comparison_world([str(checkpoint)], {}))
    result = evaluate(policy, episodes=args.episodes, seed=args.seed, config=config)
    wall = time.perf_counter() - started
    print(
        f"{date.today()}, {os.cpu_count()} cores {platform.machine()}, load average {os.getloadavg()[0]:.1f}; "
        f"{args.episodes} episodes, seed {args.seed}, model {checkpoint}"
    )
    print(
        f"world from its config: {config.human_num} humans, human v_pref {config.human_v_pref} (randomised: "
        f"{config.randomize_attributes}), goal change chance {config.goal_change_chance} every "
        f"{config.goal_change_interval:g} s, end goal change chance {config.end_goal_change_chance}, "
        f"{config.kinematics}, time limit {config.time_limit:g} s\n"
    )
    print("| measure | published | Foil | difference | allowed | within |")
    print("|---|---:|---:|---:|---:|---|")
    for key, label in (
        ("success_rate", "success rate"),
        ("collision_rate", "collision rate"),
        ("timeout_rate", "timeout rate"),
        ("nav_time_mean", "mean navigation time (s)"),
    ):
        published, found = PUBLISHED[key], result[key]
        allowed = 0.1 * published if key == "nav_time_mean" else 0.05
        print(
            f"| {label} | {published:.2f} | {found:.3f} | {found - published:+.3f} | ±{allowed:.3f} | "
            f"{'yes' if abs(found - published) <= allowed else 'NO'} |"
        )
    print(f"| mean episode reward | (20.87, discounted) | {result['reward_mean']:.2f} | | | |")
    print(
        f"| wall time of the episodes (s) | {PUBLISHED_WALL_S:.0f} | {wall:.1f} | ratio "
        f"{PUBLISHED_WALL_S / wall:.1f}x | | not the same machine |"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
