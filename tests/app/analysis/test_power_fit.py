"""`foil power`'s N for 80% and 90%: a monotone curve fitted to the simulated studies' rejections at every N, checked
on hand-made binomial counts, and the command's error for too few studies naming its real default."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.analysis.power import Crossing, PowerCurve, crossings, describe, fit_power_curve, run_power

STUDIES = Path(__file__).resolve().parents[3] / "studies"

GRID = list(range(12, 121, 12))


def counts(curve: PowerCurve, studies: int) -> list[int]:
    return [round(curve.power(n) * studies) for n in GRID]


@pytest.mark.parametrize("ceiling", [1.0, 0.9])
def test_a_known_curve_gives_its_n(ceiling):
    """Counts on a curve that reaches 80% at N = 71 (rising to 100%, or levelling off at 90%) give back that N and
    an interval around it; 1000 studies per N leave only rounding noise."""
    a = math.log(0.8 / (ceiling - 0.8)) - 2.0 * math.log(71)
    truth = PowerCurve(a, 2.0, ceiling)
    eighty, ninety = crossings(GRID, counts(truth, 1000), 1000)
    assert eighty.n == pytest.approx(71, abs=1.5) and eighty.low < 71 < eighty.high
    assert ninety.n == pytest.approx(truth.participants_for(0.9), abs=2) if ceiling == 1 else ninety.n > 1e6
    assert describe(eighty, "pairwise").startswith(f"80% power: at about N = {math.ceil(eighty.n)} (95% interval ")


def test_noisy_counts_that_dip_give_one_monotone_answer():
    """100 studies per N: 83% at 60 is noise on a curve that reaches 80% later (the first N whose own estimate
    reached 80% was what foil power used to report); the fit rises at every N and gives one N with an interval."""
    rejections = [5, 22, 40, 61, 83, 70, 76, 88, 81, 90]
    curve = fit_power_curve(GRID, rejections, 100)
    powers = [curve.power(n) for n in range(GRID[0], GRID[-1] + 1)]
    assert all(later >= earlier for earlier, later in zip(powers, powers[1:], strict=False))
    eighty = crossings(GRID, rejections, 100)[0]
    assert 60 < eighty.n < 96 and eighty.low < eighty.n < eighty.high
    assert crossings(GRID, rejections, 100) == crossings(GRID, rejections, 100)  # the bootstrap is seeded


def test_counts_of_none_or_all_studies_give_a_finite_fit():
    assert describe(crossings(GRID, [100] * 10, 100)[0], "pairwise") == (
        "80% power: at 12 participants or fewer, the smallest N tried"
    )
    nothing = crossings(GRID, [0] * 10, 100)[0]
    assert math.isfinite(fit_power_curve(GRID, [0] * 10, 100).a) and nothing.n > GRID[-1]


def test_a_curve_that_never_reaches_80_percent_says_so_and_what_would():
    """Still rising at the largest N: try more participants. Levelling off below 80%, as a ranking part's few
    ranked sets make it: more participants would not help, so the advice is more scenarios, not
    --max-participants."""
    rising = PowerCurve(math.log(0.5 / 0.5) - 2.0 * math.log(120), 2.0, 1.0)  # 50% at 120
    text = describe(crossings(GRID, counts(rising, 100), 100)[0], "pairwise")
    assert text.startswith("80% power: not reached within 120 participants") and "--max-participants" in text
    ranking = describe(crossings(GRID, counts(rising, 100), 100)[0], "ranking")  # still rising: sets come first
    assert "more ranked sets (scenarios) help more than more participants" in ranking
    flat = [10, 25, 33, 38, 40, 41, 43, 42, 43, 44]
    for task, more in (("ranking", "more ranked sets (scenarios)"), ("pairwise", "more clips per scheme")):
        text = describe(crossings(GRID, flat, 100)[0], task)
        assert "not reached within 120" in text and "levels off at 0.4" in text and more in text
        assert "--max-participants" not in text


def test_a_crossing_outside_the_interval_grid_is_written_as_a_bound():
    found = Crossing(0.8, 12, 120, n=20.2, low=9.0, high=math.inf, ceiling=1.0, power_at_last=0.99)
    assert describe(found, "pairwise") == "80% power: at about N = 21 (95% interval 12 or fewer to more than 120)"


def test_too_few_studies_names_the_commands_default(paper_study, capsys):
    """The error used to say the default is 200 studies; it is the command line's."""
    from search.cli import build_parser, main

    path, _ = paper_study
    default = build_parser().parse_args(["power", str(path)]).studies
    with pytest.raises(ValueError, match=rf"give at least 10 \(default {default}\)"):
        run_power(study_path=str(path), pairwise="", ranking=None, pilot=None, participant_sd=1.0, clip_sd=0.5,
                  largest=120, studies=5, seed=0)  # fmt: skip
    assert main(["power", str(path), "--studies", "5"]) == 2
    assert f"(default {default})" in capsys.readouterr().err


def test_the_fit_needs_three_numbers_of_participants(paper_study, capsys):
    path, study = paper_study
    schemes = ",".join(f"{s}=0.8" for s in study.design.schemes)
    assert run_power(study_path=str(path), pairwise=schemes, ranking=None, pilot=None, participant_sd=1.0,
                     clip_sd=0.5, largest=8, studies=10, seed=0) == 0  # fmt: skip
    assert "give a --max-participants of 24 or more" in capsys.readouterr().out


@pytest.mark.slow
def test_the_interval_covers_the_truth_of_a_curve():
    """Over 40 draws of 100 studies per N from a known curve, the 95% interval holds its N in most."""
    truth = PowerCurve(math.log(0.8 / 0.1) - 2.0 * math.log(60), 2.0, 0.9)
    rng = np.random.default_rng(1)
    expected = [truth.power(n) for n in GRID]
    covered = sum(
        found.low <= 60 <= found.high
        for found in (crossings(GRID, list(rng.binomial(100, expected)), 100, replicates=100)[0] for _ in range(40))
    )
    assert covered >= 34


def test_rankings_are_simulated_as_people_rank_and_powered_both_ways(capsys):
    """A ranking part's power is shown both for the report's test (the rankings' pairwise orderings) and for the
    whole order. Each simulated ranking gives three orderings, its whole order right exactly when all three are,
    at the whole-order accuracy asked for; the paper's design (two ranked sets per scheme) is never tested, and
    `foil power` says so instead of fitting a curve to zeros."""
    from app.analysis.simulation import Assumptions, layout, ranking_odds_for, simulate_rankings, whole_order_accuracy
    from app.survey.study import load_study

    study = load_study(STUDIES / "paper.toml")
    assert whole_order_accuracy(ranking_odds_for(0.5, 1.1, 3), 1.1, 3) == pytest.approx(0.5, abs=1e-3)
    assert whole_order_accuracy(-8.0, 1.1, 3) == pytest.approx(1 / 6, abs=0.02)  # no discriminability: chance
    plan = layout(study, "ranking", 400)
    fixed = Assumptions({"adaptive": 0.6, "nfirst": 0.3}, participant_sd=0.0, clip_sd=0.0)  # every ranking alike
    whole, orderings = simulate_rankings(study, plan, fixed, np.random.default_rng(1))
    right = np.asarray(orderings.correct).reshape(-1, 3)
    assert len(orderings.correct) == 3 * len(whole.correct) and (right.all(axis=1) == np.asarray(whole.correct)).all()
    scheme = np.asarray(whole.scheme)
    assert np.mean(np.asarray(whole.correct)[scheme == "adaptive"]) == pytest.approx(0.6, abs=0.05)
    assert run_power(study_path=str(STUDIES / "paper.toml"), pairwise=None, ranking="adaptive=0.6,nfirst=0.3",
                     pilot=None, participant_sd=1.0, clip_sd=0.5, largest=24, studies=10, seed=0) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "power, orderings" in out and "power, whole order" in out
    assert "orderings: no power at any N: the report would not test this design" in out and "degrees of freedom" in out
