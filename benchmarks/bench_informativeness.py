"""Which clip-generation scheme shows people the better robot: the representative solver, MCTS with outcome-contrast
selection, and the paper's preset, judged against the ground truth.

For every pair of the shipped agents and every search seed, each scheme's clip is judged the way `foil bundle`
audits a clip (`app.visible.audit`: who bumped into a person, who reached the goal and when, how far the others
got) against the ground truth (the higher mean test reward of `foil eval`). A seed's three clips of a scheme (on
one scenario) rank the agents right when their visible winners order lo < med < hi as the ground truth does, i.e.
when each shows its pair's better agent as better. The
searches never see the ground truth; only this judge does.

- **paper preset**: MCTS on the paper's two study scenarios with the paper's reading of the reward
  (`finish=first` and its code's constants), the top-1 clip;
- **MCTS, outcome selection**: MCTS on the same scenarios with the default reward, top-30, the clip with the
  largest visible contrast (`select = "contrast"`);
- **representative**: the representative solver on the training distribution, with the same budget.

    python benchmarks/bench_informativeness.py [--budget 100000] [--seeds 20] [--jobs 2] [--out DIR]

Prints a table: clips showing the better robot (Wilson 95% interval), rankings right, and each scheme's mean
simulator steps and wall time per search.
"""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import tempfile
import time
from pathlib import Path

from app.analysis.statistics import wilson_interval
from app.visible import VisibleClip, World, audit
from search.agents.evaluate import evaluate
from search.agents.policies import load_policy
from search.bundle.build import clip_summary
from search.solvers.runner import SearchJob, run_all

AGENTS = ("lo", "med", "hi")
PAPER_SCENARIOS = ("paper-bl-tr", "paper-tl-br")
PAPER_PRESET = {"finish": "first", "goal_bonus": 100.0, "alpha": 1.0, "beta": 1e4, "horizon_offset": -1e5}
SCHEMES = {  # name: (solver, scenarios, reward settings, top-k, clip selection)
    "paper preset, top-1": ("mcts", PAPER_SCENARIOS, PAPER_PRESET, 1, "reward"),
    "MCTS, outcome selection of top-30": ("mcts", PAPER_SCENARIOS, {}, 30, "contrast"),
    "representative (training distribution)": ("representative", ("training",), {}, 1, "reward"),
}


def ground_truth(episodes: int = 500) -> dict[str, float]:
    return {name: evaluate(load_policy(name), episodes, seed=0)["reward_mean"] for name in AGENTS}


def judge(folder: Path, select: str, rewards: dict[str, float]) -> dict:
    summary = json.loads(clip_summary(folder, select, World()).read_text())
    agents = [a["name"] for a in summary["agents"]]
    labels = [f"Robot {k + 1}" for k in range(len(agents))]
    better = max(agents, key=rewards.get)
    verdict = audit(VisibleClip.of_summary(summary, agents, labels), labels[agents.index(better)])
    return verdict | {
        "events": [o["event"] for o in summary["outcomes"]],
        "end_s": summary["steps"][-1]["t"],
        "scenario": summary["scenario"]["name"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=100_000)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--episodes", type=int, default=500, help="evaluation episodes for the ground truth")
    parser.add_argument("--out", type=Path, help="keep the searches and verdicts here (default: a temporary folder)")
    parser.add_argument("--schemes", help="only the schemes whose names contain this text")
    args = parser.parse_args()
    rewards = ground_truth(args.episodes)
    print("ground truth (mean test reward):", {k: round(v, 2) for k, v in rewards.items()}, flush=True)
    out = args.out or Path(tempfile.mkdtemp(prefix="informativeness-"))
    pairs = list(itertools.combinations(AGENTS, 2))
    rows = []
    for name, (solver, scenarios, reward, top_k, select) in SCHEMES.items():
        if args.schemes and args.schemes not in name:
            continue
        verdicts, rankings, steps, walls = [], [], [], []
        for seed in range(args.seeds):
            jobs = [
                SearchJob(
                    agents=pair,
                    scenario=scenario,
                    solver=solver,
                    budget=args.budget,
                    seed=seed,
                    top_k=top_k,
                    reward_settings=reward,
                )
                for scenario in scenarios
                for pair in pairs
            ]
            folder = out / name.split(" ")[0].replace(",", "") / solver / f"seed{seed}"
            study = run_all(jobs, folder, workers=args.jobs, progress=False)
            steps += [job["sim_steps"] for job in study["jobs"]]
            walls += [job["wall_s"] for job in study["jobs"]]
            for scenario in scenarios:
                found = [
                    judge(folder / solver / job.label, select, rewards) | {"seed": seed, "job": job.label}
                    for job in jobs
                    if job.scenario == scenario
                ]
                verdicts += found
                # the three clips rank the agents right exactly when each shows its pair's better agent winning
                rankings.append(all(v["shows"] == "better" for v in found))
                for v in found:
                    print(
                        f"  {name[:14]:<14} seed {seed:>2} {v['job']:<24} {v['shows']:<6} {v['scenario']:<12} "
                        f"ends {v['end_s']:5.2f} s {'/'.join(v['events']):<17} {v['why']}",
                        flush=True,
                    )
        better = sum(v["shows"] == "better" for v in verdicts)
        rows.append(
            {
                "scheme": name,
                "clips": len(verdicts),
                "better": better,
                "worse": sum(v["shows"] == "worse" for v in verdicts),
                "tie": sum(v["shows"] == "tie" for v in verdicts),
                "better_ci": wilson_interval(better, len(verdicts)),
                "rankings": len(rankings),
                "rankings_right": sum(rankings),
                "rankings_ci": wilson_interval(sum(rankings), len(rankings)),
                "sim_steps": sum(steps) / len(steps),
                "wall_s": sum(walls) / len(walls),
            }
        )
        (out / "rows.json").write_text(json.dumps(rows, indent=1))
    print(
        f"\n{args.seeds} seeds x {len(pairs)} pairs, budget {args.budget:,} simulator steps per search; "
        f"{platform.machine()}, {time.strftime('%Y-%m-%d')}\n"
    )
    print(
        "| scheme | shows the better robot [95% CI] | worse | tie | ranking right [95% CI] | "
        "steps per search | wall s per search |"
    )
    print("|---|---|---:|---:|---|---:|---:|")
    for r in rows:
        low, high = r["better_ci"]
        rlow, rhigh = r["rankings_ci"]
        print(
            f"| {r['scheme']} | {r['better']} of {r['clips']} ({r['better'] / r['clips']:.0%}) "
            f"[{low:.0%}, {high:.0%}] | {r['worse']} | {r['tie']} | {r['rankings_right']} of {r['rankings']} "
            f"({r['rankings_right'] / r['rankings']:.0%}) [{rlow:.0%}, {rhigh:.0%}] | {r['sim_steps']:,.0f} | "
            f"{r['wall_s']:.1f} |"
        )


if __name__ == "__main__":
    main()
