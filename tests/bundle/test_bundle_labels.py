"""Robot labels over a participant's whole study: a real bundle built from the demo study's survey (scripted
agents, small searches), then every condition's plan as the server builds it."""

from __future__ import annotations

import itertools
import random
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from search.bundle.build import build_bundle
from search.clips.render import agent_style

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]

SMALL_BUILD = """
[build]
seed = 11

[build.eval]
episodes = 4
seed = 0

[build.render]
speed = 8.0
hold_start = 0.1
hold_end = 0.1
event_hold = 0.1

[build.schemes.adaptive]
solver = "mcts"
budget = 200
seed = 1

[build.schemes.nfirst]
solver = "nfirst"
budget = 200
seed = 1

[build.schemes.representative]
solver = "representative"
budget = 400
seed = 1
settings = { states = 2, pushes = 2 }

[build.representativeness]
states = 2
pushes = 2

[[build.sets]]
parts = ["pairwise", "ranking"]
schemes = ["adaptive", "nfirst"]
scenarios = ["paper-bl-tr", "paper-tl-br"]
agents = ["goal", "orca", "social_force"]

[[build.sets]]
parts = ["pairwise", "ranking"]
schemes = ["representative"]
scenarios = ["training"]
agents = ["goal", "orca", "social_force"]

[[build.sets]]
parts = ["example"]
schemes = ["nfirst"]
scenarios = ["paper-code"]
pairs = [["goal", "social_force"]]
"""


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """The demo study (three schemes within, two scenarios counterbalanced, the representative scheme's from the
    training distribution, a pairwise and a ranking part and an example clip) with scripted agents, its bundle
    built, loaded as the server loads them."""
    from app.survey.bundle import check_study_against_bundle, load_bundle
    from app.survey.study import load_study

    text = (ROOT / "studies" / "demo.toml").read_text()
    text = text[: text.index("\n[build]\n")]
    for shipped, scripted in (('"lo"', '"goal"'), ('"med"', '"orca"'), ('"hi"', '"social_force"')):
        text = text.replace(shipped, scripted)
    root = tmp_path_factory.mktemp("labels")
    study_file = root / "study.toml"
    study_file.write_text(text + SMALL_BUILD)
    build_bundle(study_file, root / "out", log=lambda line: None)
    study, bundle = load_study(study_file), load_bundle(root / "out")
    check_study_against_bundle(study, bundle)
    return study, bundle


def test_a_label_never_names_two_agents_in_a_participants_study(served):
    """Over every condition's plan (example clip included), a label stands for one agent only; in a ranking round
    each agent has one label in all the round's clips and its ranking, and every round has labels of its own."""
    from app.survey.assignment import conditions
    from app.survey.plan import build_plan
    from app.survey.screens import Round

    study, bundle = served
    example = bundle.matching(study.example.scheme, study.example.scenario, study.example.agents)[0]
    for condition, seed in itertools.product(conditions(study), range(3)):
        plan = build_plan(study, bundle, condition, random.Random(seed))
        agent_of = dict(zip(example.labels, example.agents, strict=True))
        for screen in plan:
            for robot in getattr(screen, "robots", []):
                assert agent_of.setdefault(robot.label, robot.agent) == robot.agent, (condition, screen)
        rounds = {}
        for screen in plan:
            if isinstance(screen, Round):
                rounds.setdefault((screen.part, screen.block), set()).update(
                    (robot.label, robot.agent) for robot in screen.robots
                )
        assert len(rounds) == len(condition.schemes)
        for labelled in rounds.values():
            assert len(labelled) == len({label for label, _ in labelled}) == len({a for _, a in labelled}) == 3
        for a, b in itertools.combinations(rounds.values(), 2):
            assert not {label for label, _ in a} & {label for label, _ in b}


def test_each_clip_draws_its_labels_in_their_colours(served):
    """The label the plan records is the robot the clip shows: its colour is drawn in the clip's poster."""
    _, bundle = served
    for clip in bundle.clips.values():
        poster = np.asarray(
            Image.open(bundle.root / clip.file.replace(".mp4", ".poster.png")).convert("RGB"), dtype=np.int16
        )
        for label in clip.labels:
            colour = agent_style(int(label.split()[-1]))[0]
            assert (np.abs(poster - np.array(colour)).max(axis=-1) <= 3).sum() > 30, (clip.id, label)
