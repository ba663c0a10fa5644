"""Which summary method shows people the better agent: every scheme of a study, judged against the ground truth.

For every scheme of the study file's `[build]` (held to its `[build.budget]`: the same simulator steps and seconds
of clip per question), every scenario and pair of agents its pairwise sets name, and seeds 0..N-1 of the scheme,
the clip `foil bundle` would make is judged as the bundle audits it (`app.visible.audit`: outcomes, times, how far
each got, for a pair of HIGHLIGHTS reels each agent's moments on average) against the ground truth (the higher mean
test reward of `foil eval`). A seed's three clips of a scheme on one scenario rank the agents right when each shows
its pair's better agent as better. The searches never see the ground truth; only this judge does.

    python benchmarks/bench_informativeness.py --study studies/methods.toml [--seeds 20] [--jobs 2] [--out DIR]

Prints a table per study: clips showing the better agent (Wilson 95% interval), worse, tie, rankings right, and
each scheme's mean simulator steps, seconds of clip and wall time per search.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

from app.analysis.statistics import wilson_interval
from search.bundle.clips import clip_audit, shown_summaries
from search.bundle.evaluations import evaluate_agents
from search.bundle.searches import plan_clips, search_job
from search.bundle.steps import Cache
from search.bundle.study import load_study
from search.solvers.runner import Backend, in_processes, run_search, write_outputs


def judge(job, folder: Path, evaluations: dict, world, close: dict | None = None) -> dict:
    """What the clip of a search shows against the ground truth, as the bundle audits it (``close``: the pairs
    compared on more paired episodes, `search.bundle.evaluations.close_pairs`), and what it cost."""
    sources = shown_summaries(job, folder, world)
    summaries = [[json.loads(path.read_text()) for path in paths] for paths in sources]
    first = summaries[0][0]
    if len(summaries) > 1:  # a pair of reels: each agent's moments
        events = ["/".join(s["outcomes"][s["follow"]["leader"]]["event"] for s in reel) for reel in summaries]
    else:
        events = [o["event"] for o in first["outcomes"]]
    shown = [s.get("window", (0, len(s["steps"]))) for reel in summaries for s in reel]
    return clip_audit(job, sources, evaluations, world, close)[2] | {
        "events": events,
        "clip_s": sum(last - first_state for first_state, last in shown) * first["steps"][0]["t"],
        "sim_steps": first["solver"]["budget_used"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, required=True)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, help="keep the searches and verdicts here (default: a temporary folder)")
    parser.add_argument("--schemes", help="only these schemes (comma-separated names of the study's)")
    args = parser.parse_args()
    study = load_study(args.study)
    spec, domain = study.spec, study.domain
    out = args.out or Path(tempfile.mkdtemp(prefix="informativeness-"))
    evaluations = evaluate_agents(study, Cache(out / "cache"), lambda line: None, Backend(workers=args.jobs))
    truth = {name: round(e["reward_mean"], 2) for name, e in evaluations.items()}
    print(f"{args.study}: ground truth (mean test reward): {truth}", flush=True)
    wanted = args.schemes.split(",") if args.schemes else list(spec.schemes)
    clips = [j for j in plan_clips(spec) if "pairwise" in j.parts and j.scheme.name in wanted]
    tasks, where = {}, {}
    for seed in range(args.seeds):
        for job in clips:
            drawn = replace(job, scheme=replace(job.scheme, seed=seed))
            key = (job.scheme.name, job.scenario, job.pair, seed)
            where[key] = (drawn, out / job.scheme.name / f"seed{seed}" / search_job(drawn, study).label)
            tasks[key] = (run_search, (search_job(drawn, study),))
    verdicts: dict[str, list] = defaultdict(list)
    rounds: dict[tuple, list] = defaultdict(list)
    walls: dict[str, list] = defaultdict(list)
    for key, files in in_processes(tasks, args.jobs):
        job, folder = where[key]
        write_outputs(folder, files)
        verdict = judge(job, folder, evaluations, domain.world(job.scenario))
        verdicts[key[0]].append(verdict)
        rounds[key[0], key[1], key[3]].append(verdict["shows"] == "better")
        walls[key[0]].append(json.loads(files["run.json"])["wall_s"])
        pair = "-".join(job.pair)
        print(
            f"  {key[0]:<14} seed {key[3]:>2} {pair:<24} {key[1]:<18} {verdict['shows']:<6} "
            f"{'|'.join(verdict['events']):<30} {verdict['why']}",
            flush=True,
        )
    print(
        f"\n{args.study}: {args.seeds} seeds x every pair; budget {next(iter(spec.schemes.values())).budget:,} "
        f"simulator steps per search; {platform.machine()}, {time.strftime('%Y-%m-%d')}\n"
    )
    print(
        "| scheme | shows the better agent [95% CI] | worse | tie | ranking right [95% CI] | steps per search | "
        "s of clip | wall s per search |"
    )
    print("|---|---|---:|---:|---|---:|---:|---:|")
    rows = []
    for name in wanted:
        found = verdicts[name]
        if not found:
            continue
        better = sum(v["shows"] == "better" for v in found)
        right = [all(r) for (scheme, _, _), r in rounds.items() if scheme == name]
        low, high = wilson_interval(better, len(found)) or (0.0, 1.0)  # never None: found is not empty
        rlow, rhigh = wilson_interval(sum(right), len(right)) or (0.0, 1.0)
        row = {
            "scheme": f"{name} ({spec.schemes[name].solver})",
            "clips": len(found),
            "better": better,
            "worse": sum(v["shows"] == "worse" for v in found),
            "tie": sum(v["shows"] == "tie" for v in found),
            "rankings": len(right),
            "rankings_right": sum(right),
            "sim_steps": sum(v["sim_steps"] for v in found) / len(found),
            "clip_s": sum(v["clip_s"] for v in found) / len(found),
            "wall_s": sum(walls[name]) / len(walls[name]),
        }
        rows.append(row)
        print(
            f"| {row['scheme']} | {better} of {len(found)} ({better / len(found):.0%}) [{low:.0%}, {high:.0%}] | "
            f"{row['worse']} | {row['tie']} | {sum(right)} of {len(right)} ({sum(right) / len(right):.0%}) "
            f"[{rlow:.0%}, {rhigh:.0%}] | {row['sim_steps']:,.0f} | {row['clip_s']:.1f} | {row['wall_s']:.1f} |"
        )
    (out / "rows.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
