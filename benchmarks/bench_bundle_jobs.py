"""A Python world's whole bundle at `foil bundle --jobs 1` against `--jobs N` (default: one per core) and, with
--ray, as Ray tasks on a local instance: wall time, speed-up, the world's simulator steps/s, the load on the
machine, whether the bundles are byte-identical, and each build's plan (`--plan`: its expected wall time) against
its wall. Prints a table.

    .venv/bin/python benchmarks/bench_bundle_jobs.py                # --jobs 1 and one per core (a few minutes)
    .venv/bin/python benchmarks/bench_bundle_jobs.py --ray          # and --backend ray

The world is docs/examples/cartpole (CartPole with gusts behind its adapter: a Gymnasium environment stepped in
Python, no batched fast path), its study with the N-first set shown on --scenarios fixed starting states (the
example's scenario with other seeds), so a build has that many N-first searches, a representative search, two
evaluations, one representativeness check and a clip per search. Each build starts from an empty folder.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "examples" / "cartpole"
FOIL = Path(sys.executable).with_name("foil")


def study_folder(folder: Path, scenarios: int) -> None:
    """The example's folder with ``scenarios`` fixed starting states shown in its N-first set."""
    shutil.copytree(EXAMPLE, folder, ignore=shutil.ignore_patterns("__pycache__"))
    base = (folder / "cartpole.toml").read_text()
    names = [f"gusts-{n}.toml" for n in range(1, scenarios + 1)]
    for n, name in enumerate(names, start=1):
        (folder / name).write_text(base.replace("seed = 7", f"seed = {100 + n}"))
    listed = "[" + ", ".join(f'"{name}"' for name in names) + "]"
    design, sets = (folder / "study.toml").read_text().split("[[build.sets]]", 1)
    assert sets.count('scenarios = ["cartpole.toml"]') == 1  # the N-first set's
    sets = sets.replace('scenarios = ["cartpole.toml"]', f"scenarios = {listed}")
    (folder / "study.toml").write_text(design + "[[build.sets]]" + sets)


def foil(folder: Path, arguments: list[str]) -> tuple[float, list[str]]:
    """One `foil` command in ``folder``: its wall time and its output lines."""
    started = time.perf_counter()
    done = subprocess.run(
        [str(FOIL), *arguments],
        cwd=folder,
        capture_output=True,
        text=True,
        env=os.environ | {"PYTHONWARNINGS": "ignore"},
    )
    if done.returncode != 0:
        raise SystemExit(done.stdout[-3000:] + done.stderr[-3000:])
    return time.perf_counter() - started, done.stdout.splitlines()


def build(folder: Path, out: str, arguments: list[str]) -> dict:
    """`foil bundle --plan` and then `foil bundle` from an empty folder: the plan's expected wall time and the time
    it took, the build's wall time, and the load average before and after."""
    load_before = os.getloadavg()
    plan_s, plan = foil(folder, ["bundle", "study.toml", "--out", out, "--plan", *arguments])
    wall_s, _ = foil(folder, ["bundle", "study.toml", "--out", out, *arguments])
    expected = next(line for line in plan if line.startswith("  expected wall time: about "))
    return {
        "arguments": " ".join(arguments),
        "wall_s": round(wall_s, 1),
        "plan_s": round(plan_s, 1),
        "planned": expected.split("about ", 1)[1].split(" (")[0],
        "load": [round(x, 1) for x in (*load_before, *os.getloadavg())],
    }


def bundle_files(out: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.relative_to(out).parts[0] != "cache"
    }


def steps_per_second(out: Path) -> float:
    """The world's simulator steps per second in the build's searches: all their steps over all their time."""
    records = [json.loads(path.read_text()) for path in (out / "cache" / "search").glob("*/run.json")]
    return sum(r["sim_steps"] for r in records) / sum(r["search_wall_s"] for r in records)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="workers (default: one per core)")
    parser.add_argument("--scenarios", type=int, default=8, help="fixed starting states of the N-first set")
    parser.add_argument("--ray", action="store_true", help="also build with --backend ray")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-bundle-") as temporary:
        folder = Path(temporary) / "cartpole"
        study_folder(folder, args.scenarios)
        runs = {"one": build(folder, "one", ["--jobs", "1"])}
        runs["many"] = build(folder, "many", ["--jobs", str(args.jobs)])
        if args.ray:
            runs["ray"] = build(folder, "ray", ["--jobs", str(args.jobs), "--backend", "ray"])
        bundles = {name: bundle_files(folder / name) for name in runs}
        one = bundles["one"]
        clips = len(json.loads((folder / "one" / "manifest.json").read_text())["clips"])
        rate = steps_per_second(folder / "one")
    print(f"CartPole with gusts: {clips} clips, {rate:,.0f} simulator steps/s in the searches, {os.cpu_count()} cores")
    print(
        "| build | wall s | speed-up | plan's estimate | plan took s | same bundle as --jobs 1 | load before, after |"
    )
    print("|---|---:|---:|---:|---:|---|---|")
    for name, run in runs.items():
        same = "yes" if name == "one" or bundles[name] == one else "NO"
        load = f"{run['load'][0]:.1f}, {run['load'][3]:.1f}"
        print(
            f"| {run['arguments']} | {run['wall_s']} | {runs['one']['wall_s'] / run['wall_s']:.2f} | "
            f"{run['planned']} | {run['plan_s']} | {same} | {load} |"
        )


if __name__ == "__main__":
    main()
