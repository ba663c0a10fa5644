"""foil report: Table 1, the rating tests and the figures on hand-built databases whose answers are known."""

from __future__ import annotations

import csv
import io
import os
import re
import sys

import pytest

from app.analysis.exclusions import ExclusionRules
from app.analysis.report import ALL, render_report, tally_study
from app.survey.study import parse_study
from tests.support.analysis import SCENARIOS, SCHEMES, add_participant, fisher_two_sided, label_of
from tests.support.survey import SECRET_NAMES, study_text

ADAPTIVE, NFIRST = SCHEMES
LO = SECRET_NAMES["lo"]


def known_answers(wrong: bool = False):
    """Adaptive: always right, difficulty 1, agreement 5. N-first: right only on the clips with the worst robot
    (2 of 3 pairs), ranking reversed, difficulty 5, agreement 2. `wrong`: every answer wrong."""

    def answer(screen: dict) -> dict:
        if screen["kind"] == "pairwise":
            good = not wrong and (screen["scheme"] == ADAPTIVE or LO in {r["agent"] for r in screen["robots"]})
            agents = [r["agent"] for r in screen["robots"]]
            pick = screen["better"] if good else next(a for a in agents if a != screen["better"])
            return {
                "better": label_of(screen, pick),
                "justification": "seen",
                "difficulty": 1 if screen["scheme"] == ADAPTIVE else 5,
            }
        if screen["kind"] == "ranking":
            order = screen["true_order"] if screen["scheme"] == ADAPTIVE and not wrong else screen["true_order"][::-1]
            agree = 5 if screen["scheme"] == ADAPTIVE else 2
            return {
                "ranking": [label_of(screen, a) for a in order],
                "explanation": "seen",
                "difference": 7,
                "easy_worst_middle": agree,
                "easy_middle_best": agree,
            }
        return {}

    return answer


@pytest.fixture
def known_db(survey_db, paper_study, bundle_dir):
    """Four analysed participants (one per condition) plus three the rules leave out."""
    _, study = paper_study
    for condition in range(4):
        add_participant(survey_db, study, bundle_dir, condition=condition, answer=known_answers(), seed=condition)
    add_participant(survey_db, study, bundle_dir, condition=0, answer=known_answers(wrong=True), excluded=True)
    add_participant(survey_db, study, bundle_dir, condition=1, answer=known_answers(wrong=True), status="returned")
    add_participant(survey_db, study, bundle_dir, condition=2, answer=known_answers(wrong=True), minutes=1.0)
    return survey_db, study


def test_table1_counts_and_tests(known_db):
    db, study = known_db
    data = tally_study(db, study, ExclusionRules())
    e = data.exclusions
    assert (e.before, e.after) == (7, 4)
    assert e.per_reason == {"flagged_by_admin": 1, "incomplete": 1, "too_fast": 1}
    overall = {
        (task, scheme): (data.tally(task, ALL, scheme).correct, data.tally(task, ALL, scheme).incorrect)
        for task in ("pairwise", "ranking")
        for scheme in SCHEMES
    }
    assert overall == {
        ("pairwise", ADAPTIVE): (12, 0),
        ("pairwise", NFIRST): (8, 4),
        ("ranking", ADAPTIVE): (4, 0),
        ("ranking", NFIRST): (0, 4),
    }
    # conditions alternate the scenario rotation, so each scenario fed part one for two participants
    for scenario in SCENARIOS:
        nfirst = data.tally("pairwise", scenario, NFIRST)
        assert data.tally("pairwise", scenario, ADAPTIVE).correct == 6 and (nfirst.correct, nfirst.incorrect) == (4, 2)
        assert data.tally("ranking", scenario, NFIRST).incorrect == data.tally("ranking", scenario, ADAPTIVE).n == 2
    assert data.scopes() == [ALL, *SCENARIOS]
    assert data.accuracy_test("pairwise", ALL).p_value == pytest.approx(fisher_two_sided(12, 0, 8, 4))
    assert data.accuracy_test("ranking", ALL).p_value == pytest.approx(fisher_two_sided(4, 0, 0, 4))
    difficulty = data.rating_test("difficulty")
    assert difficulty.statistic == 0 and difficulty.effect == -1
    assert data.rating_test("easy_middle_best").effect == 1
    assert sorted(data.ratings["difference"][NFIRST].elements()) == [7] * 4


def test_report_files(known_db, tmp_path):
    db, study = known_db
    html = render_report(tally_study(db, study), tmp_path / "report")
    out = tmp_path / "report"
    for name in (
        "report.html",
        "table1.csv",
        "pooled_tests.csv",
        "model.csv",
        "model_accuracy.csv",
        "model_contrasts.csv",
        "ratings.csv",
        "rating_tests.csv",
        "exclusions.csv",
        "per_clip.csv",
        "likert.png",
        "likert.svg",
        "distribution-difficulty.png",
        "distribution-difference.svg",
    ):
        assert (out / name).stat().st_size > 0, name
    assert "<script" not in html and "<img" not in html and html.count("<svg") == 3  # self-contained
    assert "Fisher&#39;s exact test, two-sided" in html and "100.00%" in html and "66.67%" in html
    with (out / "table1.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    first = rows[0]
    assert (first["scope"], first["scheme"], first["pairwise_correct"], first["ranking_n"]) == (
        ALL,
        ADAPTIVE,
        "12",
        "4",
    )
    assert float(rows[1]["pairwise_accuracy"]) == pytest.approx(8 / 12, abs=1e-4)
    assert float(rows[1]["pairwise_ci95_low"]) == pytest.approx(0.3906, abs=1e-4)  # Wilson, 8 of 12
    with (out / "exclusions.csv").open() as handle:
        exclusions = {row["rule"].split(":")[0]: int(row["participants"]) for row in csv.DictReader(handle)}
    assert exclusions["participants in the database"] == 7 and exclusions["analysed (no rule applies)"] == 4
    with (out / "per_clip.csv").open() as handle:
        per_clip = list(csv.DictReader(handle))  # the report's per-clip table, as a file
    assert [row["clip"] for row in per_clip] == list(tally_study(db, study).per_clip)
    assert sum(int(row["answers"]) for row in per_clip) == 24 and all(row["scheme"] for row in per_clip)
    assert all(f'<td class="text">{row["clip"]}</td>' in html for row in per_clip)


def test_absolute_time_threshold_and_rule_off(known_db):
    db, study = known_db
    assert tally_study(db, study, ExclusionRules(min_seconds=0)).exclusions.after == 5
    strict = tally_study(db, study, ExclusionRules(min_seconds=11 * 60)).exclusions
    assert strict.after == 0 and strict.per_reason["too_fast"] == 6  # every completed one


def test_report_with_zero_participants(survey_db, paper_study, tmp_path):
    _, study = paper_study
    data = tally_study(survey_db, study)
    html = render_report(data, tmp_path / "empty")
    assert data.exclusions.before == 0 and "not tested: fewer than two schemes have answers" in html
    assert "no answers" in (tmp_path / "empty" / "distribution-difficulty.svg").read_text()


def test_report_with_one_scheme_missing(survey_db, bundle_dir, tmp_path):
    """A between-subjects study where only adaptive participants arrived: the N-first rows are empty."""
    study = parse_study(study_text(platform='"none"', assignment='"balanced"', scheme_factor='"between"'))
    adaptive_conditions = [0, 1]  # scheme order (adaptive,) with both scenario rotations
    for condition in adaptive_conditions:
        add_participant(survey_db, study, bundle_dir, condition=condition, answer=known_answers(), seed=condition)
    data = tally_study(survey_db, study)
    assert data.tally("pairwise", ALL, NFIRST).n == 0 and data.tally("pairwise", ALL, ADAPTIVE).correct == 6
    html = render_report(data, tmp_path / "one")
    assert "not tested" in html and "Mann-Whitney" not in html
    assert (tmp_path / "one" / "likert.png").exists()


FIGURE_WIDTH_PX = 960  # report.html shows a figure 100% wide up to 60rem


def smallest_text_px(svg: str) -> float:
    """The smallest text of an SVG figure, in CSS px, when it is shown FIGURE_WIDTH_PX wide."""
    width = float(re.search(r'viewBox="0 0 ([\d.]+) ', svg).group(1))
    sizes = [float(size) for size in re.findall(r"font-size: ([\d.]+)px", svg)]
    assert sizes, "no text found"
    return min(sizes) * FIGURE_WIDTH_PX / width


def test_figure_text_and_legends_are_at_least_12_px_where_the_report_shows_them(known_db):
    """Measured from the SVG: legends, ticks and titles of every figure are 12 px or more at the figure width of
    report.html (also on the admin report page), however many labelled scale questions the study has."""
    import matplotlib.pyplot as plt

    from app.analysis.report import likert_figure

    db, study = known_db
    data = tally_study(db, study)
    html = render_report(data)
    assert "max-width: 60rem" in html
    svgs = re.findall(r"<svg.*?</svg>", html, flags=re.S)
    assert len(svgs) == 3
    assert min(smallest_text_px(svg) for svg in svgs) >= 12
    labelled = [(name, q) for name, q in study.questions.items() if getattr(q, "labels", None)]
    for copies in (2, 3):  # 4 and 6 panels
        figure = likert_figure(data, labelled * copies)
        buffer = io.StringIO()
        figure.savefig(buffer, format="svg")
        plt.close(figure)
        assert smallest_text_px(buffer.getvalue()) >= 12


def test_foil_report_finds_the_served_bundle_for_the_audit_column(
    known_db, paper_study, bundle_dir, tmp_path, monkeypatch, capsys
):
    """The server records the bundle it serves; `foil report` with only the database fills the per-clip audit
    column from it, and says so when that bundle is gone."""
    import json
    import shutil

    from app.web.main import create_app
    from app.web.settings import ServerSettings
    from search.cli import main

    db, study = known_db
    served = tmp_path / "served-bundle"
    shutil.copytree(bundle_dir, served)
    manifest = json.loads((served / "manifest.json").read_text())
    for clip in manifest["clips"]:
        clip["audit"] = {"shows": "better", "why": f"what {clip['id']} shows"}
    (served / "manifest.json").write_text(json.dumps(manifest))
    path, _ = paper_study
    create_app(ServerSettings(bundle_dir=served, study_file=path, database_url=db.url)).state.context.db.dispose()
    monkeypatch.delenv("FOIL_BUNDLE_DIR", raising=False)
    assert main(["report", "--db", db.url, "--out", str(tmp_path / "report")]) == 0
    html = (tmp_path / "report" / "report.html").read_text()
    clips = re.findall(r'<tr><td class="text">([^<]+)</td>', html.split('id="per-clip"')[1])
    assert clips and all(f"shows better: what {clip} shows" in html for clip in clips)
    assert "warning" not in capsys.readouterr().err

    shutil.rmtree(served)
    assert main(["report", "--db", db.url, "--out", str(tmp_path / "again")]) == 0
    assert f"the bundle the study was served from is gone: {served}" in capsys.readouterr().err


def test_without_matplotlib_the_report_has_every_table_and_says_how_to_get_the_figures(
    known_db, paper_study, tmp_path, monkeypatch, capsys
):
    """On an install without the `figures` extra `foil report` (and the admin page, the same HTML) has all but
    the figures, and says which extra draws them; what it prints is the same."""
    from search.cli import main

    db, _ = known_db
    path, _ = paper_study
    monkeypatch.delenv("FOIL_BUNDLE_DIR", raising=False)
    command = ["report", "--db", db.url, "--study", str(path), "--out"]
    assert main([*command, str(tmp_path / "drawn")]) == 0
    drawn = capsys.readouterr()
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    assert main([*command, str(tmp_path / "plain")]) == 0
    plain = capsys.readouterr()
    assert plain.out.replace("plain", "drawn") == drawn.out
    assert (
        plain.err
        == drawn.err + "warning: the report has no figures: they need matplotlib: pip install 'foil[figures]'\n"
    )
    files = sorted(file.name for file in (tmp_path / "plain").iterdir())
    assert files == sorted(name for name in os.listdir(tmp_path / "drawn") if not name.endswith((".png", ".svg")))
    html = (tmp_path / "plain" / "report.html").read_text()
    assert "<svg" not in html and "<code>pip install &#39;foil[figures]&#39;</code> adds it" in html
    sections, drawn_sections = html.split("<h2"), (tmp_path / "drawn" / "report.html").read_text().split("<h2")
    ratings = next(k for k, section in enumerate(sections) if section.startswith(' id="ratings"'))
    assert sections[:ratings] == drawn_sections[:ratings]  # the figures are in the ratings section, before the appendix
    assert sections[ratings + 1 :] == [s.replace("plain", "drawn") for s in drawn_sections[ratings + 1 :]]


def test_a_ranked_set_is_one_cluster_whatever_order_its_clips_were_shown_in(known_db):
    """Each participant sees a round's clips in an order of their own: the model clusters by the set ranked, so
    the paper's design has one ranking cluster per scheme and scenario."""
    db, study = known_db
    answers = tally_study(db, study, ExclusionRules()).answers["ranking"]
    sets = {(scheme, scenario) for scheme, scenario in zip(answers.scheme, answers.scenario, strict=True)}
    assert len(set(answers.clip)) == len(sets) == 4
