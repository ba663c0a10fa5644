"""Is the report's model calibrated? Simulated studies in the demo's and the paper's designs (their conditions,
parts, pairs and scenarios; one clip per scheme, scenario and pair), with participant and clip effects on the
log-odds scale, fitted by the report's model (app/analysis/model.py) beside the pooled test the report used before
(app/analysis/statistics.py, which counts answers as independent).

- no scheme effect (every scheme at the same accuracy): how often each test has p < 0.05;
- an effect: how often the model's 95% intervals of the differences in accuracy between schemes cover the true
  differences, and how often its test finds that the schemes differ (power).

    .venv/bin/python benchmarks/bench_model.py [--studies 500] [--participants 40]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from app.analysis.model import fit_accuracy  # noqa: E402
from app.analysis.power import Assumptions, chance, layout, simulate, tasks  # noqa: E402
from app.analysis.statistics import accuracy_difference  # noqa: E402
from app.survey.study import load_study  # noqa: E402

NULL = {"pairwise": 0.75, "ranking": 0.4}
EFFECT = {"pairwise": (0.85, 0.7, 0.6), "ranking": (0.5, 0.3, 0.2)}


def pooled_p(answers) -> float | None:
    counts: dict[str, list[int]] = {}
    for scheme, correct in zip(answers.scheme, answers.correct, strict=True):
        counts.setdefault(scheme, [0, 0])[1 - correct] += 1
    return accuracy_difference({s: (c, i) for s, (c, i) in counts.items()}).p_value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", type=int, default=500)
    parser.add_argument("--participants", type=int, default=40)
    parser.add_argument("--participant-sd", type=float, default=1.0)
    parser.add_argument("--clip-sd", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    import numpy as np

    print(
        f"{args.studies} simulated studies per row, {args.participants} participants, participant SD "
        f"{args.participant_sd}, clip SD {args.clip_sd} (log odds)\n"
    )
    print(
        "| design | part | clips | df | false positives, model | false positives, pooled | coverage, model "
        "| power, model | ms/fit |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in ("demo", "paper"):
        study = load_study(REPO / "studies" / f"{name}.toml")
        schemes = list(study.design.schemes)
        for task in tasks(study):
            rng = np.random.default_rng(args.seed)
            plan = layout(study, task, args.participants)
            null = Assumptions({s: NULL[task] for s in schemes}, args.participant_sd, args.clip_sd)
            effect = Assumptions(dict(zip(schemes, EFFECT[task], strict=False)), args.participant_sd, args.clip_sd)
            model_hits = pooled_hits = covered = intervals = detected = 0
            df = 0
            started = time.perf_counter()
            for _ in range(args.studies):
                answers = simulate(study, task, plan, null, rng)
                result = fit_accuracy(answers, schemes, chance(study, task))
                df = result.df
                model_hits += result.scheme_p is not None and result.scheme_p < 0.05
                pooled = pooled_p(answers)
                pooled_hits += pooled is not None and pooled < 0.05
                result = fit_accuracy(simulate(study, task, plan, effect, rng), schemes, chance(study, task))
                detected += result.scheme_p is not None and result.scheme_p < 0.05
                for c in result.contrasts:
                    truth = effect.accuracy[c.scheme] - effect.accuracy[c.reference]
                    covered += c.low <= truth <= c.high
                    intervals += 1
            ms = 1000 * (time.perf_counter() - started) / (2 * args.studies)
            print(
                f"| {name} | {task} | {plan.clips} | {df} | {model_hits / args.studies:.3f} | "
                f"{pooled_hits / args.studies:.3f} | {covered / max(intervals, 1):.3f} | "
                f"{detected / args.studies:.3f} | {ms:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
