"""`foil power`: how many participants a study needs, by simulating its own design.

The simulated studies are `app.analysis.simulation`'s: the study's own design, answers drawn from assumed
accuracies with participant and clip effects, the report's model (app/analysis/model.py) fitted to each. Power is
the share of studies in which its test that the schemes differ has p < 0.05.

The N for 80% and 90% power comes from all the simulated studies at once: a curve fitted to their rejections at every
N (`fit_power_curve`), which rises monotonically however noisy the estimate at each N, with a parametric bootstrap
interval (`crossings`). The first N whose own estimate reached the target, as this used to report, is as noisy as
that one estimate and lies on the coarse grid.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import optimize

from app.analysis.design import tasks
from app.analysis.exclusions import ExclusionRules
from app.analysis.model import ModelResult
from app.analysis.report import ALL, tally_study
from app.analysis.simulation import MEASURES, Assumptions, simulated_fits
from app.analysis.source import analysis_database
from app.analysis.statistics import wilson_interval
from app.formats import Manifest
from app.survey.assignment import conditions
from app.survey.study import Study, load_study

ALPHA = 0.05
TARGETS = (0.8, 0.9)
STUDIES = 100  # simulated studies per N: the default of `foil power --studies` (app/cli.py)


def power(results: list[ModelResult]) -> float:
    """The share of studies whose test that the schemes differ has p < 0.05 (a fit that fails counts as a miss)."""
    return sum(r.scheme_p is not None and r.scheme_p < ALPHA for r in results) / len(results)


def monte_carlo_error(value: float, studies: int) -> float:
    """Half the width of the 95% interval of a power estimated from `studies` simulated studies: the noise that
    can make power dip from one N to the next. Wilson's, so that 0% and 100% get one too."""
    low, high = wilson_interval(round(value * studies), studies) or (0.0, 1.0)
    return (high - low) / 2


@dataclass(frozen=True)
class PowerCurve:
    """Power against N: ceiling * expit(a + b log N), b >= 0. Without the ceiling (a logistic curve in log N) the
    fit cannot level off as power does when the clips' spread, which more participants leave as it is, limits the
    test: it then puts 80% too late and promises a 90% that never comes."""

    a: float
    b: float
    ceiling: float

    def power(self, n: float) -> float:
        return self.ceiling / (1 + math.exp(min(700.0, -(self.a + self.b * math.log(n)))))

    def participants_for(self, target: float) -> float:
        """The N at which the curve reaches `target`: 0 if it starts above it, infinite if it never does."""
        if self.ceiling <= target or self.b == 0:
            return 0.0 if self.power(1) >= target else math.inf
        log_n = (math.log(target / (self.ceiling - target)) - self.a) / self.b
        return math.inf if log_n > 700 else math.exp(log_n)


def fit_power_curve(
    participants: list[int], rejections: list[int], studies: int, start: PowerCurve | None = None
) -> PowerCurve:
    """The maximum-likelihood curve for `rejections` out of `studies` simulated studies at each N (binomial counts),
    each count given half a rejection and half a non-rejection more, so that none is 0% or 100% and the fit stays
    finite when every study at some N rejects, or none does. Without `start`, two starts: rising to 100%, and
    levelling off at the largest power seen."""
    x = np.log(np.asarray(participants, dtype=float))
    k = np.asarray(rejections, dtype=float) + 0.5
    m = studies + 1.0

    def deviance(theta: np.ndarray) -> tuple[float, np.ndarray]:
        a, b, ceiling = theta
        rising = 1 / (1 + np.exp(-(a + b * x)))
        p = np.clip(ceiling * rising, 1e-12, 1 - 1e-12)
        slope = k / p - (m - k) / (1 - p)  # of the log likelihood in p
        along = slope * ceiling * rising * (1 - rising)
        gradient = -np.array([along.sum(), along @ x, slope @ rising])
        return -float(k @ np.log(p) + (m - k) @ np.log1p(-p)), gradient

    if start is None:
        slope, intercept = np.polyfit(x, np.log(k / (m - k)), 1)
        highest = min(1.0, float(k.max() / m) + 0.02)
        starts = [[intercept, max(slope, 0.1), 1.0], [intercept, max(slope, 0.1), highest]]
    else:
        starts = [[start.a, start.b, start.ceiling]]
    bounds = [(None, None), (0.0, 50.0), (0.01, 1.0)]
    fits = [optimize.minimize(deviance, s, jac=True, method="TNC", bounds=bounds) for s in starts]
    return PowerCurve(*(float(v) for v in min(fits, key=lambda r: float(r.fun)).x))


@dataclass(frozen=True)
class Crossing:
    """Where the fitted power reaches `target`, in whole participants, on the grid's span `first` to `last`."""

    target: float
    first: int
    last: int
    n: float  # the curve's N for the target: below `first` or above `last` (infinite: never) possible
    low: float  # 95% interval (parametric bootstrap)
    high: float
    ceiling: float  # the power the curve levels off at
    power_at_last: float


def crossings(
    participants: list[int], rejections: list[int], studies: int, seed: int = 0, replicates: int = 200
) -> list[Crossing]:
    """The N for each of TARGETS from the fitted curve, with a 95% parametric bootstrap interval: counts drawn from
    the fitted curve's power at each N, the curve refitted to each draw, and the 2.5th and 97.5th percentiles of
    their N (a draw that never reaches the target counts as infinite). It reflects the Monte Carlo error of the
    simulated studies, not whether the curve's shape is right."""
    curve = fit_power_curve(participants, rejections, studies)
    rng = np.random.default_rng(seed)
    expected = [curve.power(n) for n in participants]
    draws = [
        fit_power_curve(participants, list(rng.binomial(studies, expected)), studies, curve) for _ in range(replicates)
    ]
    first, last = participants[0], participants[-1]
    found = []
    for target in TARGETS:
        ns = np.array([draw.participants_for(target) for draw in draws])
        low, high = np.quantile(ns, 0.025, method="lower"), np.quantile(ns, 0.975, method="higher")
        found.append(
            Crossing(target, first, last, curve.participants_for(target), low, high, curve.ceiling, curve.power(last))
        )
    return found


def describe(found: Crossing, task: str) -> str:
    """`80% power: at about N = 71 (95% interval 63-80)`, or why it is not reached and what would reach it."""
    if found.n <= found.first:
        return f"{found.target:.0%} power: at {found.first} participants or fewer, the smallest N tried"
    if found.n <= found.last:
        low = f"{found.first} or fewer" if found.low <= found.first else str(math.ceil(found.low))
        high = f"more than {found.last}" if found.high > found.last else str(math.ceil(found.high))
        between = " to " if " " in low + high else "-"
        return f"{found.target:.0%} power: at about N = {math.ceil(found.n)} (95% interval {low}{between}{high})"
    at_last = f"{math.floor(found.power_at_last * 100) / 100:.2f} at {found.last}"  # rounded down: not reached
    text = f"{found.target:.0%} power: not reached within {found.last} participants (the fit gives {at_last}"
    if found.ceiling > found.target and task == "ranking":  # the sets' spread, not the participants, limits it
        return text + (
            "); a larger --max-participants may reach it, but a ranking test is limited by its few ranked sets: more "
            "ranked sets (scenarios) help more than more participants"
        )
    if found.ceiling > found.target:
        return text + "); try a larger --max-participants"
    clips = "ranked sets" if task == "ranking" else "clips per scheme"
    return text + (
        f" and levels off at {math.floor(found.ceiling * 100) / 100:.2f}): the clips' spread limits the test, so more "
        f"participants may never reach it; more {clips} (scenarios) would"
    )


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
    bundle: str | None = None,
    shown_right: float = 0.85,
) -> int:
    """`foil power`: prints power against number of participants per part, and the N at which a monotone fit of
    that curve reaches 80% and 90%."""
    study = load_study(study_path)
    if participant_sd < 0 or clip_sd < 0:
        raise ValueError("--participant-sd and --clip-sd are standard deviations: give 0 or more")
    if studies < 10:
        raise ValueError(f"--studies {studies} is too few to estimate power: give at least 10 (default {STUDIES})")
    given = {"pairwise": pairwise, "ranking": ranking}
    accuracies: dict[str, dict[str, float]] = {}
    if pilot is not None:
        accuracies = pilot_accuracies(pilot, study)
    if bundle is not None:
        accuracies |= bundle_accuracies(bundle, study, shown_right)
        print(
            f"pairwise accuracies expected from the bundle's audit: a clip that shows the better agent answered right "
            f"by {shown_right:.0%}, a tie or an undecided pair by 50%, a misleading clip by {1 - shown_right:.0%}"
        )
    for task in tasks(study):
        if given[task]:
            accuracies[task] = parse_accuracies(given[task] or "", study, f"--{task}")
    if not accuracies:
        schemes = ",".join(f"{s}=0.8" for s in study.design.schemes)
        raise ValueError(
            f"give the accuracies you expect per scheme (--{tasks(study)[0]} {schemes}), a pilot's database "
            "(--pilot sqlite:///pilot.sqlite3) or the study's bundle (--bundle bundles/NAME)"
        )
    grid = participant_grid(study, largest)
    if not grid:
        raise ValueError(f"--max-participants {largest} is fewer than the study's {len(conditions(study))} conditions")
    print(
        f"{study.study.id}: {studies} simulated studies per number of participants; participant SD {participant_sd}, "
        f"clip SD {clip_sd} (log odds); test: the report's model, schemes differ at p < {ALPHA}; N for "
        + " and ".join(f"{t:.0%}" for t in TARGETS)
        + " from a monotone curve fitted to all of them"
    )
    for task, accuracy in accuracies.items():
        assume = Assumptions(accuracy, participant_sd, clip_sd)
        print(f"\n{task}: accuracies " + ", ".join(f"{s} {a:.2f}" for s, a in accuracy.items()))
        measures = MEASURES[task]
        if task == "ranking":
            print("(of the whole order; the report tests the rankings' pairwise orderings, shown first)")
        header = "".join(f"  {'power, ' + m:>18}  {'± (Monte Carlo, 95%)':>20}" for m in measures)
        print(f"{'participants':>12}{header}")
        rejections: dict[str, list[int]] = {m: [] for m in measures}
        untested: dict[str, str] = {}  # measure -> why the design never gets a test, if it never does
        for n in grid:
            fits = simulated_fits(study, task, n, assume, studies, seed)
            line = f"{n:>12}"
            for measure in measures:
                if all(r.scheme_p is None for r in fits[measure]) and (n == grid[0] or measure in untested):
                    untested[measure] = fits[measure][0].scheme_test or fits[measure][0].note
                else:
                    untested.pop(measure, None)
                value = power(fits[measure])
                rejections[measure].append(round(value * studies))
                line += f"  {value:>18.2f}  {monte_carlo_error(value, studies):>20.2f}"
            print(line, flush=True)
        if len(grid) < 3:
            print(f"too few numbers of participants for a curve: give a --max-participants of {3 * grid[-1]} or more")
            continue
        for measure in measures:
            prefix = "" if len(measures) == 1 else f"{measure}: "
            if measure in untested:
                print(f"{prefix}no power at any N: the report would not test this design ({untested[measure]})")
                continue
            for found in crossings(grid, rejections[measure], studies, seed):
                print(prefix + describe(found, task))
    print(f"(simulation seed {seed})", file=sys.stderr)
    return 0


def bundle_accuracies(bundle: str, study: Study, shown_right: float) -> dict[str, dict[str, float]]:
    """The pairwise part's expected accuracy per scheme from the bundle, before anyone is recruited: each clip is
    answered right by `shown_right` of participants where its audit says it visibly shows the better agent, by
    half where it shows a tie or rests on a pair the evaluation could not decide (a coin toss), and by
    1 - `shown_right` where it shows the worse one as better; a scheme's accuracy is the mean over its clips."""
    path = Path(bundle) / "manifest.json"
    if not path.is_file():
        raise ValueError(f"--bundle {bundle}: no manifest.json there; give the folder foil bundle wrote")
    if not 0.5 <= shown_right < 1:
        raise ValueError(f"--shown-right {shown_right}: give the share of right answers to a clear clip, 0.5 to 1")
    manifest = Manifest.model_validate_json(path.read_text(encoding="utf-8"))
    undecided = {frozenset(pair.agents) for pair in manifest.close_pairs if not pair.decided}
    expected: dict[str, list[float]] = {}
    for clip in manifest.clips:
        if "pairwise" not in clip.parts or clip.audit is None:
            continue
        shows = "tie" if frozenset(clip.agents) in undecided else clip.audit.shows
        right = {"better": shown_right, "tie": 0.5, "worse": 1 - shown_right}[shows]
        expected.setdefault(clip.scheme, []).append(right)
    missing = [s for s in study.design.schemes if s not in expected]
    if missing:
        raise ValueError(f"--bundle {bundle}: no audited pairwise clip of {', '.join(missing)}: is it this study's?")
    return {"pairwise": {s: min(max(sum(v) / len(v), 0.01), 0.99) for s, v in expected.items()}}


def pilot_accuracies(url: str, study: Study) -> dict[str, dict[str, float]]:
    """Each part's accuracy per scheme as the report's model estimates it from a pilot's database (pilots, the
    admin's preview link, counted beside real participants)."""
    db = analysis_database(url)
    try:
        data = tally_study(db, study, ExclusionRules(include_kinds=("pilot",)))
    finally:
        db.dispose()
    accuracies: dict[str, dict[str, float]] = {}
    for task in data.tasks():
        result = data.model(task)
        found = {e.scheme: e.accuracy for e in result.schemes}
        if task == "ranking":  # the model's is of the orderings; power takes the whole order's, as --ranking does
            found = {s: data.tally(task, ALL, s).accuracy or 0.0 for s in found}
        if result.estimable and len(found) == len(study.design.schemes):
            accuracies[task] = {s: min(max(a, 0.01), 0.99) for s, a in found.items()}
        else:
            print(f"warning: the pilot gives no {task} estimate ({result.note}); give --{task}", file=sys.stderr)
    return accuracies
