"""The report's small-sample degrees of freedom beside R's clubSandwich, and its population-averaged log odds ratios
beside lme4's conditional ones, on the same data sets.

1. The data set of tests/app/analysis/test_small_sample.py (14 participants, 9 clips, 3 schemes): R's
   `glm` + `vcovCR(type = "CR2")` + `coef_test(test = "Satterthwaite")` and `Wald_test(test = "HTZ")`, one-way by
   clip and by participant, against Foil's `_wishart_df` at R's estimate.
2. Simulated studies (two schemes, 6 clips each, 40 participants) at several participant and clip standard
   deviations: Foil's log odds ratio (population-averaged) against `glmer(correct ~ scheme + (1 | participant) +
   (1 | clip))`'s (conditional), as the ratio of their means.

Needs R with clubSandwich and lme4 (Debian: r-base-core r-cran-clubsandwich r-cran-lme4).

    .venv/bin/python benchmarks/bench_clubsandwich.py [--studies 40]
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from app.analysis.model import Answers, _covariance, _part, _Robust, _scheme_test, _wishart_df, fit_accuracy  # noqa: E402
from app.analysis.simulation import log_odds_for  # noqa: E402
from tests.app.analysis.test_small_sample import reference_data, reference_fit  # noqa: E402

CLUBSANDWICH = """
suppressMessages(library(clubSandwich))
d <- read.csv(commandArgs(TRUE)[1])
fit <- glm(correct ~ 0 + scheme, family = binomial, data = d)
for (cl in c("clip", "participant")) {
  V <- vcovCR(fit, cluster = d[[cl]], type = "CR2")
  ct <- coef_test(fit, vcov = V, test = "Satterthwaite")
  w <- Wald_test(fit, constraints = constrain_pairwise(1:3), vcov = V, test = "HTZ", tidy = TRUE)
  e <- Wald_test(fit, constraints = constrain_equal(1:3), vcov = V, test = "HTZ")
  cat(cl, ct$df_Satt, w$df_denom, e$df_denom, e$p_val, "\\n")
}
"""

GLMER = """
suppressMessages(library(lme4))
d <- read.csv(commandArgs(TRUE)[1])
for (s in unique(d$study)) {
  fit <- glmer(correct ~ scheme + (1 | participant) + (1 | clip), family = binomial, data = d[d$study == s, ])
  cat(fixef(fit)[2], "\\n")
}
"""


def rscript(program: str, data: Path) -> str:
    with tempfile.NamedTemporaryFile("w", suffix=".R", delete=False) as handle:
        handle.write(program)
    return subprocess.run(["Rscript", handle.name, str(data)], check=True, capture_output=True, text=True).stdout


def degrees_of_freedom(folder: Path) -> None:
    data = reference_data()
    path = folder / "reference.csv"
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(data)
        writer.writerows(zip(*data.values(), strict=True))
    found = {line.split()[0]: [float(v) for v in line.split()[1:]] for line in rscript(CLUBSANDWICH, path).splitlines()}
    _, x, y, beta, mu, weight, bread = reference_fit()
    constraints = [*np.eye(3), np.array([-1.0, 1, 0]), np.array([-1.0, 0, 1]), np.array([0, -1.0, 1])]
    names = ["a", "b", "c", "b - a", "c - a", "c - b"]
    print("| clustering | test | clubSandwich df | Foil df | ratio |\n|---|---|---:|---:|---:|")
    for clustering, values in found.items():
        parts = [_part(1.0, np.unique(data[clustering], return_inverse=True)[1], x, weight, bread)]
        for name, constraint, expected in zip(names, constraints, values[:6], strict=True):
            ours = _wishart_df(parts, x, weight, bread, constraint[None, :])
            print(f"| {clustering} | {name} (Satterthwaite) | {expected:.6f} | {ours:.6f} | {ours / expected:.6f} |")
        robust = _Robust([(parts, _covariance(parts, x, y - mu))], x, weight, bread)
        _, p, df = _scheme_test(beta, robust, ["a", "b", "c"], ["a", "b", "c"])
        print(f"| {clustering} | a = b = c (HTZ df) | {values[6]:.6f} | {df:.6f} | {df / values[6]:.6f} |")
        print(f"| {clustering} | a = b = c (HTZ p) | {values[7]:.8f} | {p or 0:.8f} | {(p or 0) / values[7]:.6f} |")


def crossed_study(participant_sd: float, clip_sd: float, rng: np.random.Generator) -> Answers:
    """40 participants answer all 12 clips, 6 of a scheme at 70% and 6 at 85% (over participants and clips)."""
    eta = [log_odds_for(a, float(np.hypot(participant_sd, clip_sd))) for a in (0.7, 0.85)]
    clip = rng.normal(0, clip_sd, 12)
    people = list(enumerate(rng.normal(0, participant_sd, 40)))
    right = [int(rng.random() < 1 / (1 + np.exp(-(eta[c // 6] + u + clip[c])))) for _, u in people for c in range(12)]
    participant = [f"p{p}" for p, _ in people for _ in range(12)]
    clips = [f"c{c}" for _ in people for c in range(12)]
    schemes = [f"s{c // 6}" for _ in people for c in range(12)]
    return Answers(participant, clips, schemes, ["one"] * len(right), [""] * len(right), right)


def log_odds_ratios(folder: Path, studies: int) -> None:
    print("\n| participant SD | clip SD | Foil's log OR (population-averaged) | glmer's (conditional) | ratio |")
    print("|---:|---:|---:|---:|---:|")
    for participant_sd, clip_sd in ((0.5, 0.3), (1.0, 0.5), (1.5, 0.3), (1.5, 1.0)):
        rng = np.random.default_rng(1)
        path = folder / "studies.csv"
        ours = []
        with path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["study", "participant", "clip", "scheme", "correct"])
            for study in range(studies):
                answers = crossed_study(participant_sd, clip_sd, rng)
                fit = fit_accuracy(answers, ["s0", "s1"], 0.5)
                ours.append(np.log(fit.contrasts[0].odds_ratio))
                writer.writerows(
                    (study, p, c, s, k)
                    for p, c, s, k in zip(
                        answers.participant, answers.clip, answers.scheme, answers.correct, strict=True
                    )
                )
        theirs = [float(v) for v in rscript(GLMER, path).split()]
        print(
            f"| {participant_sd} | {clip_sd} | {np.mean(ours):.3f} | {np.mean(theirs):.3f} | "
            f"{np.mean(theirs) / np.mean(ours):.2f} |",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", type=int, default=40, help="simulated studies per row of the second table")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        degrees_of_freedom(Path(folder))
        log_odds_ratios(Path(folder), args.studies)


if __name__ == "__main__":
    main()
