"""The statistics of the report: Wilson intervals for accuracies, a test of the difference in accuracy between
schemes, and rank tests for the ordinal ratings. Each result carries the name of the test it ran, so the report
states exactly what was computed."""

from __future__ import annotations

import math
from dataclasses import dataclass

Z95 = 1.959963984540054  # the 97.5th percentile of the standard normal


@dataclass(frozen=True)
class TestResult:
    test: str  # what was run, in words, or why nothing was
    statistic: float | None = None
    p_value: float | None = None
    effect: float | None = None  # odds ratio (Fisher) or rank-biserial correlation (Mann-Whitney); else None


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """The Wilson score interval of a proportion: unlike the normal interval it stays inside [0, 1] and keeps
    its coverage at accuracies near 0% or 100%, where a study like the paper's lands. None when n is 0."""
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return None
    p = successes / n
    denominator = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def accuracy_difference(counts: dict[str, tuple[int, int]]) -> TestResult:
    """Do the schemes differ in accuracy? `counts` maps scheme -> (correct, incorrect).

    Two schemes: Fisher's exact test (two-sided) on the 2x2 table, exact at any sample size. More schemes:
    Pearson's chi-square test of independence on the k x 2 table. Schemes without answers are left out."""
    from scipy import stats

    table: list[tuple[float, float]] = [(c, i) for c, i in counts.values() if c + i > 0]
    if len(table) < 2:
        return TestResult("not tested: fewer than two schemes have answers")
    if len(table) == 2:
        odds, p = stats.fisher_exact(table, alternative="two-sided")
        (a, b), (c, d) = table
        if 0 in (a, b, c, d):  # Haldane-Anscombe: add 0.5 to every cell, so the odds ratio is finite
            a, b, c, d = a + 0.5, b + 0.5, c + 0.5, d + 0.5
        effect = (a * d) / (b * c)
        return TestResult(
            "Fisher's exact test, two-sided; odds ratio with the Haldane-Anscombe correction (0.5 "
            "added to every cell) when a cell is 0",
            statistic=effect,
            p_value=float(p),
            effect=effect,
        )
    if all(c == 0 for c, _ in table) or all(i == 0 for _, i in table):
        return TestResult("Pearson's chi-square test: every answer is in one column, so no difference", 0.0, 1.0)
    chi2, p, dof, _ = stats.chi2_contingency(table, correction=False)
    return TestResult(f"Pearson's chi-square test of independence, {dof} degrees of freedom", float(chi2), float(p))


def ordinal_difference(samples: dict[str, list[int]]) -> TestResult:
    """Do the schemes differ in an ordinal rating? `samples` maps scheme -> ratings.

    Two schemes: Mann-Whitney U, two-sided, normal approximation with tie correction and continuity correction
    (ratings on a 5- or 9-point scale are full of ties, where the exact distribution does not apply). The
    statistic is U of the first scheme; the effect is the rank-biserial correlation 2U/(n1 n2) - 1 (positive when
    the first scheme's ratings are higher). More schemes: Kruskal-Wallis H."""
    from scipy import stats

    groups = [(scheme, values) for scheme, values in samples.items() if values]
    if len(groups) < 2:
        return TestResult("not tested: fewer than two schemes have ratings")
    values = [v for _, group in groups for v in group]
    if len(set(values)) == 1:
        name = "Mann-Whitney U" if len(groups) == 2 else "Kruskal-Wallis H"
        return TestResult(f"{name}: every rating is the same, so no difference", None, 1.0)
    if len(groups) == 2:
        (_, a), (_, b) = groups
        result = stats.mannwhitneyu(a, b, alternative="two-sided", use_continuity=True, method="asymptotic")
        u = float(result.statistic)
        return TestResult(
            "Mann-Whitney U, two-sided, normal approximation with tie and continuity correction",
            statistic=u,
            p_value=float(result.pvalue),
            effect=2 * u / (len(a) * len(b)) - 1,
        )
    h, p = stats.kruskal(*(group for _, group in groups))
    return TestResult(f"Kruskal-Wallis H, {len(groups) - 1} degrees of freedom", float(h), float(p))
