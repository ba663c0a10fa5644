"""Is the report's model calibrated? A battery of simulated studies, each fitted by the report's model
(app/analysis/model.py), 500 with no scheme effect and 500 with one per row (by default):

- designs written here, apart from `foil power`'s simulator: every participant answers every clip of every
  scheme (in a random order), answers right with probability expit(scheme + participant effect + clip effect),
  with participant and clip standard deviations, accuracies (over participants and clips), numbers of clips per
  scheme (3 against 12, 1 against 12, 3 schemes with 3, 6 and 12), numbers of participants and dropout (half
  the participants leave after 2 to 4 answers) varied row by row;
- the shipped studies' own designs (demo, paper, methods; both parts): who answers which clip as `foil power`
  lays it out; pairwise answers from `foil power`'s simulator; each ranking drawn here as a person would rank: each
  robot's quality seen with noise (Thurstone), the clearer the larger the scheme's, participant's and clip's
  discriminability exp(scheme + participant effect + clip effect), and analysed as the report does, by its
  pairwise orderings (the accuracies of a ranking row are those of its orderings).

Per row: the share of null studies whose primary test (the schemes differ) has p < 0.05, with its Monte Carlo
95% interval (Wilson); with three schemes or more, the share of null studies with any Holm-adjusted pairwise
contrast below 0.05 (family-wise); the coverage of the 95% intervals of the differences between schemes (effect
studies) and of each scheme's accuracy (null studies); the share of tests the model declares untestable; power.

    .venv/bin/python benchmarks/bench_model.py [--studies 500] [--jobs 2] [--rows NAME,...]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from app.analysis.design import chance  # noqa: E402
from app.analysis.model import Answers, ModelResult, fit_accuracy  # noqa: E402
from app.analysis.simulation import Assumptions, layout, log_odds_for, simulate  # noqa: E402
from app.analysis.statistics import wilson_interval  # noqa: E402
from app.survey.study import load_study  # noqa: E402


@dataclass(frozen=True)
class Row:
    name: str
    clips: tuple[int, ...] = (6, 6)  # per scheme
    participants: int = 40
    participant_sd: float = 1.0
    clip_sd: float = 0.5
    accuracy: float = 0.75  # every scheme's, under no effect
    effect: tuple[float, ...] = (0.75, 0.9)  # per scheme, under an effect (the last repeated)
    dropout: bool = False
    study: str = ""  # a shipped study's design instead of the clips above
    task: str = "pairwise"
    extra: dict[str, float] = field(default_factory=dict)


ROWS = [
    Row("balanced, SD 0.5 / 0.3", participant_sd=0.5, clip_sd=0.3),
    Row("balanced, SD 1.5 / 0.3", participant_sd=1.5, clip_sd=0.3),
    Row("balanced, SD 0.5 / 1.0", participant_sd=0.5, clip_sd=1.0),
    Row("balanced, SD 1.5 / 1.0", participant_sd=1.5, clip_sd=1.0),
    Row("balanced, 12 participants", participants=12),
    Row("balanced, 60 participants", participants=60),
    Row("balanced, 240 participants", participants=240),
    Row("balanced, 90% accuracy", accuracy=0.9, effect=(0.8, 0.95)),
    Row("balanced, half drop out after 2-4", dropout=True),
    Row("3 clips against 12", clips=(3, 12)),
    Row("3 against 12, clip SD 1.0", clips=(3, 12), clip_sd=1.0),
    Row("1 clip against 12", clips=(1, 12)),
    Row("3 schemes, 3 / 6 / 12 clips", clips=(3, 6, 12), effect=(0.6, 0.75, 0.9)),
    Row("demo, pairwise", study="demo", task="pairwise", effect=(0.85, 0.7, 0.6)),
    Row("demo, ranking", study="demo", task="ranking", effect=(0.85, 0.75, 0.65)),
    Row("paper, pairwise", study="paper", task="pairwise", effect=(0.85, 0.7)),
    Row("paper, ranking", study="paper", task="ranking", effect=(0.85, 0.7)),
    Row("methods, pairwise", study="methods", task="pairwise", effect=(0.6, 0.65, 0.9, 0.75, 0.75)),
    Row("methods, ranking", study="methods", task="ranking", effect=(0.65, 0.7, 0.9, 0.8, 0.8)),
]


def synthetic(row: Row, accuracies: list[float], rng) -> Answers:
    """One study of a design written here: every participant answers every clip (shuffled order)."""
    from scipy import special

    sd = math.hypot(row.participant_sd, row.clip_sd)
    eta = [log_odds_for(a, sd) for a in accuracies]
    clips = [(s, c) for s, n in enumerate(row.clips) for c in range(n)]
    clip_effect = rng.normal(0, row.clip_sd, len(clips))
    columns: dict[str, list] = {k: [] for k in ("participant", "clip", "scheme", "scenario", "pair", "correct")}
    for p in range(row.participants):
        person = rng.normal(0, row.participant_sd)
        order = rng.permutation(len(clips))
        if row.dropout and p % 2:
            order = order[: rng.integers(2, 5)]
        for k in order:
            s, c = clips[k]
            right = rng.random() < special.expit(eta[s] + person + clip_effect[k])
            for name, value in zip(columns, (f"p{p}", f"s{s}c{c}", f"s{s}", "one", "", int(right)), strict=True):
                columns[name].append(value)
    return Answers(**columns)


def ordering_accuracy(eta: float, sd: float, agents: int) -> float:
    """A Thurstone ranking's share of right pairwise orderings, over participants and clips: robots' true
    qualities k - 1, ..., 0 times the discriminability exp(eta + effect), each seen with standard normal noise."""
    import numpy as np
    from scipy import stats

    nodes, weights = np.polynomial.hermite_e.hermegauss(40)
    gaps = [j - i for i in range(agents) for j in range(i + 1, agents)]
    scale = np.exp(eta + sd * nodes)
    return float(np.mean([stats.norm.cdf(g * scale / math.sqrt(2)) @ weights / weights.sum() for g in gaps]))


def rankings(row: Row, study, plan, accuracies: list[float], rng) -> Answers:
    """One study's rankings in the layout's design, as pairwise orderings (the report's ranking model)."""
    import numpy as np
    from scipy import optimize

    agents = next(len(part.agents) for part in study.parts if part.kind == "ranking")
    sd = math.hypot(row.participant_sd, row.clip_sd)
    eta = [optimize.brentq(lambda e, a=a: ordering_accuracy(e, sd, agents) - a, -8.0, 8.0) for a in accuracies]
    person = rng.normal(0, row.participant_sd, plan.participant_index.max() + 1)
    clip = rng.normal(0, row.clip_sd, plan.clips)
    columns: dict[str, list] = {k: [] for k in ("participant", "clip", "scheme", "scenario", "pair", "correct")}
    for r in range(len(plan.participant_index)):
        scale = np.exp(eta[plan.scheme_index[r]] + person[plan.participant_index[r]] + clip[plan.clip_index[r]])
        seen = np.arange(agents)[::-1] * scale + rng.normal(0, 1, agents)
        for i in range(agents):
            for j in range(i + 1, agents):
                values = (plan.answers.participant[r], plan.answers.clip[r], plan.answers.scheme[r],
                          plan.answers.scenario[r], "", int(seen[i] > seen[j]))  # fmt: skip
                for name, value in zip(columns, values, strict=True):
                    columns[name].append(value)
    return Answers(**columns)


def studies_of(row: Row, effect: bool, count: int, seed: int) -> list[tuple[ModelResult, list[str], list[float]]]:
    """`count` fitted studies of the row, with the schemes and their true accuracies."""
    import numpy as np

    rng = np.random.default_rng([seed, int(effect)])
    if row.study:
        study = load_study(REPO / "studies" / f"{row.study}.toml")
        schemes = list(study.design.schemes)
        truth = [row.effect[min(i, len(row.effect) - 1)] if effect else row.accuracy for i in range(len(schemes))]
        plan = layout(study, row.task, row.participants)
        assume = Assumptions(dict(zip(schemes, truth, strict=True)), row.participant_sd, row.clip_sd)
        level = chance(study, row.task) if row.task == "pairwise" else 0.5
        draws = (
            simulate(study, row.task, plan, assume, rng)
            if row.task == "pairwise"
            else rankings(row, study, plan, truth, rng)
            for _ in range(count)
        )
    else:
        schemes = [f"s{s}" for s in range(len(row.clips))]
        truth = [row.effect[min(i, len(row.effect) - 1)] if effect else row.accuracy for i in range(len(schemes))]
        level = 0.5
        draws = (synthetic(row, truth, rng) for _ in range(count))
    return [(fit_accuracy(answers, schemes, level), schemes, truth) for answers in draws]


def measure(row: Row, count: int, seed: int) -> dict[str, float]:
    started = time.perf_counter()
    found: dict[str, float] = dict.fromkeys(
        ("null", "tested", "familywise", "fw_tested", "covered", "intervals", "acc_covered", "acc_intervals",
         "untestable", "contrasts", "power", "df"),
        0.0,
    )  # fmt: skip
    for result, schemes, truth in studies_of(row, False, count, seed):
        if result.scheme_p is not None:
            found["tested"] += 1
            found["null"] += result.scheme_p < 0.05
            found["df"] += result.df
        secondary = [c.p_holm for c in result.contrasts if c.p_holm is not None]
        if len(schemes) > 2 and secondary:
            found["fw_tested"] += 1
            found["familywise"] += min(secondary) < 0.05
        for e in result.schemes:
            if e.low is not None and e.high is not None:
                found["acc_intervals"] += 1
                found["acc_covered"] += e.low <= truth[schemes.index(e.scheme)] <= e.high
    for result, schemes, truth in studies_of(row, True, count, seed):
        found["power"] += result.scheme_p is not None and result.scheme_p < 0.05
        for c in result.contrasts:
            found["contrasts"] += 1
            if c.low is None or c.high is None:
                found["untestable"] += 1
                continue
            difference = truth[schemes.index(c.scheme)] - truth[schemes.index(c.reference)]
            found["intervals"] += 1
            found["covered"] += c.low <= difference <= c.high
    found["seconds"] = time.perf_counter() - started
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", type=int, default=500, help="null and effect studies per row, each")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rows", default="", help="row names separated by semicolons (default: all)")
    args = parser.parse_args()
    rows = [r for r in ROWS if not args.rows or r.name in args.rows.split(";")]
    chunks = max(1, args.jobs * 2)
    sizes = [args.studies // chunks + (i < args.studies % chunks) for i in range(chunks)]
    print(f"{args.studies} null and {args.studies} effect studies per row (seed {args.seed})\n")
    print(
        "| design | participants | SD participant / clip | false positives (primary) [95%] | tested | "
        "family-wise (Holm) | coverage, differences | coverage, accuracies | untestable contrasts | power | "
        "mean df | s |"
    )
    print("|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    with ProcessPoolExecutor(args.jobs) as pool:
        for row in rows:
            parts = list(pool.map(measure, [row] * chunks, sizes, [args.seed * 1000 + i for i in range(chunks)]))
            total = {key: sum(p[key] for p in parts) for key in parts[0]}
            tested = int(total["tested"])
            low, high = wilson_interval(int(total["null"]), tested) or (math.nan, math.nan)
            rate = total["null"] / tested if tested else math.nan

            def share(a: str, b: str, t: dict[str, float] = total) -> str:
                return f"{t[a] / t[b]:.3f}" if t[b] else "-"

            print(
                f"| {row.name} | {row.participants} | {row.participant_sd} / {row.clip_sd} | "
                f"{rate:.3f} [{low:.3f}, {high:.3f}] | {tested}/{args.studies} | {share('familywise', 'fw_tested')} | "
                f"{share('covered', 'intervals')} | {share('acc_covered', 'acc_intervals')} | "
                f"{share('untestable', 'contrasts')} | {total['power'] / args.studies:.3f} | "
                f"{total['df'] / tested if tested else math.nan:.1f} | {total['seconds'] / args.jobs:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
