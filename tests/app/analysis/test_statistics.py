"""The report's statistics against values computed by hand (textbook formulas written out here, not scipy)."""

from __future__ import annotations

import math

import pytest

from app.analysis.statistics import accuracy_difference, ordinal_difference, wilson_interval
from tests.support.analysis import fisher_two_sided


def test_wilson_interval_textbook_values():
    # Newcombe (1998), Table I, and the closed form at the extremes: z^2 / (n + z^2) for 0 of n.
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert wilson_interval(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    z2 = 1.959963984540054**2
    assert wilson_interval(0, 120)[1] == pytest.approx(z2 / (120 + z2))
    assert wilson_interval(0, 0) is None
    with pytest.raises(ValueError):
        wilson_interval(3, 2)


@pytest.mark.parametrize("table", [((12, 0), (8, 4)), ((114, 6), (65, 55)), ((26, 14), (12, 28)), ((3, 1), (1, 3))])
def test_fisher_exact_matches_the_hypergeometric_sum(table):
    (a, b), (c, d) = table
    result = accuracy_difference({"adaptive": (a, b), "nfirst": (c, d)})
    assert result.test.startswith("Fisher's exact test, two-sided")
    assert result.p_value == pytest.approx(fisher_two_sided(a, b, c, d), rel=1e-9)
    if 0 in (a, b, c, d):  # Haldane-Anscombe: finite, with 0.5 added to every cell
        expected = (a + 0.5) * (d + 0.5) / ((b + 0.5) * (c + 0.5))
    else:
        expected = a * d / (b * c)
    assert math.isfinite(result.effect) and result.effect == pytest.approx(expected)


def test_chi_square_for_three_schemes():
    # Expected counts are all 10, so chi2 = 4 * 25 / 10 = 10 with 2 degrees of freedom: p = exp(-10 / 2).
    result = accuracy_difference({"a": (10, 10), "b": (15, 5), "c": (5, 15)})
    assert result.test.startswith("Pearson's chi-square") and "2 degrees of freedom" in result.test
    assert result.statistic == pytest.approx(10.0)
    assert result.p_value == pytest.approx(math.exp(-5))


def test_accuracy_difference_needs_two_schemes_with_answers():
    assert accuracy_difference({"a": (5, 5), "b": (0, 0)}).p_value is None
    all_wrong = accuracy_difference({"a": (0, 20), "b": (0, 20)})
    assert all_wrong.p_value == 1 and all_wrong.effect == pytest.approx(1.0)  # Haldane: no difference
    assert accuracy_difference({}).test.startswith("not tested")


def test_mann_whitney_by_hand_with_ties():
    a = [1] * 12
    b = [5] * 12
    result = ordinal_difference({"adaptive": a, "nfirst": b})
    # U of the first sample is 0; mean n1 n2 / 2 = 72; tie-corrected variance n1 n2 / 12 * ((N + 1) - sum(t^3 - t) /
    # (N (N - 1))) with two ties of 12 among N = 24; z with continuity correction 0.5.
    n1 = n2 = 12
    big_n = 24
    variance = n1 * n2 / 12 * ((big_n + 1) - 2 * (12**3 - 12) / (big_n * (big_n - 1)))
    z = (72 - 0.5) / math.sqrt(variance)
    assert result.statistic == 0
    assert result.p_value == pytest.approx(math.erfc(z / math.sqrt(2)), rel=1e-9)
    assert result.effect == -1  # rank-biserial: every adaptive rating is below every nfirst rating


def test_mann_whitney_small_mixed_sample():
    # a = [1, 2, 3], b = [2, 4, 5]: pairs where a > b: (3, 2); the tie (2, 2) counts a half, so U = 1.5.
    result = ordinal_difference({"a": [1, 2, 3], "b": [2, 4, 5]})
    assert result.statistic == 1.5
    ranks_ties = 2**3 - 2  # one tie of two
    variance = 9 / 12 * (7 - ranks_ties / 30)
    z = (4.5 - 1.5 - 0.5) / math.sqrt(variance)
    assert result.p_value == pytest.approx(math.erfc(z / math.sqrt(2)), rel=1e-9)


def test_ordinal_difference_degenerate_cases():
    assert ordinal_difference({"a": [3, 3], "b": [3]}).p_value == 1.0
    assert ordinal_difference({"a": [1, 2], "b": []}).test.startswith("not tested")
    kruskal = ordinal_difference({"a": [1, 2, 3], "b": [4, 5, 6], "c": [7, 8, 9]})
    # H = 12 / (N (N + 1)) * sum(R_i^2 / n_i) - 3 (N + 1) with rank sums 6, 15, 24 and no ties.
    assert kruskal.statistic == pytest.approx(12 / 90 * (36 + 225 + 576) / 3 - 30)
    assert kruskal.test.startswith("Kruskal-Wallis")
