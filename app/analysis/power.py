"""`foil power`: how many participants a study needs, by simulating its own design.

A simulated study has the study file's conditions (scheme orders and scenario rotations, assigned in turn), its
parts, pairs and scenarios, and one clip per scheme, scenario and pair as a bundle has. Each answer is right with
probability expit(scheme's log odds + participant effect + clip effect), the effects normal with the given
standard deviations on the log-odds scale, and each scheme's log odds set so that its accuracy over participants
and clips is the one assumed. The report's model (app/analysis/model.py) is fitted to each simulated study, and
power is the share of studies in which its test that the schemes differ has p < 0.05.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace
from functools import cache
from typing import TYPE_CHECKING

from app.analysis.model import Answers, ModelResult, fit_accuracy
from app.survey.assignment import conditions
from app.survey.study import Study

if TYPE_CHECKING:  # numpy is imported where it runs: the report (and so the server) imports this module
    import numpy as np

ALPHA = 0.05
TARGETS = (0.8, 0.9)


@dataclass(frozen=True)
class Layout:
    """Who answers which clip in one part's task for `participants` participants; `correct` left empty."""

    answers: Answers
    participant_index: np.ndarray  # answer -> participant number
    clip_index: np.ndarray  # answer -> clip number
    scheme_index: np.ndarray  # answer -> index into the study's schemes
    clips: int


def chance(study: Study, task: str) -> float:
    """The accuracy of guessing: one of two robots, or one of the k! orders of a ranking part's k agents."""
    if task == "pairwise":
        return 0.5
    agents = next(len(part.agents) for part in study.parts if part.kind == "ranking")
    return 1 / math.factorial(agents)


def tasks(study: Study) -> list[str]:
    return [task for task in ("pairwise", "ranking") if any(part.kind == task for part in study.parts)]


def layout(study: Study, task: str, participants: int) -> Layout:
    """The answers of `participants` participants in the study's design, conditions assigned in turn as the
    balanced assignment does. A ranking's clip is its block: the scheme's clips of the scenario it ranks."""
    import numpy as np

    columns: dict[str, list[str]] = {name: [] for name in ("participant", "clip", "scheme", "scenario", "pair")}
    design = conditions(study)
    for k in range(participants):
        condition = design[k % len(design)]
        for p, part in enumerate(study.parts):
            if part.kind != task:
                continue
            for scheme in condition.schemes:
                scenario = study.part_scenario(p, condition.rotation, scheme)
                pairs = ["-".join(sorted(pair)) for pair in part.pairs] if part.kind == "pairwise" else [""]
                for pair in pairs:
                    for name, value in zip(
                        columns, (f"p{k}", f"{scheme}/{scenario}/{pair}", scheme, scenario, pair), strict=True
                    ):
                        columns[name].append(value)
    schemes = list(study.design.schemes)
    clip_names, clip_index = np.unique(columns["clip"], return_inverse=True)
    return Layout(
        answers=Answers(**columns, correct=[]),
        participant_index=np.array([int(p[1:]) for p in columns["participant"]]),
        clip_index=clip_index,
        scheme_index=np.array([schemes.index(s) for s in columns["scheme"]]),
        clips=len(clip_names),
    )


@cache
def log_odds_for(accuracy: float, sd: float) -> float:
    """The log odds whose expit, averaged over a normal effect of standard deviation `sd`, is `accuracy`."""
    import numpy as np
    from scipy import optimize, special

    nodes, weights = np.polynomial.hermite_e.hermegauss(40)
    weights = weights / weights.sum()
    return float(optimize.brentq(lambda eta: float(special.expit(eta + sd * nodes) @ weights) - accuracy, -30.0, 30.0))


@dataclass(frozen=True)
class Assumptions:
    accuracy: dict[str, float]  # scheme -> accuracy over participants and clips
    participant_sd: float = 1.0  # log-odds scale
    clip_sd: float = 0.5


def simulate(study: Study, task: str, plan: Layout, assume: Assumptions, rng: np.random.Generator) -> Answers:
    """One simulated study's answers in the layout's design."""
    import numpy as np
    from scipy import special

    schemes = list(study.design.schemes)
    sd = math.hypot(assume.participant_sd, assume.clip_sd)
    eta = np.array([log_odds_for(assume.accuracy[s], sd) for s in schemes])
    person = rng.normal(0.0, assume.participant_sd, plan.participant_index.max() + 1)
    clip = rng.normal(0.0, assume.clip_sd, plan.clips)
    p = special.expit(eta[plan.scheme_index] + person[plan.participant_index] + clip[plan.clip_index])
    return replace(plan.answers, correct=(rng.random(len(p)) < p).astype(int).tolist())


def simulated_fits(
    study: Study, task: str, participants: int, assume: Assumptions, studies: int, seed: int
) -> list[ModelResult]:
    import numpy as np

    rng = np.random.default_rng([seed, participants])
    plan = layout(study, task, participants)
    schemes = list(study.design.schemes)
    return [
        fit_accuracy(simulate(study, task, plan, assume, rng), schemes, chance(study, task)) for _ in range(studies)
    ]


def power(results: list[ModelResult]) -> float:
    """The share of studies whose test that the schemes differ has p < 0.05 (a fit that fails counts as a miss)."""
    return sum(r.scheme_p is not None and r.scheme_p < ALPHA for r in results) / len(results)


def monte_carlo_error(value: float, studies: int) -> float:
    """Half the width of the 95% interval of a power estimated from `studies` simulated studies: the noise that
    can make power dip from one N to the next. Wilson's, so that 0% and 100% get one too."""
    from app.analysis.statistics import wilson_interval

    low, high = wilson_interval(round(value * studies), studies) or (0.0, 1.0)
    return (high - low) / 2


def participant_grid(study: Study, largest: int, points: int = 10) -> list[int]:
    """About `points` numbers of participants up to `largest`, each a whole number of rounds of the conditions
    (so every condition is filled equally)."""
    step = len(conditions(study))
    rounds = max(1, largest // step)
    stride = max(1, math.ceil(rounds / points))
    return [step * r for r in range(stride, rounds + 1, stride)]


def parse_accuracies(text: str, study: Study, what: str) -> dict[str, float]:
    """`adaptive=0.8,nfirst=0.7`: one accuracy per scheme of the study, each in (0, 1)."""
    schemes = list(study.design.schemes)
    accuracy: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, _, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"{what}: {item!r} is not SCHEME=ACCURACY (e.g. {schemes[0]}=0.8)") from None
        if name.strip() not in schemes:
            raise ValueError(f"{what}: no scheme {name.strip()!r} in the study (its schemes: {', '.join(schemes)})")
        if not 0 < number < 1:
            raise ValueError(f"{what}: the accuracy of {name.strip()} must be between 0 and 1, got {value}")
        accuracy[name.strip()] = number
    missing = [s for s in schemes if s not in accuracy]
    if missing:
        raise ValueError(
            f"{what}: give an accuracy for every scheme; missing {', '.join(missing)} "
            f"(e.g. {what} {','.join(f'{s}=0.8' for s in schemes)})"
        )
    return accuracy


def run_power(
    *,
    study_path: str,
    pairwise: str | None,
    ranking: str | None,
    pilot: str | None,
    participant_sd: float,
    clip_sd: float,
    largest: int,
    studies: int,
    seed: int,
) -> int:
    """`foil power`: prints power against number of participants per part, and the smallest N reaching 80%
    and 90%."""
    from app.survey.study import load_study

    study = load_study(study_path)
    if participant_sd < 0 or clip_sd < 0:
        raise ValueError("--participant-sd and --clip-sd are standard deviations: give 0 or more")
    if studies < 10:
        raise ValueError(f"--studies {studies} is too few to estimate power: give at least 10 (default 200)")
    given = {"pairwise": pairwise, "ranking": ranking}
    accuracies: dict[str, dict[str, float]] = {}
    if pilot is not None:
        accuracies = pilot_accuracies(pilot, study)
    for task in tasks(study):
        if given[task]:
            accuracies[task] = parse_accuracies(given[task] or "", study, f"--{task}")
    if not accuracies:
        schemes = ",".join(f"{s}=0.8" for s in study.design.schemes)
        raise ValueError(
            f"give the accuracies you expect per scheme (--{tasks(study)[0]} {schemes}) or a pilot's database "
            "(--pilot sqlite:///pilot.sqlite3)"
        )
    grid = participant_grid(study, largest)
    if not grid:
        raise ValueError(f"--max-participants {largest} is fewer than the study's {len(conditions(study))} conditions")
    print(
        f"{study.study.id}: {studies} simulated studies per number of participants; participant SD {participant_sd}, "
        f"clip SD {clip_sd} (log odds); test: the report's model, schemes differ at p < {ALPHA}"
    )
    for task, accuracy in accuracies.items():
        assume = Assumptions(accuracy, participant_sd, clip_sd)
        print(f"\n{task}: accuracies " + ", ".join(f"{s} {a:.2f}" for s, a in accuracy.items()))
        print(f"{'participants':>12}  {'power':>6}  {'± (Monte Carlo, 95%)':>20}")
        reached: dict[float, int] = {}
        for n in grid:
            value = power(simulated_fits(study, task, n, assume, studies, seed))
            print(f"{n:>12}  {value:>6.2f}  {monte_carlo_error(value, studies):>20.2f}", flush=True)
            for target in TARGETS:
                if value >= target:
                    reached.setdefault(target, n)
        for target in TARGETS:
            found = reached.get(target)
            print(
                f"{target:.0%} power: "
                + (f"{found} participants" if found else f"not reached with {grid[-1]} (try --max-participants)")
            )
    print(f"(simulation seed {seed})", file=sys.stderr)
    return 0


def pilot_accuracies(url: str, study: Study) -> dict[str, dict[str, float]]:
    """Each part's accuracy per scheme as the report's model estimates it from a pilot's database (pilots, the
    admin's preview link, counted beside real participants)."""
    from app.analysis.exclusions import ExclusionRules
    from app.analysis.report import tally_study
    from app.analysis.source import analysis_database

    db = analysis_database(url)
    try:
        data = tally_study(db, study, ExclusionRules(include_kinds=("pilot",)))
    finally:
        db.dispose()
    accuracies: dict[str, dict[str, float]] = {}
    for task in data.tasks():
        result = data.model(task)
        found = {e.scheme: e.accuracy for e in result.schemes}
        if result.estimable and len(found) == len(study.design.schemes):
            accuracies[task] = {s: min(max(a, 0.01), 0.99) for s, a in found.items()}
        else:
            print(f"warning: the pilot gives no {task} estimate ({result.note}); give --{task}", file=sys.stderr)
    return accuracies
