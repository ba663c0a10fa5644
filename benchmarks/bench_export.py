"""Export and report of a large synthetic study: time and peak memory for 1,000 and 10,000 participants.

The database is the real schema (migrated SQLite file) filled with participants of the shipped paper study: real
plans (app.survey.plan.build_plan over a bundle of manifest entries), random valid answers to every screen. Each export
runs in a fresh child process so its peak resident memory (ru_maxrss) is its own.

    .venv/bin/python benchmarks/bench_export.py [--participants 1000,10000]
"""

from __future__ import annotations

import argparse
import itertools
import json
import random
import resource
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from sqlalchemy import insert  # noqa: E402

from app.formats import ManifestClip  # noqa: E402
from app.store.database import Database, migrate  # noqa: E402
from app.store.models import Participant, ParticipantPlan, Response  # noqa: E402
from app.survey.assignment import conditions  # noqa: E402
from app.survey.bundle import Bundle  # noqa: E402
from app.survey.plan import build_plan  # noqa: E402
from app.survey.screens import dump_plan  # noqa: E402
from app.survey.study import load_study  # noqa: E402

STUDY = REPO / "studies" / "paper.toml"
RANK = ["lo", "med", "hi"]
WORDS = ["robot", "faster", "collided", "slow", "=SUM(A1)", "-closer", "smooth", "hesitated", "NA", "goal"]


def paper_bundle(study) -> Bundle:
    """Manifest entries for every clip the paper study can show (no files: plans only name clips)."""
    clips = {}
    keys = [
        (s, c, pair)
        for s in study.design.schemes
        for c in study.design.scenarios
        for pair in itertools.combinations(RANK, 2)
    ]
    keys.append((study.example.scheme, study.example.scenario, study.example.agents))
    for n, (scheme, scenario, pair) in enumerate(keys):
        clip_id = f"{scheme}-{scenario}-{pair[0]}-{pair[1]}"
        clips[clip_id] = ManifestClip(
            id=clip_id,
            file=f"clips/{n}.mp4",
            sha256=f"{n:064x}",
            scheme=scheme,
            scenario=scenario,
            agents=list(pair),
            labels=[f"Robot {RANK.index(a) + 1}" for a in pair],
            better=max(pair, key=RANK.index),
        )
    return Bundle(root=REPO, clips=clips, paths={})


def random_answers(screen: dict, rng: random.Random) -> dict:
    labels = [robot["label"] for robot in screen.get("robots", [])]
    answers = {}
    for name in screen.get("questions", []):
        if name == "better":
            answers[name] = rng.choice(labels)
        elif name == "ranking":
            answers[name] = rng.sample(labels, len(labels))
        elif name in ("justification", "explanation"):
            answers[name] = " ".join(rng.choices(WORDS, k=rng.randint(3, 12)))
        else:
            answers[name] = rng.randint(1, 9 if name in ("difficulty", "difference") else 5)
    return answers


def fill(url: str, n: int, seed: int = 0, chunk: int = 500) -> None:
    """Add `n` completed participants with plans and answers to a migrated database."""
    study = load_study(STUDY)
    bundle = paper_bundle(study)
    options = conditions(study)
    rng = random.Random(seed)
    db = Database(url)
    start = datetime(2024, 5, 1, tzinfo=UTC)
    for first in range(0, n, chunk):
        people, plans, responses = [], [], []
        for pid in range(first + 1, min(n, first + chunk) + 1):
            condition = pid % len(options)
            plan = dump_plan(build_plan(study, bundle, options[condition], random.Random(f"{seed}:{pid}")))
            created = start + timedelta(minutes=pid)
            people.append(
                {
                    "id": pid,
                    "code": f"p{pid:06d}",
                    "study": study.study.id,
                    "platform": "mturk",
                    "external_id": f"W{pid}",
                    "status": "completed",
                    "condition": condition,
                    "step": len(plan),
                    "created_at": created,
                    "completed_at": created + timedelta(seconds=rng.randint(300, 1500)),
                }
            )
            plans.append({"participant_id": pid, "plan": plan})
            for step, screen in enumerate(plan):
                responses.append(
                    {
                        "participant_id": pid,
                        "step": step,
                        "kind": screen["kind"],
                        "answers": random_answers(screen, rng),
                        "video_events": [],
                        "plays": 1 if "media" in screen else 0,
                        "client_ms": rng.randint(2000, 60000),
                        "server_ms": rng.randint(2000, 60000),
                        "submitted_at": created + timedelta(seconds=30 * step),
                    }
                )
        with db.writing() as session:
            session.execute(insert(Participant), people)
            session.execute(insert(ParticipantPlan), plans)
            session.execute(insert(Response), responses)
    db.dispose()


def child(url: str, out: str, what: str) -> None:
    """Run one export or report and print its time and this process's peak resident memory."""
    from app.analysis.export_csv import export_study
    from app.analysis.report import render_report, tally_study

    db = Database(url)
    study = load_study(STUDY)
    started = time.perf_counter()
    if what == "export":
        result = export_study(db, study, out)
        rows = result.answers
    else:
        data = tally_study(db, study)
        render_report(data, Path(out))
        rows = data.exclusions.before
    seconds = time.perf_counter() - started
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "peak_mib": peak_mib, "rows": rows}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", default="1000,10000")
    parser.add_argument("--child", nargs=3, metavar=("URL", "OUT", "WHAT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(*args.child)
        return
    print("| participants | rows written | step | time | peak memory (RSS) |\n|---:|---:|---|---:|---:|")
    for n in (int(x) for x in args.participants.split(",")):
        with tempfile.TemporaryDirectory() as folder:
            url = f"sqlite:///{folder}/big.sqlite3"
            migrate(url)
            fill(url, n)
            for what in ("export", "report"):
                output = subprocess.run(
                    [sys.executable, __file__, "--child", url, f"{folder}/{what}", what],
                    check=True,
                    capture_output=True,
                    text=True,
                ).stdout
                result = json.loads(output.strip().splitlines()[-1])
                print(
                    f"| {n:,} | {result['rows']:,} | {what} | {result['seconds']:.1f} s | "
                    f"{result['peak_mib']:.0f} MiB |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
