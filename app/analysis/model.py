"""The report's model of accuracy: a logistic regression of each answer's correctness on its scheme (with the pair
of agents and the scenario as fixed effects where the design has more than one), whose standard errors are
clustered two ways, by participant and by clip, because every participant answers several clips and every clip
is answered by many participants.

What it estimates: population-averaged accuracies and odds ratios (the accuracy of a scheme over the population of
participants and clips), not the conditional, subject-specific odds ratios of a mixed model, which are larger in
log terms; `foil export` writes an R script that fits that model for readers who want it.

Why this estimator (docs/analysis.md, "The model"): a logistic mixed model with crossed random effects is the
field's convention, but statsmodels' only such model rejects a true null in about half of simulated studies, and
with a handful of clips per scheme a Wald test on any fit of it is too liberal. Cluster-robust covariances with the
CR2 small-sample correction (Bell and McCaffrey 2002), two-way (Cameron, Gelbach and Miller 2011) or by clip,
whichever is larger for the contrast (`_Robust`), each test read against the small-sample reference distribution of
that very test: a t test on Satterthwaite degrees of freedom (Bell and McCaffrey 2002; Pustejovsky and Tipton 2018,
as R's clubSandwich computes them), extended here to the two-way sum, and for several contrasts at once the
approximate Hotelling T² test (clubSandwich's HTZ; Tipton and Pustejovsky 2015). The degrees of freedom count the
clips and participants that inform each contrast: a scheme with 3 clips against one with 12 gets about 3, not 14
(benchmarks/bench_model.py measures the error rates).

A comparison the design cannot test is named as such with its reason, never tested on errors that assume
independence: a scheme with fewer than two clips (ranked sets), a contrast with fewer than MIN_DF degrees of
freedom (then an exact permutation test over clips within scenarios where it has enough arrangements), or schemes
whose answers hold no variation.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

MODEL_VERSION = 2  # raised whenever a change of this model can change a report's numbers (a preregistration records it)
MIN_DF = 2.0  # below this many degrees of freedom a t test's error rate is not controlled: untestable
MIN_ARRANGEMENTS = 20  # a permutation test needs at least this many arrangements to reach p < 0.05
EXACT_ARRANGEMENTS = 50_000  # up to this many every arrangement is counted; above, 20,000 drawn (seed 0)
DEGENERATE = 1e-9  # a robust variance below this share of the model-based one holds no variation to test

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
    low: float | None  # the 95% interval, None where untestable
    high: float | None
    p_chance: float | None  # two-sided test of accuracy = chance; None where untestable (see note)
    clips: int = 0
    df: float | None = None
    p_holm: float | None = None  # p_chance adjusted (Holm) over the part's tests against chance
    note: str = ""  # why there is no test, if there is none


@dataclass(frozen=True)
class Contrast:
    scheme: str
    reference: str
    difference: float  # accuracy of scheme minus that of reference (standardised over both schemes' answers)
    low: float | None  # the difference's 95% interval: the odds ratio's interval on the accuracy scale
    high: float | None
    odds_ratio: float
    or_low: float | None
    or_high: float | None
    p_value: float | None  # None where untestable (see note)
    df: float | None = None
    p_holm: float | None = None  # adjusted (Holm) over the part's pairwise contrasts; None for the primary
    test: str = ""  # the test that gave p_value, in words
    primary: bool = False  # the part's preregistered test (the schemes differ), read unadjusted
    note: str = ""
    or_p_value: float | None = None  # the odds ratio's own t test, on the log-odds scale (its interval's test)
    or_note: str = ""  # why the odds ratio has no interval where the difference has one


@dataclass(frozen=True)
class ModelResult:
    """The fit of one part, or why there is none (`estimable` False, `note` says why)."""

    estimable: bool
    note: str  # what was fitted and any fallback, in words
    formula: str = ""
    participants: int = 0
    clips: int = 0
    df: float = 0.0  # the scheme test's denominator degrees of freedom
    schemes: tuple[SchemeEstimate, ...] = ()
    contrasts: tuple[Contrast, ...] = ()
    scheme_test: str = ""  # the test that the schemes differ (the part's primary test), in words
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


@dataclass(frozen=True)
class _Part:
    """One clustering of the two-way sandwich (participants, clips, or each answer alone), with its sign in the sum
    V = V_participant + V_clip - V_answer."""

    sign: float
    groups: NDArray[np.intp]  # answer -> cluster
    alone: bool  # each answer its own cluster
    cross: Array  # cluster x k x k: X_g' W_g X_g
    adjust: Array  # cluster x k x k: B^1/2 f(C_g) B^1/2, so that B X_g' A_g e_g = adjust_g X_g' e_g (CR2)


def _part(sign: float, groups: NDArray[np.intp], x: Array, weight: Array, bread: Array) -> _Part:
    """The CR2 correction of each cluster's working residuals by A_g = (I - H_gg)^-1/2 (Bell and McCaffrey 2002, as
    R's clubSandwich; where a cluster alone determines a parameter the inverse square root is taken of the
    pseudo-inverse, as clubSandwich does). H_gg has rank at most the number of parameters, so A_g is applied in the
    parameters' space, all clusters at once: A_g X_g = X_g B^1/2 f(C_g) B^-1/2 with C_g = B^1/2 X_g' W_g X_g B^1/2
    and f(c) = (1 - c)^-1/2, which `foil power` needs to refit thousands of studies in seconds."""
    import numpy as np

    k = x.shape[1]
    cross = np.zeros((int(groups.max()) + 1, k, k))
    np.add.at(cross, groups, (x * weight[:, None])[:, :, None] * x[:, None, :])
    values, vectors = np.linalg.eigh(bread)
    root = (vectors * np.sqrt(values)) @ vectors.T
    leverage, axes = np.linalg.eigh(root @ cross @ root)
    scale = np.where(1 - leverage > 1e-8, np.maximum(1 - leverage, 1e-8) ** -0.5, 0.0)
    adjust = root @ ((axes * scale[:, None, :]) @ axes.transpose(0, 2, 1)) @ root
    return _Part(sign, groups, len(cross) == len(x), cross, adjust)


def _covariance(parts: list[_Part], x: Array, residual: Array) -> Array:
    """The two-way CR2 covariance: sum over the parts of sign x sum over clusters of (B X_g' A_g e_g)(...)'."""
    import numpy as np

    cov = np.zeros((x.shape[1], x.shape[1]))
    for part in parts:
        scores = np.zeros((len(part.cross), x.shape[1]))
        np.add.at(scores, part.groups, x * residual[:, None])
        pieces = np.einsum("gkl,gl->gk", part.adjust, scores)
        cov += part.sign * pieces.T @ pieces
    return cov


def _wishart_df(parts: list[_Part], x: Array, weight: Array, bread: Array, constraints: Array) -> float:
    """The degrees of freedom of the robust variance of `constraints` (q x k) under the working model, as
    clubSandwich computes them for one clustering (Satterthwaite for one contrast, the Hotelling T² approximation
    HTZ for several), for the signed sum of the two-way estimator. The estimate is a quadratic form in the
    standardised residuals, y' M y with M = sum_a sign_a u_a u_a' over every cluster a of every part; its
    moments need the cross-products P_ab = u_a' u_b = z_a' z_b - t_a' B t_b (z_a the cluster's weights on
    the answers, t_a = X' W^1/2 z_a), summed here without forming any n x n matrix: products of z's only
    meet where clusters share answers (a participant's answers to one clip), the t's in k x k sums."""
    import numpy as np

    def moments(c: Array) -> tuple[Array, Array]:
        """E[V] (q x q) and S[s,t,u,v] = sum_ab sign_a sign_b P^st_ab P^uv_ab."""
        root_w = np.sqrt(weight)
        loads, ts, signs, groups = [], [], [], []
        for part in parts:
            gc = part.adjust @ c.T  # cluster x k x q
            loads.append(root_w[:, None] * np.einsum("ik,ikq->iq", x, gc[part.groups]))  # z_a[i] per answer
            ts.append(part.cross @ gc)  # cluster x k x q
            signs.append(part.sign)
            groups.append(part.groups)
        q = c.shape[0]
        k_sum = sum(s * np.einsum("akx,aly->xykl", t, t) for s, t in zip(signs, ts, strict=True))  # q q k k
        expected = sum(s * load.T @ load for s, load in zip(signs, loads, strict=True)) - np.einsum(
            "kl,tslk->st", bread, k_sum
        )
        overlap = np.zeros((q, q, q, q))
        for (si, li, pi), (sj, lj, pj) in itertools.product(zip(signs, loads, parts, strict=True), repeat=2):
            n = li[:, :, None] * lj[:, None, :]  # each answer's own cell: where either part is the answers'
            if not (pi.alone or pj.alone):
                cells = (
                    pi.groups if pi is pj else np.unique(pi.groups * len(pj.cross) + pj.groups, return_inverse=True)[1]
                )
                n = np.zeros((int(cells.max()) + 1, q, q))
                np.add.at(n, cells, li[:, :, None] * lj[:, None, :])
            overlap += si * sj * np.einsum("cst,cuv->stuv", n, n)
        y = sum(
            s * np.einsum("is,iku->isuk", load, t[g]) for s, load, t, g in zip(signs, loads, ts, groups, strict=True)
        )
        mixed = np.einsum("isuk,itvk->stuv", y @ bread, y)
        weighted = np.einsum("kl,tvlm->tvkm", bread, k_sum)  # B K^tv
        second = np.einsum("tvkm,usmk->stuv", weighted, weighted)  # tr(B K^tv B K^us)
        return expected, overlap - mixed - mixed.transpose(2, 3, 0, 1) + second

    expected, _ = moments(constraints)
    values, vectors = np.linalg.eigh((expected + expected.T) / 2)
    if np.any(values <= 0):
        return 0.0
    _, s = moments((vectors / np.sqrt(values)) @ vectors.T @ constraints)
    q = constraints.shape[0]
    total = sum(s[a, b, b, a] + s[a, a, b, b] for a in range(q) for b in range(q))
    return float(q * (q + 1) / total) if total > 0 else 0.0


@dataclass(frozen=True)
class _Robust:
    """A fit's cluster-robust variances: two-way (V_participant + V_clip - V_answer, Cameron, Gelbach and Miller
    2011) and clustered by clip alone. Each test reads the larger of the two for its contrast, with that one's
    degrees of freedom. Why: each one-way CR2 correction assumes the other clustering away, so where participants
    differ much and clips little the two-way sum is biased low (9-12% false positives with participant SD 1.5 and
    clip SD 0-0.3), while the clip-clustered variance held 5%; where both clusterings hold variation the two-way
    one is the larger. Participants alone are no candidate: chosen where a few clips' spread happened to look
    small, they made designs with two clips per scheme reject a true null in 10-16% of studies
    (benchmarks/bench_model.py)."""

    candidates: list[tuple[list[_Part], Array]]
    x: Array
    weight: Array
    bread: Array

    def _choose(self, constraints: Array) -> tuple[list[_Part], Array] | None:
        """The candidate with the larger variance of the constraints (scaled by the model-based one), among those
        that are a variance at all for them; None where none holds any variation."""
        import numpy as np

        values, vectors = np.linalg.eigh(constraints @ self.bread @ constraints.T)
        scale = vectors / np.sqrt(values)
        best: tuple[float, list[_Part], Array] | None = None
        for parts, cov in self.candidates:
            variance = constraints @ cov @ constraints.T
            spread = np.linalg.eigvalsh(scale.T @ (variance + variance.T) / 2 @ scale)
            if spread.min() > DEGENERATE and (best is None or spread.sum() > best[0]):
                best = (float(spread.sum()), parts, variance)
        return None if best is None else (best[1], best[2])

    def variance(self, constraints: Array) -> Array:
        """The chosen variance of constraints @ beta (q x q); call after `degrees` found it testable."""
        chosen = self._choose(constraints)
        assert chosen is not None, "variance of an untestable contrast"
        return chosen[1]

    def degrees(self, constraints: Array, what: str) -> tuple[float | None, str]:
        """The test's degrees of freedom, or None with why `what` cannot be tested."""
        chosen = self._choose(constraints)
        if chosen is None:
            return None, (
                f"not tested: the answers under {what} show no spread (between their clips, participants or answers) "
                "to measure its uncertainty by"
            )
        df = _wishart_df(chosen[0], self.x, self.weight, self.bread, constraints)
        return (None, _too_few_degrees(df, what)) if df < MIN_DF else (df, "")


def _too_few_degrees(df: float, what: str) -> str:
    """Why a test on `df` degrees of freedom, below MIN_DF, is not run. The df is rounded down (1.96 reads 1.9),
    never to a "2.0" that reads as enough against the floor beside it."""
    return (
        f"not tested: only {math.floor(df * 10) / 10:.1f} degrees of freedom for {what} (at least {MIN_DF:g} "
        "needed): too few clips or participants inform it"
    )


def _robust(
    x: Array, weight: Array, residual: Array, bread: Array, participant: Sequence[str], clip: Sequence[str]
) -> _Robust:
    """Clustered by participant and by clip at once, and by clip alone (each cluster CR2-corrected)."""
    import numpy as np

    by_participant, by_clip, by_answer = (
        _part(sign, np.unique(groups, return_inverse=True)[1].astype(np.intp), x, weight, bread)
        for sign, groups in ((1.0, participant), (1.0, clip), (-1.0, np.arange(len(x))))
    )
    candidates = [[by_participant, by_clip, by_answer], [by_clip]]
    return _Robust([(parts, _covariance(parts, x, residual)) for parts in candidates], x, weight, bread)


def _t_quantile(df: float) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, df))


def _t_p(t: float, df: float) -> float:
    from scipy import stats

    return float(2 * stats.t.sf(abs(t), df))


def _logit(p: float) -> float:
    return math.log(p / (1 - p))


def _exp(x: float) -> float:
    return math.exp(x) if x < 700 else math.inf


def _expit(x: float) -> float:
    return 1 / (1 + math.exp(-x)) if x >= 0 else math.exp(x) / (1 + math.exp(x))


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment (Holm 1979): controls the chance of any false positive in the family at
    alpha, uniformly more powerful than Bonferroni."""
    order = sorted(range(len(p_values)), key=lambda i: p_values[i])
    adjusted = [0.0] * len(p_values)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(p_values) - rank) * p_values[i]))
        adjusted[i] = running
    return adjusted


def permutation_p(answers: Answers, scheme: str, reference: str) -> tuple[float | None, str]:
    """An exact permutation test that two schemes' clips differ in accuracy: within each scenario the two schemes'
    clips swap labels in every way that keeps each scheme's count there; the statistic is the difference of the
    schemes' mean clip accuracies (each clip's answers together, so participants' answers stay with their clip).
    Valid where clips of one scenario are exchangeable under no difference; None with the reason where there are
    too few arrangements to reach p < 0.05."""
    import numpy as np

    clip_answers: dict[str, list[int]] = {}
    clip_of: dict[str, tuple[str, str]] = {}
    for clip, s, scenario, correct in zip(answers.clip, answers.scheme, answers.scenario, answers.correct, strict=True):
        if s in (scheme, reference):
            clip_answers.setdefault(clip, []).append(correct)
            clip_of[clip] = (s, scenario)
    by_scenario: dict[str, list[tuple[float, bool]]] = {}
    for clip, (s, scenario) in clip_of.items():
        by_scenario.setdefault(scenario, []).append((float(np.mean(clip_answers[clip])), s == scheme))
    blocks = [(np.array([a for a, _ in clips]), np.array([m for _, m in clips])) for clips in by_scenario.values()]
    arrangements = math.prod(math.comb(len(values), int(mask.sum())) for values, mask in blocks)
    if arrangements < MIN_ARRANGEMENTS:
        return None, (
            f"no permutation test either: the two schemes' clips within scenarios allow only {arrangements} "
            f"arrangement{'s' * (arrangements != 1)}, fewer than the {MIN_ARRANGEMENTS} that p < 0.05 needs"
        )
    total = sum(float(values.sum()) for values, _ in blocks)
    m = sum(int(mask.sum()) for _, mask in blocks)
    n = sum(len(values) for values, _ in blocks)

    def statistic(chosen: Sequence[NDArray[np.bool_]]) -> float:
        picked = sum(float(values[mask].sum()) for (values, _), mask in zip(blocks, chosen, strict=True))
        return abs(picked / m - (total - picked) / (n - m))

    observed = statistic([mask for _, mask in blocks])
    if arrangements <= EXACT_ARRANGEMENTS:
        masks = [
            [
                np.isin(np.arange(len(values)), combo)
                for combo in itertools.combinations(range(len(values)), int(k.sum()))
            ]
            for values, k in blocks
        ]
        found = [statistic(choice) for choice in itertools.product(*masks)]
        how = f"exact permutation test over {arrangements} arrangements of clips within scenarios"
    else:
        rng = np.random.default_rng(0)
        found = [statistic([rng.permutation(mask) for _, mask in blocks]) for _ in range(20_000)]
        how = "permutation test over 20,000 drawn arrangements of clips within scenarios (seed 0)"
    return float(np.mean(np.asarray(found) >= observed - 1e-12)), how


def fit_accuracy(answers: Answers, schemes: Sequence[str], chance: float, primary_only: bool = False) -> ModelResult:
    """Per scheme: accuracy with its 95% interval and a test against `chance`; per pair of schemes: the
    difference in accuracy and the odds ratio with 95% intervals, both from one test; and the test that the
    schemes differ, the part's primary test (with two schemes, their one contrast). Tests against chance and,
    with three schemes or more, the pairwise contrasts are secondary: each family is Holm-adjusted.
    `primary_only` (for `foil power`, which refits thousands of studies) leaves the secondary tests out.

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

    def too_few(parameters: int, formula: str) -> ModelResult:
        return ModelResult(
            False,
            f"not tested: {participants} participant{'s' * (participants != 1)} and {clips} clip"
            f"{'s' * (clips != 1)} are too few clusters for {parameters} parameters; the intervals need more "
            "participants (or clips) than that",
            formula,
            participants,
            clips,
        )

    if min(participants, clips) <= len(present):  # too few even for the schemes alone: no fit can help
        return too_few(len(present), "correct ~ scheme")
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
        return ModelResult(False, "not tested: the fit does not converge", formula, participants, clips)
    scheme_of = np.asarray(answers.scheme)
    boundary = [s for s in present if len(set(y[scheme_of == s])) == 1]
    alike = {s: f"every answer under {s} was {'right' if y[scheme_of == s][0] else 'wrong'}" for s in boundary}
    if boundary:
        notes.append(
            f"every answer under {', '.join(boundary)} is the same (all right or all wrong): "
            "a clustered interval is too narrow there; read Table 1's Wilson interval for it"
        )
    if min(participants, clips) <= x.shape[1]:
        return too_few(x.shape[1], formula)
    beta, fitted = fit
    weight = fitted * (1 - fitted)
    residual = y - fitted
    bread = np.asarray(np.linalg.inv((x * weight[:, None]).T @ x), dtype=np.float64)
    robust = _robust(x, weight, residual, bread, answers.participant, answers.clip)
    degrees = robust.degrees
    clips_of = {s: len(set(c for c, sc in zip(answers.clip, answers.scheme, strict=True) if sc == s)) for s in present}

    def few_clips(names: Sequence[str]) -> str:
        few = [s for s in names if clips_of[s] < 2]
        return "; ".join(
            f"not tested: {s} has {clips_of[s]} clip in this part, and one clip cannot show how much its accuracy "
            "depends on the clip"
            for s in few
        )

    gradients: dict[str, Array] = {}
    estimates: list[SchemeEstimate] = []
    for k, scheme in enumerate(present):
        rows = x[:, k] == 1
        accuracy = float(fitted[rows].mean())
        gradients[scheme] = (weight[rows, None] * x[rows]).mean(axis=0)
        reason = few_clips([scheme]) or ("not asked for" if primary_only else "")
        df, reason = (None, reason) if reason else degrees(gradients[scheme][None, :], scheme)
        if df is None:
            estimates.append(
                SchemeEstimate(scheme, int(rows.sum()), accuracy, None, None, None, clips_of[scheme], note=reason)
            )
            continue
        se = math.sqrt(float(robust.variance(gradients[scheme][None, :])[0, 0])) / (accuracy * (1 - accuracy))
        centre, quantile = _logit(accuracy), _t_quantile(df)
        estimates.append(
            SchemeEstimate(
                scheme,
                int(rows.sum()),
                accuracy,
                _expit(centre - quantile * se),
                _expit(centre + quantile * se),
                _t_p((centre - _logit(chance)) / se, df),
                clips_of[scheme],
                df,
            )
        )
    tested = [e.p_chance for e in estimates if e.p_chance is not None]
    adjusted = iter(holm(tested))
    estimates = [e if e.p_chance is None else replace(e, p_holm=next(adjusted)) for e in estimates]

    contrasts: list[Contrast] = []
    for i, reference in enumerate(present):
        for j in range(i + 1, len(present) if len(present) == 2 or not primary_only else i + 1):
            scheme = present[j]
            log_odds = np.zeros(x.shape[1])
            log_odds[j], log_odds[i] = 1, -1
            log_or = float(log_odds @ beta)
            gradient = gradients[scheme] - gradients[reference]
            difference = estimates[j].accuracy - estimates[i].accuracy
            what = f"{scheme} against {reference}"
            reason = few_clips([reference, scheme])
            df, reason = (None, reason) if reason else degrees(gradient[None, :], what)
            if df is None:
                p, test = None, ""
                if "degrees of freedom" in reason:
                    p, test = permutation_p(answers, scheme, reference)
                    reason, test = (f"{reason}; {test}", "") if p is None else (reason, test)
                contrasts.append(
                    Contrast(
                        scheme, reference, difference, None, None, _exp(log_or), None, None, p, test=test, note=reason
                    )  # fmt: skip
                )
                continue
            # the difference's t test on Fisher's z scale (atanh): its interval stays inside (-1, 1) and excludes
            # 0 exactly when its p is below 0.05
            bounded = max(min(difference, 1 - 1e-12), -1 + 1e-12)
            se = math.sqrt(float(robust.variance(gradient[None, :])[0, 0])) / (1 - bounded**2)
            quantile = _t_quantile(df)
            or_df, or_reason = degrees(log_odds[None, :], f"the odds ratio of {what}")
            # near the ceiling a scheme's log odds rest on few answers that vary, so its own test may lack the
            # degrees of freedom the difference's has: say why rather than leave a bare dash
            or_why = [alike[s] for s in (scheme, reference) if s in alike] + [or_reason.removeprefix("not tested: ")]
            or_se = math.sqrt(float(robust.variance(log_odds[None, :])[0, 0])) if or_df else 0.0
            or_half = _t_quantile(or_df) * or_se if or_df else 0.0
            contrasts.append(
                Contrast(
                    scheme,
                    reference,
                    difference,
                    math.tanh(math.atanh(bounded) - quantile * se),
                    math.tanh(math.atanh(bounded) + quantile * se),
                    _exp(log_or),
                    _exp(log_or - or_half) if or_df else None,
                    _exp(log_or + or_half) if or_df else None,
                    _t_p(math.atanh(bounded) / se, df),
                    df,
                    test=f"t test of the difference on {df:.1f} degrees of freedom (Satterthwaite)",
                    or_p_value=_t_p(log_or / or_se, or_df) if or_df else None,
                    or_note="" if or_df else "interval not estimable: " + "; ".join(or_why),
                )
            )
    testable = [s for s in present if clips_of[s] >= 2]
    if len(present) == 2 and len(contrasts) == 1:
        (only,) = contrasts
        contrasts = [replace(only, primary=True)]
        scheme_test = f"{only.test} (the primary test: the two schemes differ)" if only.test else only.note
        scheme_p, scheme_df = only.p_value, only.df or 0.0
    else:
        secondary = [c.p_value for c in contrasts if c.p_value is not None]
        adjusted = iter(holm(secondary))
        contrasts = [c if c.p_value is None else replace(c, p_holm=next(adjusted)) for c in contrasts]
        scheme_test, scheme_p, scheme_df = _scheme_test(beta, robust, present, testable)
        scheme_test += " (the primary test: the schemes differ)" if scheme_p is not None else ""
        if len(testable) < len(present):
            scheme_test += f"; {', '.join(s for s in present if s not in testable)} left out (fewer than two clips)"
    if len(present) < len(schemes):
        notes.append(f"schemes without answers left out: {', '.join(s for s in schemes if s not in present)}")
    return ModelResult(
        True,
        "; ".join(notes),
        formula,
        participants,
        clips,
        scheme_df,
        tuple(estimates),
        tuple(contrasts),
        scheme_test,
        scheme_p,
    )


def _scheme_test(
    beta: Array, robust: _Robust, present: list[str], testable: list[str]
) -> tuple[str, float | None, float]:
    """Do the schemes differ? The approximate Hotelling T² test (HTZ: Tipton and Pustejovsky 2015, as
    clubSandwich's Wald_test) that the testable schemes' log odds are equal: F = (nu - q + 1) / (nu q) Q on
    (q, nu - q + 1) degrees of freedom, with Q the robust Wald statistic and nu from the estimator's moments."""
    import numpy as np
    from scipy import stats

    if len(testable) < 2:
        return "not tested: fewer than two schemes have two clips or more", None, 0.0
    index = [present.index(s) for s in testable]
    constraints = np.zeros((len(index) - 1, len(beta)))
    for row, k in enumerate(index[1:]):
        constraints[row, index[0]], constraints[row, k] = -1, 1
    nu, reason = robust.degrees(constraints, "the schemes together")
    q = len(index) - 1
    if nu is None:
        return reason, None, 0.0
    df = nu - q + 1
    if df < MIN_DF:
        return _too_few_degrees(df, "the schemes together"), None, 0.0
    difference = constraints @ beta
    wald = float(difference @ np.linalg.solve(robust.variance(constraints), difference))
    f = (nu - q + 1) / (nu * q) * wald
    return (
        f"approximate Hotelling T² test (HTZ), F on {q} and {df:.1f} degrees of freedom",
        float(stats.f.sf(f, q, df)),
        df,
    )


@dataclass(frozen=True)
class Ratings:
    """A rating question's answers: who gave each, about which clip (a ranking's: its set), under which scheme."""

    participant: Sequence[str]
    clip: Sequence[str]
    scheme: Sequence[str]
    value: Sequence[int]


@dataclass(frozen=True)
class RatingMean:
    scheme: str
    n: int
    mean: float
    low: float | None  # the 95% interval, inside the scale; None where untestable (see note)
    high: float | None
    note: str = ""


@dataclass(frozen=True)
class RatingContrast:
    scheme: str
    reference: str
    difference: float  # mean rating of scheme minus that of reference, in points
    low: float | None
    high: float | None
    p_value: float | None
    p_holm: float | None = None  # adjusted (Holm) over the question's pairwise contrasts
    df: float | None = None
    note: str = ""


@dataclass(frozen=True)
class RatingResult:
    """One rating question's model, or why there is none (`estimable` False, `note` says why)."""

    estimable: bool
    note: str
    participants: int = 0
    clips: int = 0
    means: tuple[RatingMean, ...] = ()
    contrasts: tuple[RatingContrast, ...] = ()
    test: str = ""  # that the schemes' mean ratings differ
    p_value: float | None = None


def fit_ratings(ratings: Ratings, schemes: Sequence[str], points: int) -> RatingResult:
    """Mean rating per scheme with its 95% interval, the pairwise differences (Holm-adjusted) and the test that
    the schemes differ, from a linear model rating ~ scheme with the accuracy model's errors: clustered by
    participant and by clip, CR2, Satterthwaite and HTZ degrees of freedom, untestable comparisons named. Ratings
    are repeated measures as answers are: a participant rates several clips and a clip is rated by many. Each
    interval is computed on a bounded scale (the mean's position on the scale through the logit, a difference's
    share of the scale's width through atanh) and mapped back, so it stays within the scale, and each p is the
    same test as its interval."""
    import numpy as np

    present = [s for s in schemes if s in set(ratings.scheme)]
    participants, clips = len(set(ratings.participant)), len(set(ratings.clip))
    if len(present) < 1:
        return RatingResult(False, "not tested: no ratings")
    x = np.column_stack([(np.asarray(ratings.scheme) == s).astype(float) for s in present])
    if min(participants, clips) <= x.shape[1]:
        return RatingResult(
            False,
            f"not tested: {participants} participant{'s' * (participants != 1)} and {clips} clip"
            f"{'s' * (clips != 1)} are too few clusters for {x.shape[1]} schemes",
            participants,
            clips,
        )
    y = np.asarray(ratings.value, dtype=float)
    bread = np.linalg.inv(x.T @ x)
    beta = bread @ x.T @ y
    robust = _robust(x, np.ones(len(y)), y - x @ beta, bread, ratings.participant, ratings.clip)
    width = points - 1
    clips_of = {s: len(set(c for c, sc in zip(ratings.clip, ratings.scheme, strict=True) if sc == s)) for s in present}
    means: list[RatingMean] = []
    for k, scheme in enumerate(present):
        mean, n = float(beta[k]), int(x[:, k].sum())
        unit = np.eye(len(present))[k]
        df, reason = (
            (None, f"not tested: {scheme} has {clips_of[scheme]} clip")
            if clips_of[scheme] < 2
            else robust.degrees(unit[None, :], scheme)
        )
        share = (mean - 1) / width
        if df is None or not 0 < share < 1:
            means.append(RatingMean(scheme, n, mean, None, None, reason or "not tested: every rating at one end"))
            continue
        half = _t_quantile(df) * math.sqrt(float(robust.variance(unit[None, :])[0, 0])) / width / (share * (1 - share))
        means.append(
            RatingMean(
                scheme, n, mean, 1 + width * _expit(_logit(share) - half), 1 + width * _expit(_logit(share) + half)
            )
        )
    contrasts: list[RatingContrast] = []
    for i, reference in enumerate(present):
        for j in range(i + 1, len(present)):
            scheme = present[j]
            contrast = np.zeros(len(present))
            contrast[j], contrast[i] = 1, -1
            difference = float(contrast @ beta)
            few = [s for s in (reference, scheme) if clips_of[s] < 2]
            df, reason = (
                (None, f"not tested: {', '.join(few)} {'has' if len(few) == 1 else 'have'} one clip")
                if few
                else robust.degrees(contrast[None, :], f"{scheme} against {reference}")
            )
            if df is None:
                contrasts.append(RatingContrast(scheme, reference, difference, None, None, None, note=reason))
                continue
            share = max(min(difference / width, 1 - 1e-12), -1 + 1e-12)
            se = math.sqrt(float(robust.variance(contrast[None, :])[0, 0])) / width / (1 - share**2)
            quantile = _t_quantile(df)
            contrasts.append(
                RatingContrast(
                    scheme,
                    reference,
                    difference,
                    width * math.tanh(math.atanh(share) - quantile * se),
                    width * math.tanh(math.atanh(share) + quantile * se),
                    _t_p(math.atanh(share) / se, df),
                    df=df,
                )
            )
    adjusted = iter(holm([c.p_value for c in contrasts if c.p_value is not None]))
    contrasts = [c if c.p_value is None else replace(c, p_holm=next(adjusted)) for c in contrasts]
    testable = [s for s in present if clips_of[s] >= 2]
    test, p, _ = _scheme_test(beta, robust, present, testable)
    return RatingResult(True, "", participants, clips, tuple(means), tuple(contrasts), test, p)
