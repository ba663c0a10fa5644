"""Stored plans: the typed screens read every plan the server has stored, and a plan is written as the same JSON
as before, so existing databases and their exports read unchanged."""

from __future__ import annotations

import json
import random

import pytest
from pydantic import ValidationError

from app.survey.assignment import conditions
from app.survey.bundle import load_bundle
from app.survey.plan import build_plan
from app.survey.screens import (
    Asked,
    Attention,
    Clip,
    Closing,
    OneOf,
    Pairwise,
    Ranking,
    Shape,
    Watch,
    dump_plan,
    parse_plan,
    shows_clip,
)
from app.survey.study import parse_study
from tests.support.survey import ATTENTION, CLOSING, VIDEO_CHECK, study_text

# One screen of each kind as the server stored them (a video attention check and a plain one), byte for byte.
STORED = """[{"kind": "instructions", "position": [0, 18]}, \
{"kind": "pairwise", "part": 1, "clip": "n-one-lo-hi", "media": "2b2c", "scheme": "n", "scenario": "one", \
"robots": [{"label": "Robot 1", "agent": "lo"}, {"label": "Robot 3", "agent": "hi"}], "better": "hi", \
"questions": ["better", "justification", "difficulty"], "clip_ms": 1000, "width": 64, "height": 64, \
"progress": "Part 1 of 2, clip 1 of 6", "position": [1, 18]}, \
{"kind": "attention", "part": 1, "check": 1, "options": ["Yes", "No"], "expected": "Yes", "clip": "n-ex-lo-hi", \
"media": "a7ff", "clip_ms": 1000, "width": 64, "height": 64, "progress": "Part 1 of 2, a check question", \
"position": [2, 18]}, \
{"kind": "attention", "part": 1, "check": 0, "options": ["Disagree", "Agree"], "expected": "Agree", \
"progress": "Part 1 of 2, a check question", "position": [3, 18]}, \
{"kind": "watch", "part": 2, "clip": "a-two-lo-med", "media": "0acb", "scheme": "a", "scenario": "two", \
"robots": [{"label": "Robot 1", "agent": "lo"}, {"label": "Robot 2", "agent": "med"}], "better": "med", \
"questions": [], "clip_ms": 1000, "width": 64, "height": 64, "block": 1, "round_start": true, \
"progress": "Part 2 of 2, round 1 of 2, clip 1 of 3", "position": [9, 18]}, \
{"kind": "ranking", "part": 2, "block": 1, "scheme": "a", "scenario": "two", "clips": ["a-two-lo-med", \
"a-two-med-hi"], "media_list": ["0acb", "27f7"], "shapes": [{"clip_ms": 1000, "width": 64, "height": 64}, {}], \
"robots": [{"label": "Robot 1", "agent": "lo"}, {"label": "Robot 3", "agent": "hi"}, \
{"label": "Robot 2", "agent": "med"}], "true_order": null, "questions": ["ranking", "explanation"], \
"progress": "Part 2 of 2, round 1 of 2, ranking", "position": [12, 18]}, \
{"kind": "closing", "questions": ["age_range"], "feedback": true, "progress": "Last screen: closing questions", \
"position": [17, 18]}]"""
# A plan from before screens knew their position, a ranking its clips' files and a clip its playing time.
OLDER = """[{"kind": "instructions"}, \
{"kind": "watch", "part": 1, "clip": "a-two-lo-med", "media": "0acb", "scheme": "a", "scenario": "two", \
"robots": [{"label": "Robot 1", "agent": "lo"}, {"label": "Robot 2", "agent": "med"}], "better": "med", \
"questions": [], "block": 1, "progress": "Part 1 of 1, round 1 of 1, clip 1 of 1"}, \
{"kind": "ranking", "part": 1, "block": 1, "scheme": "a", "scenario": "two", "clips": ["a-two-lo-med"], \
"robots": [{"label": "Robot 1", "agent": "lo"}, {"label": "Robot 2", "agent": "med"}], \
"true_order": ["med", "lo"], "questions": ["ranking"], "progress": "Part 1 of 1, round 1 of 1, ranking"}]"""


def variant(screen: dict) -> tuple[str, bool]:
    return screen["kind"], "media" in screen


def test_stored_plans_read_and_write_back_byte_for_byte():
    for text in (STORED, OLDER):
        assert json.dumps(dump_plan(parse_plan(json.loads(text)))) == text
    older = parse_plan(json.loads(OLDER))
    assert isinstance(older[1], Watch) and older[1].round_start is False and older[1].clip_ms is None
    assert isinstance(older[2], Ranking) and older[2].media_list == [] and older[2].position is None


def test_a_new_plan_is_stored_with_the_keys_of_a_stored_one_in_the_same_order(bundle_dir):
    text = (
        study_text(contact=VIDEO_CHECK.format(scheme="schemenfirstsecret"))
        + ATTENTION
        + CLOSING.format(required="[]").removeprefix('""')
    )
    study = parse_study(text)
    plan = build_plan(study, load_bundle(bundle_dir), conditions(study)[0], random.Random(4))
    assert {type(screen) for screen in plan} >= {Pairwise, Watch, Ranking, Attention}
    stored = {variant(screen): list(screen) for screen in json.loads(STORED)}
    written = dump_plan(plan)
    assert {variant(screen) for screen in written} == set(stored)
    for screen in written:
        assert list(screen) == stored[variant(screen)]


@pytest.mark.parametrize(
    ("plan", "message"),
    [
        ([{"kind": "video"}], "tag 'video' found using 'kind' does not match"),
        ([{"kind": "pairwise", "part": 1}], r"0\.pairwise\.clip\n  Field required"),
        ([{"kind": "instructions", "colour": "red"}], r"0\.instructions\.colour\n  Extra inputs are not permitted"),
    ],
)
def test_a_stored_plan_that_is_not_one_is_refused_with_the_field_named(plan, message):
    with pytest.raises(ValidationError, match=message):
        parse_plan(plan)


COMPREHENSION = """
[[comprehension]]
text = "Which robot is better?"
options = ["Fast", "Careful"]
expected = "Careful"
"""


def test_each_kind_of_screen_asks_for_its_own_fields_and_names_its_clip(bundle_dir):
    text = (
        study_text(contact=VIDEO_CHECK.format(scheme="schemenfirstsecret"))
        + ATTENTION
        + CLOSING.format(required='["age_range"]').removeprefix('""')
        + COMPREHENSION
    )
    study = parse_study(text)
    plan = build_plan(study, load_bundle(bundle_dir), conditions(study)[0], random.Random(4))
    by_kind = {}
    for screen in plan:
        by_kind.setdefault(type(screen), []).append(screen)
    pairwise, watch, ranking = by_kind[Pairwise][0], by_kind[Watch][0], by_kind[Ranking][0]
    video_check, plain_check = sorted(by_kind[Attention], key=lambda screen: screen.media is None)
    closing, instructions = by_kind[Closing][0], plan[0]

    assert [(a.name, a.question, a.required) for a in pairwise.asks(study)] == [
        (name, study.questions[name], True) for name in pairwise.questions
    ]
    assert watch.asks(study) == [] and [a.name for a in ranking.asks(study)] == ranking.questions
    assert plain_check.asks(study) == [Asked("attention", OneOf(plain_check.options))]
    assert instructions.asks(study) == [Asked("understand1", OneOf(["Fast", "Careful"], "Careful"))]
    asked = [(a.name, a.required) for a in closing.asks(study)]
    assert asked == [("age_range", True), ("robot_experience", False), ("confidence", False), ("feedback", False)]

    assert pairwise.clips_to_watch() == [Clip(pairwise.media, Shape(clip_ms=pairwise.clip_ms, width=64, height=64))]
    assert len(watch.clips_to_watch()) == len(video_check.clips_to_watch()) == 1
    assert [s.clips_to_watch() for s in (plain_check, ranking, instructions, closing)] == [[]] * 4
    assert pairwise.clip_names() == [pairwise.clip] and ranking.clip_names() == ranking.clips
    assert video_check.clip_names() == [video_check.clip] and plain_check.clip_names() == closing.clip_names() == []
    assert [shows_clip(s) for s in (pairwise, video_check, plain_check, ranking, None)] == [1, 1, 0, 0, 0]

    assert [s.template for s in (instructions, pairwise, closing)] == [
        "instructions.html",
        "screen.html",
        "screen.html",
    ]
    assert plain_check.failed_check({"attention": "Disagree"}) and not plain_check.failed_check({"attention": "Agree"})
    assert not pairwise.failed_check({"attention": "Disagree"})
    assert instructions.counts_comprehension(study) and not pairwise.counts_comprehension(study)
    assert [s.admin_name() for s in (instructions, ranking, closing)] == [
        "Instructions",
        f"Part {ranking.part}, ranking",
        "Closing questions",
    ]
