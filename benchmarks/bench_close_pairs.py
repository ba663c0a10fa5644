"""Close pairs: how often the representative clip of two agents within a few success points shows the better one,
is flagged, or misleads without a flag.

For every pair of the study file's pairwise sets (benchmarks/close_pairs/: snapshots of one training run whose
test success rates differ by at most 5 points) and search seeds 0..N-1, the clip `foil bundle` would make with
the study's representative scheme is judged as the bundle judges it: the ground truth is the pair compared
episode by episode on the same starting states, on more paired episodes while undecided
(`search.bundle.evaluations.close_pairs`); the clip's audit says whether it shows the better agent (`judge` of
bench_informativeness.py). A clip is **flagged** when the bundle warns of it without looking at the clip: the
ground truth is undecided, or the solver's vote is weak or favours the agent the ground truth ranks worse
(`search.bundle.clips.vote_warnings`). A clip that does not show the better agent and is not flagged misleads
unflagged.

    python benchmarks/bench_close_pairs.py --study benchmarks/close_pairs/crowd.toml [--seeds 20] [--jobs 2]
    python benchmarks/bench_close_pairs.py --study benchmarks/close_pairs/cartpole.toml \\
        --folder docs/examples/cartpole [--seeds 20] [--jobs 2]

``--folder``: the folder a Gymnasium study runs from (its adapter's module and scenario files). Prints a table per
pair: success rates, the paired ground truth, clips showing the better agent, the worse or neither (Wilson 95%
intervals), the share flagged and misleading unflagged, votes decided, mean simulator steps and wall time per
search. The same study and seeds give the same clips and verdicts.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from bench_informativeness import judge

from app.analysis.statistics import wilson_interval
from app.formats import load_summary
from search.bundle.clips import clip_vote, shown_summaries, vote_warnings
from search.bundle.evaluations import better_agent, close_pairs, evaluate_agents, evaluate_runs, shown_pairs
from search.bundle.searches import plan_clips, search_job
from search.bundle.steps import Cache
from search.bundle.study import load_study
from search.bundle.truth import LOOKS, PairedComparison, paired_comparison
from search.solvers.runner import Backend, run_search, write_outputs


def classify(shows: str, undecided: bool, warnings: list[str]) -> dict:
    """A clip's verdict: flagged when the bundle warns of it without its audit (an undecided ground truth, a weak
    vote or one against the truth), misleading unflagged when it does not show the better agent and is not
    flagged."""
    flagged = undecided or bool(warnings)
    return {"flagged": flagged, "misleading_unflagged": shows != "better" and not flagged}


def share(count: int, total: int) -> str:
    """``count of total (share) [Wilson 95% interval]``."""
    low, high = wilson_interval(count, total) or (0.0, 1.0)
    return f"{count} of {total} ({count / total:.0%}) [{low:.0%}, {high:.0%}]"


def tally(verdicts: list[dict]) -> dict:
    """One pair's counts over its seeds: clips showing the better agent, the worse, neither; flagged; misleading
    unflagged; votes decided and for the better agent; mean steps and wall seconds per search."""
    n = len(verdicts)
    return {
        "clips": n,
        "better": sum(v["shows"] == "better" for v in verdicts),
        "worse": sum(v["shows"] == "worse" for v in verdicts),
        "tie": sum(v["shows"] == "tie" for v in verdicts),
        "flagged": sum(v["flagged"] for v in verdicts),
        "misleading_unflagged": sum(v["misleading_unflagged"] for v in verdicts),
        "votes_decided": sum(v["vote_decided"] for v in verdicts),
        "votes_for_better": sum(v["vote_for"] == "better" for v in verdicts),
        "sim_steps": sum(v["sim_steps"] for v in verdicts) / n,
        "wall_s": sum(v["wall_s"] for v in verdicts) / n,
    }


def verdict(job, folder: Path, evaluations: dict, world, close: dict) -> dict:
    """What a search's clip shows (the bundle's audit), its vote, and whether the bundle would flag it."""
    found = judge(job, folder, evaluations, world, close)
    order = sorted(range(2), key=lambda k: job.numbers[k])
    agents = [job.pair[k] for k in order]
    vote = clip_vote(dict(load_summary(shown_summaries(job, folder, world)[0][0])), order)
    better = better_agent(job.pair, evaluations, close)
    undecided = any(set(c.agents) == set(job.pair) and not c.decided for c in close.values())
    warnings = vote_warnings(agents, None if undecided else better, vote)
    for_better, for_worse = (
        (vote["won"][agents.index(better)], vote["won"][1 - agents.index(better)]) if vote else (0, 0)
    )
    # the vote leans by its states' summed weight (on-screen order), a vote before the weights by its counts
    lean = float(for_better - for_worse)
    if vote is not None and "weight" in vote:
        lean = vote["weight"] if agents[0] == better else -vote["weight"]
    return (
        found
        | classify(found["shows"], undecided, warnings)
        | {
            "vote": f"{for_better}-{for_worse} ({vote['no_majority'] if vote else 0})",
            "vote_for": "better" if lean > 0 else "worse" if lean < 0 else "neither",
            "vote_decided": bool(vote and vote["decided"]),
            "warnings": warnings,
        }
    )


def ground_truth(pair, evaluations: dict, close: dict) -> PairedComparison:
    """The pair's paired comparison as the bundle ends it: the close pairs' last look, else the study's episodes
    (the first look of `compare_pairs`, at its level)."""
    for comparison in close.values():
        if set(comparison.agents) == set(pair):
            return comparison
    first, second = (evaluations[a]["episode_rewards"] for a in pair)
    return paired_comparison(pair, first, second, LOOKS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, required=True)
    parser.add_argument("--folder", type=Path, help="run from this folder (a Gymnasium study's adapter and scenarios)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--scheme", default="representative", help="the study's scheme to judge")
    parser.add_argument("--out", type=Path, help="keep the evaluations, searches and verdicts here")
    args = parser.parse_args()
    study = args.study.resolve()
    out = (args.out or Path(tempfile.mkdtemp(prefix="close-pairs-"))).resolve()
    if args.folder:
        os.chdir(args.folder)
    started = time.perf_counter()
    resolved = load_study(study)
    spec, domain = resolved.spec, resolved.domain
    cache, backend = Cache(out / "cache"), Backend(workers=args.jobs)
    jobs = [j for j in plan_clips(spec) if "pairwise" in j.parts and j.scheme.name == args.scheme]
    pairs = shown_pairs(jobs)
    with backend.session():
        evaluations = evaluate_agents(resolved, cache, print, backend)
        close = close_pairs(resolved, pairs, evaluations, cache, print, backend)
        truth = {pair: ground_truth(pair, evaluations, close) for pair in pairs}
        last = sorted({(agent, truth[pair].episodes) for pair in pairs for agent in pair})
        runs = evaluate_runs(resolved, cache, lambda line: None, last, backend)  # each look's, cached
        truth_s = time.perf_counter() - started
        tasks, where = {}, {}
        for seed in range(args.seeds):
            for job in jobs:
                drawn = replace(job, scheme=replace(job.scheme, seed=seed))
                search = search_job(drawn, resolved)
                where[job.pair, seed] = (drawn, out / args.scheme / f"seed{seed}" / search.label)
                tasks[job.pair, seed] = (run_search, (search,))
        verdicts: dict[tuple[str, str], list[dict]] = {pair: [] for pair in pairs}
        for key, files in backend.run(tasks):
            job, folder = where[key]
            write_outputs(folder, files)
            found = verdict(job, folder, evaluations, domain.world(job.scenario), close)
            found |= {"seed": key[1], "wall_s": json.loads(files["run.json"])["wall_s"]}
            verdicts[key[0]].append(found)
            print(
                f"  seed {key[1]:>2} {' vs '.join(Path(a).stem for a in key[0]):<40} {found['shows']:<6} "
                f"vote {found['vote']:<10} {'flagged' if found['flagged'] else '':<8}{found['why']}",
                flush=True,
            )
    wall = time.perf_counter() - started
    print(
        f"\n{study.name}: {args.seeds} seeds per pair, scheme {args.scheme} "
        f"({spec.schemes[args.scheme].budget:,} steps); {platform.machine()}, {time.strftime('%Y-%m-%d')}; "
        f"ground truth {truth_s / 60:.1f} min, all {wall / 60:.1f} min\n"
    )
    print(
        "| pair (first - second) | success [95% CI] | paired difference in reward [simultaneous 95% CI], episodes | "
        "shows the better agent [95% CI] | worse | neither | flagged [95% CI] | misleading unflagged [95% CI] | "
        "votes decided, for the better | steps per search | wall s per search |"
    )
    print("|---|---|---|---|---:|---:|---|---|---|---:|---:|")
    rows = []
    for pair in pairs:
        row, comparison = tally(verdicts[pair]), truth[pair]
        rates = []
        for agent in pair:
            e = runs[agent, comparison.episodes]
            low, high = wilson_interval(round(e["success_rate"] * e["episodes"]), e["episodes"]) or (0.0, 1.0)
            rates.append(f"{e['success_rate']:.3f} [{low:.3f}, {high:.3f}]")
        low, high = comparison.ci95
        decided = "decided" if comparison.decided else "undecided"
        better = Path(better_agent(pair, evaluations, close)).stem
        print(
            f"| {' - '.join(Path(a).stem for a in pair)} | {' / '.join(rates)} | {comparison.difference:+.2f} "
            f"[{low:+.2f}, {high:+.2f}], {comparison.episodes}, {decided} (better: {better}) | "
            f"{share(row['better'], row['clips'])} | {row['worse']} | {row['tie']} | "
            f"{share(row['flagged'], row['clips'])} | {share(row['misleading_unflagged'], row['clips'])} | "
            f"{row['votes_decided']}, {row['votes_for_better']} | {row['sim_steps']:,.0f} | {row['wall_s']:.1f} |"
        )
        rows.append(
            row | {"pair": list(pair), "success": rates, "truth": comparison.to_manifest(), "verdicts": verdicts[pair]}
        )
    (out / f"{args.scheme}.json").write_text(json.dumps(rows, indent=1))
    print(f"\n{out / args.scheme}.json")


if __name__ == "__main__":
    main()
