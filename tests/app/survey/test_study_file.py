"""The study file: the shipped paper study is valid, and mistakes are reported with their line and field."""

from __future__ import annotations

import pytest

from app.survey.study import StudyError, load_study, parse_study
from tests.support.survey import PAPER_STUDY

PAPER = PAPER_STUDY.read_text()


def line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


def test_paper_study_is_the_papers_survey():
    study = load_study(PAPER_STUDY)
    one, two = study.parts
    assert one.kind == "pairwise" and len(one.pairs) * len(study.design.schemes) == 6
    assert one.questions == ["better", "justification", "difficulty"]
    assert study.questions["difficulty"].point_labels()[0] == "Very Easy"
    assert study.questions["difficulty"].point_labels()[-1] == "Very Hard"
    assert two.kind == "ranking" and two.agents == ["lo", "med", "hi"]
    assert study.questions["difference"].anchors == ("Very Small", "Very Large")
    assert study.questions["easy_worst_middle"].points == 5
    assert "worst and middle ranked robot" in study.questions["easy_worst_middle"].text
    assert "middle and best ranked robot" in study.questions["easy_middle_best"].text
    assert study.study.assignment == "self-select"


def test_the_build_table_is_the_bundle_builders_and_left_alone_here():
    """`[build]` belongs to `foil bundle` (search/bundle/spec.py): the server takes any table there as it is."""
    assert parse_study(PAPER).build["schemes"]["adaptive"]["budget"] == 1_000_000
    text = PAPER.replace('scenarios = ["paper-code"]', 'scenarios = ["paper-code"]\nagents = ["lo", "hi"]')
    assert parse_study(text).build["sets"][1]["agents"] == ["lo", "hi"]
    with pytest.raises(StudyError, match=r"line 1, build: Input should be a valid dictionary"):
        parse_study("build = 3\n" + PAPER[: PAPER.index("\n[build]")])


def test_unknown_top_level_key_is_rejected_with_its_line():
    text = PAPER.replace("[build]", "[bulid]\nx = 1\n[build]")
    with pytest.raises(StudyError) as error:
        parse_study(text, "paper.toml")
    assert f"paper.toml, line {line_of(text, '[bulid]')}, bulid: unknown key" in str(error.value)


def test_misspelt_field_in_a_part_names_line_and_field():
    text = PAPER.replace('order = "shuffled"', 'ordr = "shuffled"')
    with pytest.raises(StudyError) as error:
        parse_study(text)
    assert f"line {line_of(text, 'ordr =')}, parts[0].ordr: unknown key" in str(error.value)


def test_bad_scale_points_and_labels_name_the_question():
    text = PAPER.replace('points = 9\nanchors = ["Very Easy"', 'points = 1\nanchors = ["Very Easy"')
    with pytest.raises(StudyError) as error:
        parse_study(text)
    message = str(error.value)
    assert "questions.difficulty.points" in message and f"line {line_of(text, 'points = 1')}" in message
    text = PAPER.replace(
        'labels = ["Strongly disagree", "Disagree", "Neither agree nor disagree", "Agree", '
        '"Strongly agree"]\n\n[questions.easy_middle_best]',
        'labels = ["No", "Yes"]\n\n[questions.easy_middle_best]',
    )
    with pytest.raises(StudyError, match=r"questions\.easy_worst_middle: labels has 2 entries but points = 5"):
        parse_study(text)


def test_missing_required_field_points_at_its_table():
    text = PAPER.replace('title = "Which robot moves through a crowd better?"\n', "")
    with pytest.raises(StudyError) as error:
        parse_study(text)
    assert f"line {line_of(text, '[study]')}, study.title: Field required" in str(error.value)


def test_reference_to_an_unknown_question_is_reported():
    text = PAPER.replace('"justification", "difficulty"]', '"justification", "dificulty"]')
    with pytest.raises(StudyError) as error:
        parse_study(text)
    line = line_of(text, '"dificulty"]')
    assert f"line {line}, parts[0].questions[2]: no question named 'dificulty'" in str(error.value)


def test_a_rank_question_in_a_pairwise_part_is_refused():
    text = PAPER.replace('questions = ["better", "justification"', 'questions = ["ranking", "justification"')
    with pytest.raises(StudyError, match="a 'rank' question cannot be asked in a pairwise part"):
        parse_study(text)


def test_toml_syntax_errors_and_missing_files():
    with pytest.raises(StudyError, match="not valid TOML.*line 2"):
        parse_study("[study]\nid = \n")
    with pytest.raises(StudyError, match="cannot read study file"):
        load_study("/nonexistent/study.toml")


def test_completion_needs_a_code_or_an_https_redirect():
    text = PAPER.replace('code = "FOIL-PAPER-7Q2K"', 'code = ""')
    with pytest.raises(StudyError, match="completion: give a completion code"):
        parse_study(text)
    text = PAPER.replace('redirect_url = ""', 'redirect_url = "javascript:alert(1)"')
    with pytest.raises(StudyError, match="completion.redirect_url"):
        parse_study(text)


def test_a_scheme_with_scenarios_of_its_own_takes_them_part_by_part():
    """The demo's representative scheme draws its clips from the training distribution, the others from the
    paper's two scenarios; a scheme_scenarios entry for an unknown scheme, or of the wrong length, is refused."""
    from tests.support.survey import PAPER_STUDY as paper

    demo = load_study(paper.parent / "demo.toml")
    assert [demo.part_scenario(p, 1, "representative") for p in (0, 1)] == ["training", "training"]
    assert [demo.part_scenario(p, 1, "adaptive") for p in (0, 1)] == ["paper-tl-br", "paper-bl-tr"]
    text = (paper.parent / "demo.toml").read_text()
    right = 'representative = ["training", "training"]'
    for wrong, message in (
        (
            'representativ = ["training", "training"]',
            "scheme_scenarios names 'representativ', which is not one of schemes",
        ),
        (
            'representative = ["training"]',
            "scheme_scenarios.representative gives 1 scenarios; the design has 2, one for each",
        ),
    ):
        bad = text.replace(right, wrong)
        with pytest.raises(StudyError) as error:
            parse_study(bad, "demo.toml")
        assert str(error.value).startswith(f"demo.toml, line {line_of(bad, '[design]')}, design: {message}")
