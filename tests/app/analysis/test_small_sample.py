"""The report's small-sample tests (app/analysis/model.py) on small data sets whose answers are known: the
degrees of freedom and the Hotelling T² approximation against R's clubSandwich, the two-way extension against
the same moments summed over dense matrices, Holm, the permutation test, a ranking's pairwise orderings, the
untestable cases, and intervals that agree with their p and stay in range."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.model import (
    Answers,
    Ratings,
    _covariance,
    _design,
    _fit,
    _part,
    _Robust,
    _scheme_test,
    _wishart_df,
    fit_accuracy,
    fit_ratings,
    holm,
    permutation_p,
)
from app.analysis.report import orderings

# R 4.2, clubSandwich 0.5.8, on `reference_data()` (benchmarks/bench_clubsandwich.py prints them anew):
# glm(correct ~ 0 + scheme, binomial); vcovCR(type = "CR2"); coef_test(test = "Satterthwaite");
# Wald_test(constraints = constrain_pairwise(1:3) and constrain_equal(1:3), test = "HTZ").
CLUBSANDWICH = {
    "clip": {
        "coef": (1.983609, 1.986208, 2.000002),
        "pairwise": (3.946230, 3.982678, 3.952407),
        "equal": (3.469948, 0.74191141),
    },
    "participant": {
        "coef": (12.132545, 12.464356, 12.226559),
        "pairwise": (12.461553, 12.600026, 12.648990),
        "equal": (11.609930, 0.59105743),
    },
}


def reference_data() -> dict[str, list]:
    """14 participants, 9 clips (3 per scheme), a participant effect and fixed clip effects; about 15% missing."""
    rng = np.random.default_rng(5)
    rows: dict[str, list] = {"participant": [], "clip": [], "scheme": [], "correct": []}
    for p in range(14):
        u = rng.normal(0, 1.0)
        for c in range(9):
            if rng.random() < 0.85:
                v = [0.3, -0.4, 0.8, 0.1, 0.5, -0.2, 1.0, 0.4, 0.0][c]
                right = int(rng.random() < 1 / (1 + np.exp(-(1.0 + u + v))))
                for name, value in zip(rows, (f"p{p}", f"c{c}", "abc"[c // 3], right), strict=True):
                    rows[name].append(value)
    return rows


def _maximum_likelihood(x, y):
    """The plain logistic fit R's glm gives (the report's model is Firth-penalised; the degrees of freedom are
    compared at R's estimate)."""
    beta = np.zeros(x.shape[1])
    for _ in range(50):
        mu = 1 / (1 + np.exp(-x @ beta))
        beta = beta + np.linalg.solve((x * (mu * (1 - mu))[:, None]).T @ x, x.T @ (y - mu))
    mu = 1 / (1 + np.exp(-x @ beta))
    return beta, mu


def reference_fit():
    """`reference_data()` fitted as R's glm(correct ~ 0 + scheme, binomial): data, design, answers, estimate,
    fitted probabilities, weights and bread."""
    data = reference_data()
    scheme = np.asarray(data["scheme"])
    x = np.column_stack([(scheme == s).astype(float) for s in "abc"])
    y = np.asarray(data["correct"], dtype=float)
    beta, mu = _maximum_likelihood(x, y)
    weight = mu * (1 - mu)
    return data, x, y, beta, mu, weight, np.linalg.inv((x * weight[:, None]).T @ x)


def test_degrees_of_freedom_and_hotelling_equal_clubsandwich():
    data, x, y, beta, mu, weight, bread = reference_fit()
    pairs = np.array([[-1.0, 1, 0], [-1, 0, 1], [0, -1, 1]])
    for clustering, expected in CLUBSANDWICH.items():
        parts = [_part(1.0, np.unique(data[clustering], return_inverse=True)[1], x, weight, bread)]
        for k in range(3):
            assert _wishart_df(parts, x, weight, bread, np.eye(3)[[k]]) == pytest.approx(expected["coef"][k], abs=1e-4)
        for k in range(3):
            assert _wishart_df(parts, x, weight, bread, pairs[[k]]) == pytest.approx(expected["pairwise"][k], abs=1e-4)
        robust = _Robust([(parts, _covariance(parts, x, y - mu))], x, weight, bread)
        _, p, df = _scheme_test(beta, robust, ["a", "b", "c"], ["a", "b", "c"])
        assert (df, p) == pytest.approx(expected["equal"], abs=1e-4)


def test_two_way_degrees_of_freedom_equal_the_moments_summed_over_dense_matrices():
    """The signed two-way sum V_participant + V_clip - V_answer is y'My; its Satterthwaite (q = 1) and HTZ (q = 2)
    degrees of freedom from tr(MΦMΦ)-type sums over every pair of clusters, with (I - H) formed in full."""
    data = reference_data()
    answers = Answers(data["participant"], data["clip"], data["scheme"], ["one"] * len(data["clip"]),
                      [""] * len(data["clip"]), data["correct"])  # fmt: skip
    x = _design(answers, ["a", "b", "c"], ())
    y = np.asarray(data["correct"], dtype=float)
    _, fitted = _fit(y, x)
    weight = fitted * (1 - fitted)
    bread = np.linalg.inv((x * weight[:, None]).T @ x)
    parts = [
        _part(sign, np.unique(groups, return_inverse=True)[1], x, weight, bread)
        for sign, groups in ((1.0, data["participant"]), (1.0, data["clip"]), (-1.0, np.arange(len(y))))
    ]
    standard = x * np.sqrt(weight)[:, None]
    residual_maker = np.eye(len(y)) - standard @ bread @ standard.T
    clusters = [(part.sign, part.groups == g, part.adjust[g]) for part in parts for g in range(len(part.adjust))]
    signs = np.array([sign for sign, _, _ in clusters])

    def cross(c_s, c_t):
        def loads(c):
            z = np.zeros((len(clusters), len(y)))
            for a, (_, rows, adjust) in enumerate(clusters):
                z[a, rows] = standard[rows] @ (adjust @ c)
            return z

        return loads(c_s) @ residual_maker @ loads(c_t).T

    for constraints in (np.array([[-1.0, 1, 0]]), np.array([[-1.0, 1, 0], [-1, 0, 1]])):
        q = len(constraints)
        expected = np.array(
            [[signs @ np.diag(cross(constraints[s], constraints[t])) for t in range(q)] for s in range(q)]
        )
        values, vectors = np.linalg.eigh(expected)
        scaled = (vectors / np.sqrt(values)) @ vectors.T @ constraints
        p = {(s, t): cross(scaled[s], scaled[t]) for s in range(q) for t in range(q)}
        both = np.outer(signs, signs)
        total = sum(
            np.sum(both * p[s, t] * p[t, s]) + np.sum(both * p[s, s] * p[t, t]) for s in range(q) for t in range(q)
        )
        assert _wishart_df(parts, x, weight, bread, constraints) == pytest.approx(q * (q + 1) / total, rel=1e-9)


def test_holm_by_hand():
    # sorted 0.01, 0.02, 0.04, 0.30: times 4, 3, 2, 1 -> 0.04, 0.06, 0.08, 0.30, never falling
    assert holm([0.04, 0.01, 0.30, 0.02]) == pytest.approx([0.08, 0.04, 0.30, 0.06])
    assert holm([0.5, 0.5]) == [1.0, 1.0] and holm([]) == []


def test_a_rankings_pairwise_orderings():
    assert orderings("a>b>c", "a>b>c") == [1, 1, 1]
    assert orderings("b>a>c", "a>b>c") == [0, 1, 1]  # one neighbouring pair swapped: two of three right
    assert orderings("c>b>a", "a>b>c") == [0, 0, 0]
    assert sum(orderings("b>d>a>c", "a>b>c>d")) == 3  # of 6: a>c, b>c, b>d right


def _answers(rows: list[tuple[str, str, str, int]], scenario=lambda clip: "one") -> Answers:
    return Answers(
        [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows], [scenario(r[1]) for r in rows],
        [""] * len(rows), [r[3] for r in rows],
    )  # fmt: skip


def test_the_exact_permutation_test_by_hand():
    """Two schemes, 3 clips each in one scenario: C(6, 3) = 20 arrangements. Clip accuracies a: 1, 1, 1 and
    b: 0, 0, 1/2: the observed difference (1 - 1/6 = 5/6) is matched only by itself and its mirror image, so
    p = 2/20."""
    rows = []
    for p in range(2):
        rows += [(f"p{p}", f"a{c}", "a", 1) for c in range(3)]
        rows += [(f"p{p}", "b0", "b", 0), (f"p{p}", "b1", "b", 0), (f"p{p}", "b2", "b", p)]
    p, how = permutation_p(_answers(rows), "b", "a")
    assert p == pytest.approx(2 / 20) and "exact permutation test over 20 arrangements" in how
    # clips exchange only within their scenario: C(4, 2) x C(2, 1) = 12 arrangements, too few for p < 0.05
    p, how = permutation_p(_answers(rows, scenario=lambda clip: clip[1] in "01" and "s1" or "s2"), "b", "a")
    assert p is None and "only 12 arrangements" in how


def _study(clips: dict[str, int], participants: int, accuracy: dict[str, float], seed: int) -> Answers:
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(participants):
        person = rng.normal(0, 1.0)
        for scheme, count in clips.items():
            for c in range(count):
                logit = math.log(accuracy[scheme] / (1 - accuracy[scheme])) + person
                rows.append((f"p{p}", f"{scheme}{c}", scheme, int(rng.random() < 1 / (1 + math.exp(-logit)))))
    return _answers(rows)


def test_one_clip_against_twelve_is_untestable_and_says_why():
    answers = _study({"one": 1, "twelve": 12}, 40, {"one": 0.95, "twelve": 0.6}, seed=1)
    fit = fit_accuracy(answers, ["one", "twelve"], 0.5)
    (contrast,) = fit.contrasts
    assert fit.estimable and fit.scheme_p is None and contrast.p_value is None and contrast.low is None
    assert "one has 1 clip" in contrast.note and "one has 1 clip" in fit.scheme_test
    one = next(e for e in fit.schemes if e.scheme == "one")
    assert one.p_chance is None and one.low is None and "1 clip" in one.note


def test_too_few_degrees_of_freedom_get_the_permutation_test_instead():
    """2 clips against 2 with 3 participants: the t test's degrees of freedom fall below the floor; the clips
    allow C(4, 2) = 6 arrangements, too few for p < 0.05, which is said; with 4 clips each (70) the permutation
    test runs."""
    fit = fit_accuracy(_study({"a": 2, "b": 2}, 3, {"a": 0.5, "b": 0.8}, seed=3), ["a", "b"], 0.5)
    (contrast,) = fit.contrasts
    assert contrast.p_value is None and "degrees of freedom" in contrast.note and "only 6 arrangements" in contrast.note
    fit = fit_accuracy(_study({"a": 4, "b": 4}, 3, {"a": 0.5, "b": 0.8}, seed=3), ["a", "b"], 0.5)
    (contrast,) = fit.contrasts
    if contrast.df is None:  # the t test's df are data-dependent; where they fall short, the permutation test runs
        assert contrast.p_value is not None and "exact permutation test over 70 arrangements" in contrast.test


def test_each_interval_agrees_with_its_p_and_stays_in_range():
    """The new user's case: 12 participants at 90% accuracy, where a difference's interval ran to 115.6%. Every
    difference's 95% interval excludes 0 exactly when its p is below 0.05, and lies inside (-1, 1); every
    accuracy's inside (0, 1) and excludes chance exactly when its p against chance is below 0.05."""
    for seed in range(12):
        answers = _study({"a": 3, "b": 6, "c": 12}, 12, {"a": 0.97, "b": 0.9, "c": 0.6}, seed=seed)
        fit = fit_accuracy(answers, ["a", "b", "c"], 0.5)
        for c in fit.contrasts:
            if c.p_value is not None and c.low is not None and c.high is not None:
                assert -1 < c.low <= c.difference <= c.high < 1
                assert (c.p_value < 0.05) == (c.low > 0 or c.high < 0)
            if c.or_p_value is not None and c.or_low is not None and c.or_high is not None:
                assert (c.or_p_value < 0.05) == (c.or_low > 1 or c.or_high < 1)  # the odds ratio's own test
        for e in fit.schemes:
            if e.p_chance is not None and e.low is not None and e.high is not None:
                assert 0 < e.low <= e.accuracy <= e.high < 1
                assert (e.p_chance < 0.05) == (e.low > 0.5 or e.high < 0.5)


def test_pairwise_contrasts_are_holm_adjusted_and_the_primary_test_is_not():
    fit = fit_accuracy(
        _study({"a": 3, "b": 6, "c": 12}, 40, {"a": 0.9, "b": 0.75, "c": 0.6}, seed=4), ["a", "b", "c"], 0.5
    )
    tested = [c for c in fit.contrasts if c.p_value is not None]
    assert tested and not any(c.primary for c in fit.contrasts)
    assert [c.p_holm for c in tested] == pytest.approx(holm([c.p_value for c in tested]))
    assert "Hotelling" in fit.scheme_test and "primary" in fit.scheme_test
    chance_tests = [e for e in fit.schemes if e.p_chance is not None]
    assert [e.p_holm for e in chance_tests] == pytest.approx(holm([e.p_chance for e in chance_tests]))


def test_ratings_from_two_participants_get_no_test():
    """Kruskal-Wallis gave p = 0.0034 for difficulty from 2 participants, treating their ratings as independent;
    the ratings' model says the design is too small."""
    ratings = Ratings(
        ["p0"] * 6 + ["p1"] * 6, [f"c{k}" for k in range(6)] * 2, (["a"] * 3 + ["b"] * 3) * 2, [1, 2, 1, 5, 4, 5] * 2
    )
    fit = fit_ratings(ratings, ["a", "b"], 5)
    assert not fit.estimable and fit.p_value is None and "2 participants" in fit.note


def test_ratings_model_intervals_stay_on_the_scale():
    rng = np.random.default_rng(0)
    participant, clip, scheme, value = [], [], [], []
    for p in range(30):
        for c in range(8):
            participant.append(f"p{p}")
            clip.append(f"c{c}")
            scheme.append("a" if c < 4 else "b")
            value.append(int(min(5, max(1, round(4.6 + rng.normal(0, 0.8)))) if c < 4 else rng.integers(1, 4)))
    fit = fit_ratings(Ratings(participant, clip, scheme, value), ["a", "b"], 5)
    assert fit.estimable and fit.p_value is not None and fit.p_value < 0.05
    for m in fit.means:
        assert m.low is not None and m.high is not None and 1 <= m.low <= m.mean <= m.high <= 5
    (c,) = fit.contrasts
    assert c.low is not None and c.high is not None and -4 < c.low <= c.difference <= c.high < 0


def test_a_df_below_the_floor_never_reads_as_the_floor():
    """Three schemes of 2, 3 and 2 clips, 4 participants: the schemes' joint test has 1.96 degrees of freedom,
    which read "only 2.0 ... (at least 2 needed)" before; they are rounded down, as the pairwise tests' are."""
    fit = fit_accuracy(_study({"a": 2, "b": 3, "c": 2}, 4, {"a": 0.6, "b": 0.7, "c": 0.8}, seed=20), list("abc"), 0.5)
    assert fit.scheme_p is None
    assert fit.scheme_test.startswith("not tested: only 1.9 degrees of freedom for the schemes together (at least 2")


def test_an_odds_ratio_without_an_interval_says_why():
    """3 participants, 3 clips a scheme, every answer under b right: the difference has its interval (3.0 degrees
    of freedom) but the odds ratio's own test has 1.7, so its interval is not estimable, and the contrast says why
    instead of leaving a bare dash."""
    fit = fit_accuracy(_study({"a": 3, "b": 3}, 3, {"a": 0.7, "b": 0.9}, seed=2), ["a", "b"], 0.5)
    (contrast,) = fit.contrasts
    assert contrast.low is not None and contrast.odds_ratio > 1 and contrast.or_low is None
    assert contrast.or_note.startswith(
        "interval not estimable: every answer under b was right; only 1.7 degrees of freedom for the odds ratio of b "
        "against a (at least 2 needed)"
    )
