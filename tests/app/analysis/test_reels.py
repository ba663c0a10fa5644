"""`foil simulate`'s bots on pairs of reels: a bot finds a reels screen's clip by its two videos, judges each robot by
its reel's segments and answers like a participant, through the real app."""

from __future__ import annotations

import random
import shutil
from pathlib import Path

import pytest

from app.analysis.bots import Bot, ClipIndex
from app.store.models import Participant, Response
from app.survey.kinds import pilot_token
from app.visible import Observer, VisibleReels
from tests.support.analysis import add_reels
from tests.support.survey import stored


@pytest.fixture(scope="module")
def reels_bundle(tmp_path_factory, bundle_dir) -> Path:
    """The bots' bundle with a pair of reels for every pairwise screen."""
    root = shutil.copytree(bundle_dir, tmp_path_factory.mktemp("reels") / "bundle")
    return add_reels(root, root / "clips" / "000.mp4")


def test_a_bot_judges_a_pair_of_reels_by_each_robots_moments(make_client, reels_bundle):
    client = make_client({"platform": '"none"', "assignment": '"balanced"'}, bundle_dir=reels_bundle)
    clips = ClipIndex(reels_bundle)
    assert sum(isinstance(clip, VisibleReels) for clip in clips.clips.values()) == 12
    token = pilot_token(client.app.state.context.db, "paper")
    observer, rng, link = Observer(noise=0.0), random.Random(0), {"pilot": token}
    run = Bot(client, clips, observer, rng, number=0, external_id="reels", link=link, fast=True).take_study()
    assert run.completed
    assert sum("+" in (answer["clip"] or "") for answer in run.answers if answer["question"] == "better") == 6

    plan = stored(client, Participant)[0].plan
    reels = [(response, plan[response.step]) for response in stored(client, Response) if "reels" in plan[response.step]]
    assert len(reels) == 6
    for response, screen in reels:
        chosen = next(robot["agent"] for robot in screen["robots"] if robot["label"] == response.answers["better"])
        assert chosen == screen["better"]  # each reel's segments show its robot as SHOWN says: the better one wins
        assert {(e["type"], e.get("reel")) for e in response.video_events} >= {("ended", 0), ("ended", 1)}
