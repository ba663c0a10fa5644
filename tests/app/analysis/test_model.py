"""The report's model (app/analysis/model.py), `foil power` and `foil prereg`, on simulated studies in the shipped
designs and on hand-built databases. The full calibration (500 studies per design) is benchmarks/bench_model.py."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from app.analysis.design import chance
from app.analysis.model import fit_accuracy
from app.analysis.power import parse_accuracies
from app.analysis.report import render_report, tally_study
from app.analysis.simulation import Assumptions, layout, simulate
from app.analysis.statistics import accuracy_difference
from app.survey.study import load_study
from tests.app.analysis.test_report import known_answers, known_db  # noqa: F401  (the fixture)
from tests.support.analysis import SCHEMES, add_participant

STUDIES = Path(__file__).resolve().parents[3] / "studies"


def test_under_no_effect_the_model_rejects_far_less_often_than_the_pooled_test():
    study = load_study(STUDIES / "demo.toml")
    schemes = list(study.design.schemes)
    plan = layout(study, "pairwise", 36)
    same = Assumptions({s: 0.75 for s in schemes}, participant_sd=1.0, clip_sd=0.7)
    rng = np.random.default_rng(7)
    model = pooled = 0
    for _ in range(60):
        answers = simulate(study, "pairwise", plan, same, rng)
        model += fit_accuracy(answers, schemes, 0.5).scheme_p < 0.05
        counts = {s: [0, 0] for s in schemes}
        for scheme, correct in zip(answers.scheme, answers.correct, strict=True):
            counts[scheme][1 - correct] += 1
        pooled += accuracy_difference({s: (c, i) for s, (c, i) in counts.items()}).p_value < 0.05
    assert model <= 6 and pooled >= 12  # at most 10% against at least 20% of 60 studies


def test_the_model_recovers_a_scheme_effect_and_its_accuracy_is_the_raw_one():
    study = load_study(STUDIES / "paper.toml")
    schemes = list(study.design.schemes)
    truth = {schemes[0]: 0.9, schemes[1]: 0.6}
    answers = simulate(study, "pairwise", layout(study, "pairwise", 80), Assumptions(truth), np.random.default_rng(3))
    fit = fit_accuracy(answers, schemes, chance(study, "pairwise"))
    # two schemes: the primary test is their one difference, on Satterthwaite degrees of freedom, which count the
    # 6 clips a scheme has rather than the 12 of the part
    assert fit.estimable and fit.clips == 12 and fit.participants == 80 and 2 < fit.df < 12 - 1
    for estimate in fit.schemes:
        raw = np.mean([c for s, c in zip(answers.scheme, answers.correct, strict=True) if s == estimate.scheme])
        assert estimate.accuracy == pytest.approx(raw, abs=0.01)  # Firth's penalty pulls only slightly to 50%
        assert estimate.low < estimate.accuracy < estimate.high
    (contrast,) = fit.contrasts
    assert contrast.low < truth[schemes[1]] - truth[schemes[0]] < contrast.high < 0
    assert contrast.odds_ratio < 1 and fit.scheme_p == contrast.p_value < 0.05 and contrast.primary


def test_the_cr2_correction_in_the_parameters_space_equals_the_per_cluster_one():
    """_part applies (I - H_gg)^-1/2 in the parameters' space for all clusters at once; here it is taken of each
    cluster's full H_gg, with the pseudo-inverse where a cluster alone determines a parameter (the demo's
    representative scheme has one ranked set)."""
    from app.analysis.model import _covariance, _design, _fit, _part

    study = load_study(STUDIES / "demo.toml")
    schemes = list(study.design.schemes)
    for task in ("pairwise", "ranking"):
        answers = simulate(study, task, layout(study, task, 24), Assumptions({s: 0.7 for s in schemes}),
                           np.random.default_rng(2))  # fmt: skip
        x = _design(answers, schemes, ("pair", "scenario") if task == "pairwise" else ("scenario",))
        beta, fitted = _fit(np.asarray(answers.correct, dtype=float), x)
        weight, residual = fitted * (1 - fitted), np.asarray(answers.correct) - fitted
        bread = np.linalg.inv((x * weight[:, None]).T @ x)
        for clusters in (answers.participant, answers.clip):
            groups = np.unique(clusters, return_inverse=True)[1]
            expected = np.zeros_like(bread)
            for g in range(groups.max() + 1):
                rows = groups == g
                xg = x[rows] * np.sqrt(weight[rows, None])
                values, vectors = np.linalg.eigh(np.eye(rows.sum()) - xg @ bread @ xg.T)
                scale = np.where(values > 1e-8, np.maximum(values, 1e-8) ** -0.5, 0.0)
                score = xg.T @ vectors @ (scale * (vectors.T @ (residual[rows] / np.sqrt(weight[rows]))))
                expected += np.outer(score, score)
            found = _covariance([_part(1.0, groups, x, weight, bread)], x, residual)
            assert found == pytest.approx(bread @ expected @ bread, rel=1e-9, abs=1e-9)


def test_two_participants_get_no_test_from_the_model(survey_db, paper_study, bundle_dir, tmp_path):
    _, study = paper_study
    for condition in range(2):
        add_participant(survey_db, study, bundle_dir, condition=condition, answer=known_answers(), seed=condition)
    data = tally_study(survey_db, study)
    for task in ("pairwise", "ranking"):
        fit = data.model(task)
        assert not fit.estimable and fit.scheme_p is None and "2 participants" in fit.note
    html = render_report(data, tmp_path / "report")
    model, appendix = html.split('id="model"')[1].split('id="exclusions"')[0], html.split('id="appendix"')[1]
    assert "Not tested: 2 participants" in model and "p =" not in model
    assert "ignoring repeated measures" in appendix and "Fisher" in appendix and "p =" in appendix
    assert html.index('id="model"') < html.index('id="table1"') < html.index('id="appendix"')


def test_the_report_and_its_csv_say_why_an_odds_ratio_has_no_interval(known_db, tmp_path):  # noqa: F811
    """Part one's answers replaced by a small study where every answer under N-first is right: its odds ratio is
    shown with the reason it has no interval, in the table and in model_contrasts.csv, never a bare dash."""
    from dataclasses import replace

    from tests.app.analysis.test_small_sample import _study

    db, study = known_db
    adaptive, nfirst = SCHEMES
    answers = _study({adaptive: 3, nfirst: 3}, 3, {adaptive: 0.7, nfirst: 0.9}, seed=2)
    data = replace(tally_study(db, study), answers={"pairwise": answers})
    html = render_report(data, tmp_path / "report")
    why = f"nterval not estimable: every answer under {nfirst} was right; only 1.7 degrees of freedom for the odds"
    assert f'<td class="text">I{why}' in html.split('id="model"')[1].split('id="table1"')[0]
    with (tmp_path / "report" / "model_contrasts.csv").open() as handle:
        (row,) = [row for row in csv.DictReader(handle) if row["task"] == "pairwise"]
    assert row["ci95_low"] and not row["or_ci95_low"] and row["or_note"].startswith(f"i{why}")


def test_power_and_prereg_commands(known_db, paper_study, bundle_dir, tmp_path, capsys):  # noqa: F811
    from search.cli import main

    db, _ = known_db
    path, _ = paper_study
    assert main(["power", str(path), "--pairwise", f"{SCHEMES[0]}=0.95,{SCHEMES[1]}=0.6", "--studies", "10",
                 "--max-participants", "16"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert (
        f"pairwise: accuracies {SCHEMES[0]} 0.95, {SCHEMES[1]} 0.60" in out
        and "± (Monte Carlo, 95%)" in out
        and "80% power:" in out
        and "90% power:" in out
    )
    assert main(["prereg", str(path), "--bundle", str(bundle_dir), "--participants", "4", "--out", str(tmp_path)]) == 0
    fixed = json.loads((tmp_path / "prereg.json").read_text())
    assert fixed["participants"] == 4 and fixed["study_file"].startswith("sha256:")
    assert "correct ~ scheme" in fixed["model"] and "Hypotheses" in (tmp_path / "prereg.md").read_text()
    report = ["report", "--db", db.url, "--study", str(path), "--bundle", str(bundle_dir), "--prereg"]
    assert main([*report, str(tmp_path / "prereg.json"), "--out", str(tmp_path / "same")]) == 0
    assert "The data match the preregistration" in (tmp_path / "same" / "report.html").read_text()
    capsys.readouterr()
    (tmp_path / "other.toml").write_text(path.read_text() + "\n# edited\n")
    fixed["participants"] = 40
    (tmp_path / "prereg.json").write_text(json.dumps(fixed))
    report[4] = str(tmp_path / "other.toml")
    assert main([*report, str(tmp_path / "prereg.json"), "--out", str(tmp_path / "other")]) == 0
    out = capsys.readouterr().out
    assert "2 deviations from the preregistration" in out
    assert "the study file differs" in out and "4 participants analysed, fewer than the 40 planned" in out


def test_bad_input_says_what_is_wrong_and_how_to_fix_it(paper_study, tmp_path):
    from app.analysis.exclusions import ExclusionRules
    from app.analysis.prereg import run_prereg

    study = load_study(STUDIES / "paper.toml")
    with pytest.raises(ValueError, match="missing nfirst .*--pairwise adaptive=0.8,nfirst=0.8"):
        parse_accuracies("adaptive=0.8", study, "--pairwise")
    with pytest.raises(ValueError, match="no scheme 'fast'.*adaptive, nfirst"):
        parse_accuracies("fast=0.8", study, "--pairwise")
    with pytest.raises(ValueError, match="between 0 and 1, got 80"):
        parse_accuracies("adaptive=80,nfirst=0.5", study, "--pairwise")
    with pytest.raises(ValueError, match="no manifest.json in bundle"):
        run_prereg(study_path=str(paper_study[0]), bundle=str(tmp_path), out=str(tmp_path), participants=4,
                   rules=ExclusionRules())  # fmt: skip


def test_the_report_says_what_a_ranking_test_can_show(known_db, tmp_path):  # noqa: F811
    db, study = known_db
    data = tally_study(db, study)
    html = render_report(data, tmp_path / "report")
    ranking = data.model("ranking")
    assert ranking.estimable and html.count("A ranking part has one ranked set per scheme and scenario") == 1
    assert f"the spread of only {ranking.clips} sets" in html
    # part two is modelled by its pairwise orderings (three per ranking of three), the whole order in Table 1
    orderings = data.answers["orderings"]
    assert len(orderings.correct) == 3 * sum(data.tally("ranking", "all scenarios", s).n for s in data.schemes)
    assert sum(e.n for e in ranking.schemes) == len(orderings.correct) and "pairwise orderings" in html
    assert "population-averaged" in html and "p Holm" in html and "Primary test" in html
    ratings = html.split('id="ratings"')[1].split('id="appendix"')[0]
    assert "Not tested" in ratings and "Kruskal" not in ratings and "Mann-Whitney" in html.split('id="appendix"')[1]


def test_schemes_with_one_clip_or_no_variation_are_named_untestable_not_tested():
    """The methods study's ranking part, 40 bots: representative, disagreements and highlights have one ranked set
    each, two schemes are always right and one always wrong. A scheme with one clip cannot show how its accuracy
    depends on the clip, and schemes whose answers are all alike hold no variation: each such comparison says why
    it is not tested (it was tested before, on errors that assume independence), and the primary test is of the
    two schemes with two clips, saying which were left out."""
    from app.analysis.model import Answers

    rows = []
    for p in range(40):
        half = p % 2
        rows += [
            ("representative", "r", 1),
            ("disagreements", "d", 1),
            ("highlights", "h", int(p >= 4)),
            ("adaptive", f"a{half}", 0),
            ("nfirst", f"n{half}", int(p < 6)),
        ]
    participants = [f"bot-{p}" for p in range(40) for _ in range(5)]
    answers = Answers(
        participant=participants,
        clip=[clip for _, clip, _ in rows],
        scheme=[scheme for scheme, _, _ in rows],
        scenario=["training"] * len(rows),
        pair=[""] * len(rows),
        correct=[correct for _, _, correct in rows],
    )
    fit = fit_accuracy(answers, ["adaptive", "nfirst", "representative", "disagreements", "highlights"], 1 / 6)
    assert fit.estimable
    one_clip = {"representative", "disagreements", "highlights"}
    for e in fit.schemes:
        if e.scheme in one_clip:
            assert e.p_chance is None and e.low is None and "has 1 clip" in e.note
    for c in fit.contrasts:
        if one_clip & {c.scheme, c.reference}:
            assert c.p_value is None and c.low is None and c.or_low is None and "1 clip" in c.note
    assert "representative, disagreements, highlights left out (fewer than two clips)" in fit.scheme_test


def test_one_participant_is_too_few_clusters_whether_or_not_a_fit_converges():
    """One participant ranking one set per scheme, every ordering right: the fit does not converge, but the
    reason nothing is tested is the one participant (and one clip per scheme), and the note says so."""
    from app.analysis.model import Answers

    schemes = ["adaptive", "nfirst", "representative"]
    answers = Answers(
        participant=["p1"] * 3,
        clip=[f"{scheme}-1" for scheme in schemes],
        scheme=schemes,
        scenario=["dense"] * 3,
        pair=[""] * 3,
        correct=[1, 1, 1],
    )
    fit = fit_accuracy(answers, schemes, 0.5)
    assert not fit.estimable and fit.note.startswith("not tested: 1 participant and 3 clips are too few clusters")
