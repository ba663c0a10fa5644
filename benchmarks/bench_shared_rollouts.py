"""A build that the representative scheme dominates, step by step: `foil bundle --jobs 2` of the study in
benchmarks/shared_rollouts/ (three snapshots of the CartPole example's training run, every pair in a pairwise part
and all three in a ranking part, under the N-first and the representative scheme; six representative searches whose
votes use all of their 128 starting states), from an empty folder; with --study, another: highway-env/study.toml
(the shipped highway agents in traffic the highway kernel does not cover, stepped by highway-env itself) or one of
studies/. For each build it prints, per step
(evaluations, searches by scheme, representativeness checks, renders), the job seconds the build's log reports
summed over the step's jobs and the number of jobs, the whole build's wall seconds, and the simulator steps of the
representative searches summed over their run.json files: `sim_steps` (the budget they used) and, where run.json
has it, `vote.played_steps` (the steps its agents newly played for it, counted once per agent).

    nice .venv/bin/python benchmarks/bench_shared_rollouts.py              # the working tree's code (2 to 4 min)
    nice .venv/bin/python benchmarks/bench_shared_rollouts.py --base HEAD  # a revision's first, then after / before
    nice .venv/bin/python benchmarks/bench_shared_rollouts.py --base HEAD --study studies/demo.toml --keep /tmp/demo

With --base REV, REV is checked out into a temporary `git worktree` and built first with PYTHONPATH pointing at it
(its `search` and `app` packages, and the `foil.*` entry points, which name modules, resolve there), then the
working tree; the table's last column is the working tree's over REV's. Each build runs in a fresh copy of
docs/examples/cartpole (the working tree's) with the study file beside it.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "examples" / "cartpole"
STUDY = ROOT / "benchmarks" / "shared_rollouts" / "study.toml"
FOIL = Path(sys.executable).with_name("foil")
STEPS = ("eval", "search", "representativeness", "render")  # how a step's job lines start, in build order
NAMES = {"eval": "evaluations", "representativeness": "representativeness checks", "render": "renders"}
JOB = re.compile(r"(\d+(?:\.\d+)?) s\)? \[\d+/\d+[,\]]")  # a finished job's line: its seconds, then its progress
MORE = re.compile(r" and (\d+) more sharing")  # a job of several searches: "search ... and 5 more sharing its rollouts"


def steps(log: list[str]) -> dict[str, list[tuple[float, int]]]:
    """Each step's jobs in the build's ``log``, searches by scheme ("searches representative"): each job's seconds
    and how many searches (or other things) it ran."""
    found: dict[str, list[tuple[float, int]]] = defaultdict(list)
    for line in log:
        first, *rest = line.split(" ", 2)
        job = JOB.search(line)
        if first not in STEPS or not job:
            continue
        name = f"searches {rest[0]}" if first == "search" else NAMES[first]
        more = MORE.search(line)
        found[name].append((float(job.group(1)), 1 + int(more.group(1)) if more else 1))
    return found


def build(code: Path, folder: Path, jobs: int, study: Path) -> dict:
    """`foil bundle --jobs N` of ``study`` with the code in ``code`` into ``folder``/bundle: a benchmark's own study
    (benchmarks/shared_rollouts/) in a fresh copy of its folder beside the CartPole example's files, a shipped study
    (studies/) from the code's folder. Its steps' job seconds, its wall seconds and the representative searches'
    summed steps."""
    if study.parent.is_relative_to(STUDY.parent):  # a benchmark's own study: from a copy of its folder
        shutil.copytree(EXAMPLE, folder, ignore=shutil.ignore_patterns("__pycache__", "bundle*"))
        shutil.copytree(
            study.parent, folder, ignore=shutil.ignore_patterns("__pycache__", "bundle*"), dirs_exist_ok=True
        )
        where, named = folder, study.name
    else:
        folder.mkdir(parents=True)
        where, named = code, str(study.relative_to(ROOT))
    environment = os.environ | {"PYTHONPATH": str(code), "PYTHONWARNINGS": "ignore"}
    load = os.getloadavg()[0]
    started = time.perf_counter()
    done = subprocess.run(
        [str(FOIL), "bundle", named, "--out", str(folder / "bundle"), "--jobs", str(jobs)],
        cwd=where,
        env=environment,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"the build with {code} failed:\n{done.stdout[-5000:]}")
    print(f"  built in {wall:.1f} s", flush=True)
    records = [json.loads(path.read_text()) for path in (folder / "bundle" / "cache" / "search").glob("*/run.json")]
    representative = [record for record in records if record["solver"]["name"] == "representative"]
    played = [record["vote"].get("played_steps") for record in representative]
    sim_steps = sum(record["sim_steps"] for record in representative)
    return {
        "steps": steps(done.stdout.splitlines()),
        "wall": wall,
        "load": load,
        "sim_steps": sim_steps,
        # each agent's steps: where run.json says none (before rollouts were shared), each step of the pair moved
        # both of its agents
        "agent_steps": sum(played) if None not in played else 2 * sim_steps,
        "bundle": folder / "bundle",
    }


def table(builds: dict[str, dict]) -> list[str]:
    """A Markdown table of the ``builds`` (before, then after), with after / before where there are two."""
    names = list(builds)
    rows: list[tuple[str, list[float | None], list[str]]] = []  # (row, value per build, cell per build)
    for step in dict.fromkeys(name for run in builds.values() for name in run["steps"]):  # in the log's order
        seconds, cells = [], []
        for run in builds.values():
            jobs = run["steps"].get(step, [])
            seconds.append(sum(s for s, _ in jobs))
            ran = sum(n for _, n in jobs)  # more than the jobs where a job ran several searches
            cells.append(f"{seconds[-1]:.1f} s, {len(jobs)}" + (f" ({ran} searches)" if ran != len(jobs) else ""))
        rows.append((f"{step} (job s, jobs)", seconds, cells))
    walls = [run["wall"] for run in builds.values()]
    rows.append(("whole build (wall s)", walls, [f"{w:.1f} s" for w in walls]))
    for key, row in (
        ("sim_steps", "representative searches' budget used (sim_steps)"),
        ("agent_steps", "representative searches' steps played, each agent's"),
    ):
        values = [run[key] for run in builds.values()]
        rows.append((row, values, [f"{v:,}" for v in values]))
    ratio = len(builds) == 2
    lines = [
        "| step | " + " | ".join(names) + (" | after / before |" if ratio else " |"),
        "|---|" + "---:|" * (len(names) + ratio),
    ]
    for row, values, cells in rows:
        line = f"| {row} | " + " | ".join(cells) + " |"
        if ratio:
            before, after = values
            line += f" {after / before:.2f} |" if before and after is not None else " - |"
        lines.append(line)
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", metavar="REV", help="also build with this revision's code, first")
    parser.add_argument("--jobs", type=int, default=2, help="foil bundle --jobs (default: 2)")
    parser.add_argument(
        "--study", type=Path, default=STUDY, help="a study to build instead: one of studies/ (default: the benchmark's)"
    )
    parser.add_argument("--keep", type=Path, help="copy each build's bundle here (before/, after/), to compare them")
    args = parser.parse_args()
    study = args.study.resolve()
    builds: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench-shared-rollouts-") as temporary:
        if args.base:
            commit = subprocess.run(
                ["git", "rev-parse", "--short", f"{args.base}^{{commit}}"],
                cwd=ROOT,
                check=True,
                capture_output=True,
                text=True,
            ).stdout.strip()
            worktree = Path(temporary) / "base"
            subprocess.run(
                ["git", "worktree", "add", "--detach", str(worktree), commit], cwd=ROOT, check=True, capture_output=True
            )
            try:
                print(f"building with {args.base} ({commit}) ...", flush=True)
                builds[f"before: {args.base} ({commit})"] = build(
                    worktree, Path(temporary) / "before", args.jobs, study
                )
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(worktree)], cwd=ROOT, check=True)
        print("building with the working tree ...", flush=True)
        builds["after: working tree" if args.base else "working tree"] = build(
            ROOT, Path(temporary) / "after", args.jobs, study
        )
        if args.keep:
            for name, run in zip(("before", "after"), builds.values(), strict=False):
                shutil.copytree(run["bundle"], args.keep / (name if len(builds) == 2 else "after"), dirs_exist_ok=True)
    loads = ", ".join(f"{run['load']:.1f}" for run in builds.values())
    print(f"\n{study.relative_to(ROOT)}, --jobs {args.jobs}, {os.cpu_count()} cores, load at each start: {loads}\n")
    print("\n".join(table(builds)))


if __name__ == "__main__":
    main()
