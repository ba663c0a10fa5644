"""How agents are named, in a world's own words: the instructions' naming paragraph, the line above a ranking
round's clips and a new round's notice come from the bundle's world (a Gymnasium world speaks of agents, never of
robots), and a study file's [texts] still says otherwise."""

from __future__ import annotations

import html
import re
from pathlib import Path

import pytest

from app.visible import CROWD_WORDS, Words, World
from tests.app.test_world_words import with_world
from tests.support.analysis import write_bot_bundle
from tests.support.survey import start, walk

GENERIC_WORDS = Words()  # a Gymnasium world's words unless its adapter says otherwise


@pytest.fixture(scope="module")
def crowd_bundle(tmp_path_factory) -> Path:
    return write_bot_bundle(tmp_path_factory.mktemp("naming-clips"), tmp_path_factory.mktemp("naming-crowd"))


def page_texts(client, pages: list[str] | None = None) -> list[str]:
    """Each page of a participant's walk through the study (or of ``pages``) as its text, tags left out."""
    pages = pages or walk(client, start(client, "?workerId=W1&assignmentId=A1&hitId=H1"))
    return [html.unescape(re.sub(r"<[^>]+>", " ", page)) for page in pages]


def test_a_gym_world_names_its_agents_in_its_own_words(make_client, crowd_bundle, tmp_path):
    bundle = with_world(crowd_bundle, tmp_path / "gym", World(domain="gym", words=GENERIC_WORDS).to_manifest())
    client = make_client(bundle_dir=bundle)
    pages = walk(client, start(client, "?workerId=W1&assignmentId=A1&hitId=H1"))
    texts = page_texts(client, pages)
    shown = "\n".join(texts)
    for paragraph in (GENERIC_WORDS.names, GENERIC_WORDS.names_in_round, GENERIC_WORDS.new_round):
        assert paragraph in shown
    crowd = CROWD_WORDS
    for paragraph in (crowd.names, crowd.names_in_round, crowd.new_round):
        assert paragraph not in shown
    assert GENERIC_WORDS.names in next(text for text in texts if "How to read a clip" in text)
    # the pages' own words (the study file's questions and the bundle's labels are this crowd bundle's)
    assert "Choose one agent for each place. Each agent takes exactly one place." in shown
    assert 'aria-label="Agents in the clip"' in "\n".join(pages)
    assert "robot for each place" not in shown and "Robots in the clip" not in "\n".join(pages)


def test_a_crowd_bundle_keeps_its_naming_paragraphs(make_client, crowd_bundle):
    shown = "\n".join(page_texts(make_client(bundle_dir=crowd_bundle)))
    crowd = CROWD_WORDS
    for paragraph in (crowd.names, crowd.names_in_round, crowd.new_round):
        assert paragraph in shown


def test_a_study_files_texts_name_the_agents_over_the_worlds_words(make_client, crowd_bundle, tmp_path):
    from tests.support.survey import study_text

    bundle = with_world(crowd_bundle, tmp_path / "gym", World(domain="gym", words=GENERIC_WORDS).to_manifest())
    study = tmp_path / "study.toml"
    study.write_text(
        study_text().replace("[texts]", '[texts]\nrobot_names = "Each controller is named, such as Agent 7."', 1)
    )
    shown = "\n".join(page_texts(make_client(bundle_dir=bundle, study_file=study)))
    assert "Each controller is named, such as Agent 7." in shown and GENERIC_WORDS.names not in shown
