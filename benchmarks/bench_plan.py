"""A study's `foil bundle --plan` against its build: the plan's expected wall time per step and in all, the time
making it took, and the build's wall time per step (from each step's first line to its last finished job), from
an empty folder at the same --jobs. Prints a Markdown table for BENCHMARKS.md, with the machine's load average.

    nice .venv/bin/python benchmarks/bench_plan.py studies/demo.toml --jobs 2            # a few minutes
    nice .venv/bin/python benchmarks/bench_plan.py studies/methods-highway.toml --jobs 2 # 15 to 20 minutes

A step's build time runs from the end of the step before it (the first step: from the build's start) to its last
job's line; the evaluations' include the close pairs' more episodes, which the plan does not foresee.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from search.bundle.build import build_bundle, prepare  # noqa: E402
from search.bundle.plan import plan_lines  # noqa: E402
from search.bundle.steps import Cache  # noqa: E402

STEPS = {
    "evaluations": "eval ",
    "searches": "search ",
    "representativeness checks": "representativeness ",
    "clips": "render ",
}  # a step's name in the plan: how its jobs' lines start
FINISHED = re.compile(r"\[\d+/\d+[,\]]")  # a job's line: its progress


def seconds(text: str) -> float:
    """A plan's "about 40 s", "12 min" or "2 h 5 min" in seconds."""
    hours = re.search(r"(\d+) h", text)
    minutes = re.search(r"(\d+) min", text)
    plain = re.search(r"(\d+) s\b", text)
    return sum(float(m.group(1)) * unit for m, unit in ((hours, 3600), (minutes, 60), (plain, 1)) if m)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("study")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-plan-") as folder:
        out = Path(folder) / "bundle"
        started = time.perf_counter()
        plan = plan_lines(prepare(args.study), Cache(out / "cache"), args.jobs)
        planning = time.perf_counter() - started
        print("\n".join(plan), flush=True)
        expected = {line.split(":")[0].strip(): seconds(line.rsplit("about", 1)[1]) for line in plan[1:-1]}

        lines: list[tuple[float, str]] = []
        started = time.perf_counter()

        def log(line: str) -> None:
            lines.append((time.perf_counter() - started, line))
            print(f"{lines[-1][0]:7.1f} {line}", flush=True)

        build_bundle(args.study, out, log=log, workers=args.jobs)
        wall = time.perf_counter() - started
    ends = {
        name: max(t for t, line in lines if line.startswith(prefix) and FINISHED.search(line))
        for name, prefix in STEPS.items()
    }
    took, before = {}, 0.0
    for name, end in ends.items():
        took[name], before = end - before, end
    print(
        f"\n{args.study} at --jobs {args.jobs}, load average {os.getloadavg()[0]:.1f} at the end; "
        f"the plan took {planning:.1f} s\n"
    )
    print("| step | plan | build | plan / build |\n|---|---:|---:|---:|")
    for name, actual in took.items():
        print(f"| {name} | {expected[name]:.0f} s | {actual:.1f} s | {expected[name] / actual:.2f} |")
    total = sum(expected.values())
    print(f"| whole build (wall) | {total:.0f} s | {wall:.1f} s | {total / wall:.2f} |")


if __name__ == "__main__":
    main()
