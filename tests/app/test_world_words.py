"""Each world's own words reach its participants: the instructions' legend, the clips' accessible names and the
ranking rounds' outcome lines come from the bundle's manifest, a crowd bundle (no `world` key) reads as ever, and
the bots judge and explain clips by the bundle's world."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from app.analysis.bots import ClipIndex
from app.formats import Manifest, manifest_json
from app.survey.bundle import BundleError, load_bundle
from app.visible import CROWD, Words, World
from tests.support.analysis import write_bot_bundle
from tests.support.survey import start, walk

CARS = World(
    domain="highway",
    rule="survival",
    words=Words(
        clip_title="Clip of two self-driving cars on a highway",
        example_caption="An example: two self-driving cars, each in its own colour, drive the same highway.",
        legend_robots="Robots: each self-driving car wears its robot's colour; its name is listed below the picture.",
        others_marker="",
        legend_others="Traffic: the other cars, in blue, all driving the same way.",
        legend_trails="",
        legend_crash="A yellow-and-black burst and **CRASH** mark a car hitting another car or leaving the road.",
        legend_status="Below the picture each robot's line says **drove through** or **on its way**, with the time.",
        success="drove through",
        collision="crashed after {seconds} seconds",
        timeout="ran out of time",
        running="was still driving when the clip ended",
        close_call="came close to other cars",
    ),
)
CROWD_WORDS = re.compile(r"person|people|crowd|goal|walk", re.IGNORECASE)


@pytest.fixture(scope="module")
def crowd_bundle(tmp_path_factory) -> Path:
    """The paper study's bundle with a summary.json per clip, so ranking rounds say how each clip ended."""
    return write_bot_bundle(tmp_path_factory.mktemp("words-clips"), tmp_path_factory.mktemp("words-crowd"))


def with_world(crowd_bundle: Path, root: Path, world: dict) -> Path:
    """A copy of the crowd bundle whose manifest says it shows ``world``."""
    shutil.copytree(crowd_bundle, root)
    manifest = json.loads((root / "manifest.json").read_text())
    (root / "manifest.json").write_text(json.dumps(manifest | {"world": world}))
    return root


def world_parts(page: str) -> str:
    """What a page says in its world's words: the legend, the videos' accessible names and their captions (a
    ranking round's with its outcome lines)."""
    legend = re.findall(r'<ul class="clip-legend".*?</ul>', page, re.DOTALL)
    titles = re.findall(r'<video [^>]*aria-label="([^"]*)"', page)
    captions = re.findall(r"<figcaption>.*?</figcaption>", page, re.DOTALL)
    return "\n".join(legend + titles + captions)


def pages(client) -> str:
    return "\n".join(world_parts(page) for page in walk(client, start(client, "?workerId=W1&assignmentId=A1&hitId=H1")))


def test_a_highway_bundle_speaks_of_cars_and_never_of_people(make_client, crowd_bundle, tmp_path):
    bundle = with_world(crowd_bundle, tmp_path / "highway", CARS.to_manifest())
    shown = pages(make_client(bundle_dir=bundle))
    assert "Traffic: the other cars, in blue" in shown and 'class="marker person"' not in shown
    assert "<strong>CRASH</strong> mark a car hitting another car" in shown and "Trails:" not in shown
    assert "Clip of two self-driving cars on a highway" in shown and CARS.words.example_caption in shown
    assert (
        re.search(r"Robot \d crashed after 6.0 seconds\.", shown)
        and "drove through and came close to other cars" in shown
    )
    assert CROWD_WORDS.findall(shown) == []


def test_a_crowd_bundle_reads_as_before(make_client, crowd_bundle):
    shown = pages(make_client(bundle_dir=crowd_bundle))
    assert (
        '<li><span class="marker person" aria-hidden="true">0</span> People: grey discs with a number, each with a '
        "short tail showing where it walks.</li>" in shown
    )
    assert (
        "<li>Below the picture each robot's line says <strong>reached goal</strong> or <strong>out of time</strong> "
        "with the time, or <strong>on its way</strong> (<strong>still on its way</strong> when the clip ends, with how "
        "far it stopped from its goal).</li>" in shown
    )
    assert "Clip of two robots in a crowd" in shown and "move through a crowd to the same goal." in shown
    assert re.search(r"Robot \d bumped into a person\.", shown)
    assert re.search(r"Robot \d reached the goal after 9.0 seconds\.", shown)


def test_a_legend_line_is_text_whatever_the_manifest_says(make_client, crowd_bundle, tmp_path):
    sly = replace(CARS, words=replace(CARS.words, legend_others="<script>x</script> & **bold**"))
    shown = pages(make_client(bundle_dir=with_world(crowd_bundle, tmp_path / "sly", sly.to_manifest())))
    assert "&lt;script&gt;x&lt;/script&gt; &amp; <strong>bold</strong>" in shown and "<script>x" not in shown


def test_the_bots_judge_and_explain_by_the_bundles_world(crowd_bundle, tmp_path):
    clips = ClipIndex(with_world(crowd_bundle, tmp_path / "highway", CARS.to_manifest())).clips.values()
    assert {clip.world for clip in clips} == {CARS}
    said = " ".join(clip.describe(label) for clip in clips for label in clip.labels)
    assert "crashed after 6.0 seconds" in said and CROWD_WORDS.findall(said) == []


def test_only_a_world_of_its_own_is_written_into_a_manifest(crowd_bundle):
    crowd = Manifest.model_validate_json((crowd_bundle / "manifest.json").read_text())
    assert crowd.world is None and '"world"' not in manifest_json(crowd)
    assert load_bundle(crowd_bundle).world == CROWD
    highway = crowd.model_copy(update={"world": CARS.to_manifest()})
    assert Manifest.model_validate_json(manifest_json(highway)).shown_world() == CARS


def test_a_world_the_server_cannot_speak_of_stops_it_at_start_up(crowd_bundle, tmp_path):
    bundle = with_world(crowd_bundle, tmp_path / "odd", {"domain": "highway", "rule": "fastest"})
    with pytest.raises(BundleError, match="world.rule must be one of 'goal', 'survival', 'score', not 'fastest'"):
        load_bundle(bundle)
