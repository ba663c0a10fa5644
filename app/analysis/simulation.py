"""Simulated studies of a study's own design: who answers which clip, answers drawn from assumed accuracies with
participant and clip effects (a ranking by Thurstone's model), and the report's model fitted to each. `foil power`
measures power on them; `foil prereg` fits one to learn whether a part's primary test can run at all.

A simulated study has the study file's conditions (scheme orders and scenario rotations, assigned in turn), its
parts, pairs and scenarios, and one clip per scheme, scenario and pair as a bundle has. Each answer is right with
probability expit(scheme's log odds + participant effect + clip effect), the effects normal with the given
standard deviations on the log-odds scale, and each scheme's log odds set so that its accuracy over participants
and clips is the one assumed."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache

import numpy as np
from scipy import optimize, special

from app.analysis.design import chance
from app.analysis.model import Answers, ModelResult, fit_accuracy
from app.survey.assignment import conditions
from app.survey.study import Study


@dataclass(frozen=True)
class Layout:
    """Who answers which clip in one part's task for `participants` participants; `correct` left empty."""

    answers: Answers
    participant_index: np.ndarray  # answer -> participant number
    clip_index: np.ndarray  # answer -> clip number
    scheme_index: np.ndarray  # answer -> index into the study's schemes
    clips: int


def layout(study: Study, task: str, participants: int) -> Layout:
    """The answers of `participants` participants in the study's design, conditions assigned in turn as the
    balanced assignment does. A ranking's clip is its block: the scheme's clips of the scenario it ranks. A study
    of updates scores its decided pairs: its controls (`[design] controls`) have no right version, so none here."""
    columns: dict[str, list[str]] = {name: [] for name in ("participant", "clip", "scheme", "scenario", "pair")}
    design = conditions(study)
    controls = {tuple(pair) for pair in study.design.controls} | {tuple(reversed(p)) for p in study.design.controls}
    for k in range(participants):
        condition = design[k % len(design)]
        for p, part in enumerate(study.parts):
            if part.kind != task:
                continue
            for scheme in condition.schemes:
                scenario = study.part_scenario(p, condition.rotation, scheme)
                pairs = (
                    ["-".join(sorted(pair)) for pair in part.pairs if tuple(pair) not in controls]
                    if part.kind == "pairwise"
                    else [""]
                )
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
    schemes = list(study.design.schemes)
    sd = math.hypot(assume.participant_sd, assume.clip_sd)
    eta = np.array([log_odds_for(assume.accuracy[s], sd) for s in schemes])
    person = rng.normal(0.0, assume.participant_sd, plan.participant_index.max() + 1)
    clip = rng.normal(0.0, assume.clip_sd, plan.clips)
    p = special.expit(eta[plan.scheme_index] + person[plan.participant_index] + clip[plan.clip_index])
    return replace(plan.answers, correct=(rng.random(len(p)) < p).astype(int).tolist())


MEASURES = {"pairwise": ("answers",), "ranking": ("orderings", "whole order")}  # what each part's power is of


@cache
def _ranking_noise(agents: int) -> np.ndarray:
    """Common random numbers for `ranking_odds_for`: the same noise for every log odds tried keeps the whole-order
    accuracy a smooth, monotone function of it."""
    return np.random.default_rng(0).normal(0.0, 1.0, (4000, agents))


def whole_order_accuracy(eta: float, sd: float, agents: int) -> float:
    """The share of rankings with every agent in the true order, over participants and clips, when a person ranks
    as Thurstone's model says: agent i's quality (agents - 1 - i) times the discriminability exp(eta + effect),
    seen with standard normal noise, the effect normal with standard deviation `sd`."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(20)
    seen = np.arange(agents)[::-1] * np.exp(eta + sd * nodes)[:, None, None] + _ranking_noise(agents)
    right = np.all(np.diff(seen, axis=2) < 0, axis=2).mean(axis=1)
    return float(right @ weights / weights.sum())


@cache
def ranking_odds_for(accuracy: float, sd: float, agents: int) -> float:
    """The log odds (of discriminability) at which a ranking part's whole-order accuracy is `accuracy`; at or
    below chance (1/k!), the lowest tried."""
    low, high = -8.0, 8.0
    if accuracy <= whole_order_accuracy(low, sd, agents):
        return low
    return float(optimize.brentq(lambda eta: whole_order_accuracy(eta, sd, agents) - accuracy, low, high))


def simulate_rankings(
    study: Study, plan: Layout, assume: Assumptions, rng: np.random.Generator
) -> tuple[Answers, Answers]:
    """One simulated study's rankings (Thurstone's model, scheme accuracies of the whole order), as the whole-order
    answers and as their pairwise orderings (the report's ranking model)."""
    agents = next(len(part.agents) for part in study.parts if part.kind == "ranking")
    sd = math.hypot(assume.participant_sd, assume.clip_sd)
    eta = np.array([ranking_odds_for(assume.accuracy[s], sd, agents) for s in study.design.schemes])
    person = rng.normal(0.0, assume.participant_sd, plan.participant_index.max() + 1)
    clip = rng.normal(0.0, assume.clip_sd, plan.clips)
    scale = np.exp(eta[plan.scheme_index] + person[plan.participant_index] + clip[plan.clip_index])
    seen = np.arange(agents)[::-1] * scale[:, None] + rng.normal(0.0, 1.0, (len(scale), agents))
    pairs = [(i, j) for i in range(agents) for j in range(i + 1, agents)]
    right = np.stack([seen[:, i] > seen[:, j] for i, j in pairs], axis=1)  # ranking x pair
    whole = replace(plan.answers, correct=right.all(axis=1).astype(int).tolist())
    a = plan.answers

    def each(column: Sequence[str]) -> list[str]:
        return list(np.repeat(np.asarray(column), len(pairs)).tolist())

    orderings = Answers(each(a.participant), each(a.clip), each(a.scheme), each(a.scenario), [""] * right.size,
                        right.astype(int).ravel().tolist())  # fmt: skip
    return whole, orderings


def simulated_fits(
    study: Study, task: str, participants: int, assume: Assumptions, studies: int, seed: int
) -> dict[str, list[ModelResult]]:
    """The report's model fitted to `studies` simulated studies, per measure of the part (MEASURES): a ranking part
    both by its pairwise orderings (the report's test) and by whole orders."""
    rng = np.random.default_rng([seed, participants])
    plan = layout(study, task, participants)
    schemes = list(study.design.schemes)
    fits: dict[str, list[ModelResult]] = {measure: [] for measure in MEASURES[task]}
    for _ in range(studies):
        if task == "pairwise":
            fits["answers"].append(
                fit_accuracy(simulate(study, task, plan, assume, rng), schemes, chance(study, task), True)
            )
            continue
        whole, orderings = simulate_rankings(study, plan, assume, rng)
        fits["orderings"].append(fit_accuracy(orderings, schemes, 0.5, True))
        fits["whole order"].append(fit_accuracy(whole, schemes, chance(study, task), True))
    return fits
