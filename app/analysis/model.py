"""The report's model of accuracy: a logistic regression of each answer's correctness on its scheme (with the pair
of agents and the scenario as fixed effects where the design has more than one), whose standard errors are
clustered two ways, by participant and by clip, because every participant answers several clips and every clip
is answered by many participants.

Why this estimator (docs/analysis.md, "The model"): a logistic mixed model with crossed random effects for
participant and clip is the field's convention, but statsmodels' only such model (a variational Bayes fit)
rejects a true null in about half of simulated studies, and with a handful of clips per scheme a Wald test on
any fit of it is too liberal. The two-way cluster-robust covariance (Cameron, Gelbach and Miller 2011) with the
CR2 small-sample correction of each part (Bell and McCaffrey 2002), read against a t distribution on G - 1 degrees
of freedom with G the smaller number of clusters (clips, or participants if fewer), as Cameron, Gelbach and Miller
recommend for two-way clustering, rejects a true null in 3-7% of simulated pairwise studies in Foil's designs
(benchmarks/bench_model.py; G minus the parameters made the paper's test reject in 2%). It makes no assumption
about how answers of a participant or of a clip correlate, so by-participant scheme slopes are covered without
fitting them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

MODEL_VERSION = 2  # raised whenever a change of this model can change a report's numbers (a preregistration records it)

if TYPE_CHECKING:  # numpy is imported where it runs: the server imports this module at start-up
    import numpy as np
    from numpy.typing import NDArray

    Array = NDArray[np.float64]


@dataclass(frozen=True)
class Answers:
    """A part's scored answers, one entry per answer in each column: who gave it, to which clip (for a ranking,
    the ranked clips), under which scheme and scenario, comparing which agents (empty for a ranking)."""

    participant: Sequence[str]
    clip: Sequence[str]
    scheme: Sequence[str]
    scenario: Sequence[str]
    pair: Sequence[str]
    correct: Sequence[int]


@dataclass(frozen=True)
class SchemeEstimate:
    scheme: str
    n: int
    accuracy: float
    low: float
    high: float
    p_chance: float  # two-sided test of accuracy = chance


@dataclass(frozen=True)
class Contrast:
    scheme: str
    reference: str
    difference: float  # accuracy of scheme minus that of reference
    low: float
    high: float
    odds_ratio: float
    or_low: float
    or_high: float
    p_value: float


@dataclass(frozen=True)
class ModelResult:
    """The fit of one part, or why there is none (`estimable` False, `note` says why)."""

    estimable: bool
    note: str  # what was fitted and any fallback, in words
    formula: str = ""
    participants: int = 0
    clips: int = 0
    df: int = 0
    schemes: tuple[SchemeEstimate, ...] = ()
    contrasts: tuple[Contrast, ...] = ()
    scheme_test: str = ""  # the test that the schemes differ, in words
    scheme_p: float | None = None


def _levels(values: Sequence[str]) -> list[str]:
    return list(dict.fromkeys(values))


def _design(answers: Answers, schemes: list[str], covariates: tuple[str, ...]) -> Array:
    """One indicator per scheme (no intercept: each scheme's log odds at the reference levels), then indicators of
    the other levels of each covariate, leaving out any column the earlier ones already determine (a scheme
    whose clips come from a scenario of its own, as the representative scheme's)."""
    import numpy as np

    scheme = np.asarray(answers.scheme)
    columns = [(scheme == s).astype(float) for s in schemes]
    for covariate in covariates:
        values = np.asarray(getattr(answers, covariate))
        for level in _levels(list(values))[1:]:
            column = (values == level).astype(float)
            trial = np.column_stack([*columns, column])
            if np.linalg.matrix_rank(trial) == trial.shape[1]:
                columns.append(column)
    return np.column_stack(columns)


def _fit(y: Array, x: Array) -> tuple[Array, Array] | None:
    """Logistic regression with Firth's penalty (the Jeffreys prior; Firth 1993, Heinze and Schemper 2002):
    coefficients and fitted probabilities. Unlike the maximum-likelihood fit its estimates stay finite when a
    scheme, pair or scenario has only right (or only wrong) answers, which small studies and clear clips give;
    its bias is smaller too. None when it does not converge."""
    import numpy as np

    beta = np.zeros(x.shape[1])
    for _ in range(200):
        mu = 1 / (1 + np.exp(-(x @ beta)))
        weight = mu * (1 - mu)
        inverse = np.linalg.inv((x * weight[:, None]).T @ x)
        leverage = np.einsum("ij,jk,ik->i", x, inverse, x) * weight
        step = inverse @ (x.T @ (y - mu + leverage * (0.5 - mu)))
        step *= min(1.0, 2.0 / max(np.max(np.abs(step)), 1e-300))  # at most 2 on the log-odds scale per step
        beta = beta + step
        if np.max(np.abs(step)) < 1e-9:
            return beta, 1 / (1 + np.exp(-(x @ beta)))
    return None


def _meat(x: Array, residual: Array, weight: Array, bread: Array, groups: NDArray[np.intp]) -> Array:
    """The sandwich's middle for one clustering, each cluster's working residuals corrected by (I - H_gg)^-1/2
    (CR2: Bell and McCaffrey 2002, as R's clubSandwich): without it the few clusters of a small study give too
    small standard errors (the stronger (I - H_gg)^-1 of Mancl and DeRouen made the tests too conservative in
    the simulations). Where a cluster alone determines a parameter (a scheme with one clip) the inverse square
    root is taken of the pseudo-inverse, as clubSandwich does.

    H_gg has rank at most the number of parameters, so the correction is computed in the parameters' space, all
    clusters at once: X_g' (I - H_gg)^-1/2 e_g = B^-1/2 f(C_g) B^1/2 X_g' e_g with C_g = B^1/2 X_g' W_g X_g B^1/2
    and f(c) = (1 - c)^-1/2, which `foil power` needs to refit thousands of studies in seconds."""
    import numpy as np

    members = (groups[:, None] == np.arange(int(groups.max()) + 1)).astype(float).T  # cluster x answer
    k = x.shape[1]
    cross = (members @ ((x * weight[:, None])[:, :, None] * x[:, None, :]).reshape(len(x), k * k)).reshape(-1, k, k)
    values, vectors = np.linalg.eigh(bread)
    root = (vectors * np.sqrt(values)) @ vectors.T
    inverse_root = (vectors / np.sqrt(values)) @ vectors.T
    leverage, axes = np.linalg.eigh(root @ cross @ root)
    scale = np.where(1 - leverage > 1e-8, np.maximum(1 - leverage, 1e-8) ** -0.5, 0.0)
    rotated = np.einsum("gji,jk,gk->gi", axes, root, members @ (x * residual[:, None]))
    scores = np.einsum("jk,gkl,gl->gj", inverse_root, axes, scale * rotated)
    return np.asarray(scores.T @ scores, dtype=np.float64)


def _t_quantile(df: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, df))


def _t_p(t: float, df: int) -> float:
    from scipy import stats

    return float(2 * stats.t.sf(abs(t), df))


def _logit(p: float) -> float:
    return math.log(p / (1 - p))


def _exp(x: float) -> float:
    return math.exp(x) if x < 700 else math.inf


def _expit(x: float) -> float:
    return 1 / (1 + math.exp(-x)) if x >= 0 else math.exp(x) / (1 + math.exp(x))


def fit_accuracy(answers: Answers, schemes: Sequence[str], chance: float) -> ModelResult:
    """Per scheme: accuracy with its 95% interval and a test against `chance`; per pair of schemes: the
    difference in accuracy and the odds ratio with 95% intervals; and the test that the schemes differ.

    A scheme's accuracy is the mean of the fitted probabilities of its answers, which for this model is its raw
    accuracy (Table 1): what the model adds is an interval that counts participants and clips, not answers."""
    import numpy as np

    present = [s for s in schemes if s in set(answers.scheme)]
    participants = len(set(answers.participant))
    clips = len(set(answers.clip))
    if not present:
        return ModelResult(False, "not fitted: no answers")
    y = np.asarray(answers.correct, dtype=float)
    notes: list[str] = []
    covariates = tuple(c for c in ("pair", "scenario") if len(set(getattr(answers, c))) > 1)
    x = _design(answers, present, covariates)
    fit = _fit(y, x)
    if fit is None and covariates:
        notes.append(f"{' and '.join(covariates)} left out: with them the fit does not converge")
        covariates = ()
        x = _design(answers, present, covariates)
        fit = _fit(y, x)
    formula = "correct ~ " + " + ".join(["scheme", *covariates])
    if fit is None:
        return ModelResult(False, "not estimable: the fit does not converge", formula, participants, clips)
    scheme_of = np.asarray(answers.scheme)
    boundary = [s for s in present if len(set(y[scheme_of == s])) == 1]
    if boundary:
        notes.append(
            f"every answer under {', '.join(boundary)} is the same (all right or all wrong): "
            "a clustered interval is too narrow there; read Table 1's Wilson interval for it"
        )
    if min(participants, clips) <= x.shape[1]:
        return ModelResult(
            False,
            f"not tested: {participants} participants and {clips} clips are too few clusters for "
            f"{x.shape[1]} parameters; the intervals need more participants (or clips) than that",
            formula,
            participants,
            clips,
        )
    df = min(participants, clips) - 1  # G - 1 with G the smaller number of clusters (Cameron et al. 2011)
    beta, fitted = fit
    weight = fitted * (1 - fitted)
    residual = y - fitted
    bread = np.asarray(np.linalg.inv((x * weight[:, None]).T @ x), dtype=np.float64)
    by_participant, by_clip = (
        _meat(x, residual, weight, bread, np.unique(groups, return_inverse=True)[1])
        for groups in (answers.participant, answers.clip)
    )
    leverage = np.einsum("ij,jk,ik->i", x, bread, x) * weight  # each answer on its own: H_ii
    scores = x * (residual * (1 - leverage) ** -0.5)[:, None]
    meat = by_participant + by_clip - scores.T @ scores
    cov = bread @ meat @ bread
    if np.any(np.linalg.eigvalsh((cov + cov.T) / 2) <= 0):
        # the two-way estimate can fail to be positive definite; adding both clusterings' parts without taking
        # out the answers' own is the conservative fallback
        notes.append("two-way covariance not positive definite: the participant and clip parts were added")
        cov = bread @ (by_participant + by_clip) @ bread
    quantile = _t_quantile(df)
    degenerate: list[str] = []

    def variance(vector: Array, what: str = "") -> float:
        """vector' V vector under the cluster-robust V, or the model-based one where the robust is degenerate: a
        scheme whose answers are all alike (all right, all wrong) leaves its clusters no variation to measure, and
        two such schemes' comparison gets a variance of zero."""
        robust, model_based = float(vector @ cov @ vector), float(vector @ bread @ vector)
        if robust > DEGENERATE * model_based:
            return robust
        if what:
            degenerate.append(what)
        return model_based

    gradients: dict[str, Array] = {}
    estimates: list[SchemeEstimate] = []
    for k, scheme in enumerate(present):
        rows = x[:, k] == 1
        accuracy = float(fitted[rows].mean())
        gradients[scheme] = (weight[rows, None] * x[rows]).mean(axis=0)
        se = math.sqrt(variance(gradients[scheme], scheme)) / (accuracy * (1 - accuracy))
        centre = _logit(accuracy)
        estimates.append(
            SchemeEstimate(
                scheme,
                int(rows.sum()),
                accuracy,
                _expit(centre - quantile * se),
                _expit(centre + quantile * se),
                _t_p((centre - _logit(chance)) / se, df),
            )
        )
    contrasts: list[Contrast] = []
    for i, reference in enumerate(present):
        for j in range(i + 1, len(present)):
            scheme = present[j]
            contrast = np.zeros(x.shape[1])
            contrast[j], contrast[i] = 1, -1
            log_or = float(contrast @ beta)
            se_log_or = math.sqrt(variance(contrast, f"{scheme} against {reference}"))
            gradient = gradients[scheme] - gradients[reference]
            se_diff = math.sqrt(variance(gradient))
            difference = estimates[j].accuracy - estimates[i].accuracy
            contrasts.append(
                Contrast(
                    scheme,
                    reference,
                    difference,
                    difference - quantile * se_diff,
                    difference + quantile * se_diff,
                    _exp(log_or),
                    _exp(log_or - quantile * se_log_or),
                    _exp(log_or + quantile * se_log_or),
                    _t_p(log_or / se_log_or, df),
                )
            )
    scheme_test, scheme_p = _scheme_test(beta, bread if degenerate else cov, len(present), df)
    if degenerate:
        notes.append(
            "cluster-robust variance degenerate (answers all alike) for "
            f"{', '.join(degenerate)}: model-based standard errors there and in the F test"
        )
    if len(present) < len(schemes):
        notes.append(f"schemes without answers left out: {', '.join(s for s in schemes if s not in present)}")
    return ModelResult(
        True,
        "; ".join(notes),
        formula,
        participants,
        clips,
        df,
        tuple(estimates),
        tuple(contrasts),
        scheme_test,
        scheme_p,
    )


DEGENERATE = 1e-9  # a robust variance below this share of the model-based one is treated as zero


def _scheme_test(beta: Array, cov: Array, k: int, df: int) -> tuple[str, float | None]:
    """Do the schemes differ? A Wald F test that the k schemes' log odds are equal, on (k - 1, df) degrees of
    freedom (for two schemes the square of the odds ratio's t test)."""
    import numpy as np
    from scipy import stats

    if k < 2:
        return "not tested: fewer than two schemes have answers", None
    contrast = np.zeros((k - 1, len(beta)))
    for i in range(k - 1):
        contrast[i, 0], contrast[i, i + 1] = -1, 1
    difference = contrast @ beta
    f = float(difference @ np.linalg.solve(contrast @ cov @ contrast.T, difference)) / (k - 1)
    return f"Wald F test, {k - 1} and {df} degrees of freedom", float(stats.f.sf(f, k - 1, df))
