"""A study of updates is checked before anything is served: every update pair is a pair of a pairwise part that
asks a compare question, every control is an update pair, and a compare answer is an agent shown or no
difference."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.survey.study import NO_DIFFERENCE, StudyError, parse_study

STUDY = (Path(__file__).parents[3] / "studies" / "cartpole-updates.toml").read_text()
CONTROL = 'controls = [["cartpole_run:snapshot_2", "cartpole_run:snapshot_3"]]'


def test_the_shipped_study_of_updates_reads_with_its_updates_and_control():
    design = parse_study(STUDY).design
    assert design.update_of(["cartpole_run:snapshot_1", "cartpole_run:snapshot_0"]) == (
        "cartpole_run:snapshot_0",
        "cartpole_run:snapshot_1",
    )
    assert design.controls == [("cartpole_run:snapshot_2", "cartpole_run:snapshot_3")]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ((CONTROL, 'controls = [["cartpole_run:snapshot_3", "cartpole_run:snapshot_2"]]'), "not one of updates"),
        (("updates = [\n    [", 'updates = [\n    ["a:b", "c:d"],\n    ['), "is no pair of a pairwise part"),
        (('questions = ["verdict", "justification"', 'questions = ["justification"'), "asks no 'compare' question"),
    ],
)
def test_a_study_of_updates_that_cannot_be_analysed_is_refused(change, message):
    old, new = change
    assert old in STUDY
    with pytest.raises(StudyError, match=message):
        parse_study(STUDY.replace(old, new, 1))


def test_a_compare_answer_is_an_agent_shown_or_no_difference():
    question = parse_study(STUDY).questions["verdict"]
    labels = ["Controller 2", "Controller 5"]
    assert question.answers(labels) == ["Controller 2", NO_DIFFERENCE, "Controller 5"]
    assert question.check("verdict", lambda _: NO_DIFFERENCE, labels) == (NO_DIFFERENCE, None)
    assert question.check("verdict", lambda _: "Controller 5", labels) == ("Controller 5", None)
    assert question.check("verdict", lambda _: "Controller 9", labels)[0] is None
