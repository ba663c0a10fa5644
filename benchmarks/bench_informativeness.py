"""Which search semantics and reward constants give clips that show the better robot.

For every pair of the shipped agents on the paper's two study scenarios, with several search seeds, the best
summary of an MCTS search is judged the way `foil bundle` audits a clip (`app.visible.audit`: who bumped into a
person, who reached the goal and when, how far the others got) against the ground truth (the higher mean test
reward of `foil eval`). The searches never see the ground truth; only this judge does.

    python benchmarks/bench_informativeness.py [--budget 100000] [--seeds 0,1,2] [--jobs 2] [--out DIR]

Prints one row per setting: clips that show the better robot as better, as worse, and no visible difference.
"""

from __future__ import annotations

import argparse
import itertools
import json
import tempfile
import time
from pathlib import Path

from app.visible import VisibleClip, audit
from search.agents.evaluate import evaluate
from search.agents.policies import load_policy
from search.solvers.runner import SearchJob, run_all

AGENTS = ("lo", "med", "hi")
SCENARIOS = ("paper-bl-tr", "paper-tl-br")
PAPER_CONSTANTS = {"goal_bonus": 100.0, "alpha": 1.0, "beta": 1e4, "horizon_offset": -1e5}
SETTINGS = {
    "all, plain (earlier default)": {"finish": "all"},
    "all, paper code's constants, collision is goal": {"finish": "all", "collision_is_goal": True,
                                                        **PAPER_CONSTANTS},
    "first, plain": {"finish": "first"},
    "first, paper code's constants (paper preset)": {"finish": "first", **PAPER_CONSTANTS},
    "first, paper code's constants, goal needs contrast": {"finish": "first", "goal_needs_contrast": True,
                                                            **PAPER_CONSTANTS},
}


def ground_truth(episodes: int = 500) -> dict[str, float]:
    return {name: evaluate(load_policy(name), episodes, seed=0)["reward_mean"] for name in AGENTS}


def judge(folder: Path, rewards: dict[str, float]) -> dict:
    summary = json.loads((folder / "summary-001.json").read_text())
    agents = [a["name"] for a in summary["agents"]]
    labels = [f"Robot {k + 1}" for k in range(len(agents))]
    better = max(agents, key=rewards.get)
    verdict = audit(VisibleClip.of_summary(summary, agents, labels), labels[agents.index(better)])
    return verdict | {"events": [o["event"] for o in summary["outcomes"]], "end_s": summary["steps"][-1]["t"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=100_000)
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, help="keep the searches here (default: a temporary folder)")
    parser.add_argument("--settings", help="only the settings whose names contain this text")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rewards = ground_truth()
    print("ground truth (mean test reward):", {k: round(v, 2) for k, v in rewards.items()}, flush=True)
    out = args.out or Path(tempfile.mkdtemp(prefix="informativeness-"))
    rows = []
    for name, reward in SETTINGS.items():
        if args.settings and args.settings not in name:
            continue
        jobs = [SearchJob(agents=pair, scenario=scenario, budget=args.budget, seed=seed, top_k=1,
                          reward_settings=reward)
                for pair in itertools.combinations(AGENTS, 2) for scenario in SCENARIOS for seed in seeds]
        started = time.perf_counter()
        folder = out / name.split(" (")[0].replace(", ", "-").replace(" ", "_").replace("'", "")
        # run_all writes one folder per (solver, agents, scenario): one call per seed keeps seeds apart
        verdicts = []
        for seed in seeds:
            seed_jobs = [job for job in jobs if job.seed == seed]
            run_all(seed_jobs, folder / f"seed{seed}", workers=args.jobs, progress=False)
            verdicts += [judge(folder / f"seed{seed}" / job.solver / job.label, rewards) | {"job": job.label,
                                                                                          "seed": seed}
                         for job in seed_jobs]
        counts = {shows: sum(v["shows"] == shows for v in verdicts) for shows in ("better", "worse", "tie")}
        rows.append((name, counts, len(verdicts), time.perf_counter() - started))
        print(f"{name}: {counts} of {len(verdicts)} in {rows[-1][3]:.0f} s", flush=True)
        for v in verdicts:
            print(f"    seed {v['seed']} {v['job']:<28} {v['shows']:<6} ends {v['end_s']:5.2f} s "
                  f"{'/'.join(v['events']):<20} {v['why']}", flush=True)
    print(f"\nMCTS, {args.budget:,} steps per search, seeds {args.seeds}, 3 pairs x 2 scenarios\n")
    print("| setting | shows the better robot | shows it as worse | no visible difference |")
    print("|---|---:|---:|---:|")
    for name, counts, total, _ in rows:
        print(f"| {name} | {counts['better']} of {total} ({counts['better'] / total:.0%}) | {counts['worse']} | "
              f"{counts['tie']} |")


if __name__ == "__main__":
    main()
