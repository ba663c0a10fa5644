"""A crashed car's readout stops where its run ended: the speed its view shows from the crash on, the one the pages
and the audit read from its summary, and the one the representative vote's fast rollouts score are the same."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from app.visible import VisibleClip, VisibleReels
from search.core.domain import domain_for
from search.gym.clips import load_gym_scene
from search.solvers.highlights import HighlightsDivConfig
from search.solvers.representative import RepresentativeConfig
from search.solvers.runner import SearchJob, run_search
from tests.support.played import checked_rollouts

AGENTS = ("tests.highway.drivers:faster", "tests.highway.drivers:slower")  # the faster one crashes in traffic


@pytest.fixture(scope="module")
def crash():
    """The representative clip of two drivers from highway traffic, in which the faster driver crashes."""
    job = SearchJob(
        agents=AGENTS,
        scenario="highway-traffic",
        solver="representative",
        budget=400,
        top_k=1,
        solver_config=RepresentativeConfig(states=2, pushes=0),
        reward_settings={"horizon": 20},
    )
    summary = json.loads(run_search(job)["summary-001.json"])
    assert summary["outcomes"][0]["event"] == "collision" and summary["outcomes"][1]["event"] != "collision"
    return summary


def test_the_crashed_cars_view_page_and_audit_read_one_speed(crash):
    domain = domain_for(list(AGENTS), "highway-traffic")
    world = domain.world("highway-traffic")
    clip = VisibleClip.of_summary(crash, list(AGENTS), ["Car 1", "Car 2"], world)
    crashed_at = crash["outcomes"][0]["time"]
    speeds = [step["scores"][0] for step in crash["steps"] if step["t"] <= crashed_at]
    assert clip.summed[0] == round(float(np.mean(speeds)))  # the mean up to the crash, not over the whole clip
    assert clip.summed[0] != round(float(np.mean([step["scores"][0] for step in crash["steps"]])))
    scene, _ = load_gym_scene(crash, [1, 2], 480)
    shown = re.search(r"(\d+) km/h mean speed", scene.caption(0, scene.end_time))
    assert shown and int(shown.group(1)) == clip.summed[0]  # the frozen view's readout
    assert f"had a mean speed of {clip.summed[0]:.0f} km/h" in clip.describe("Car 1")  # the pages' and audit's


def test_the_fast_rollouts_score_a_crash_as_its_summary_does():
    """Three drivers on the kernel: each pair's clips read from all three's rollouts as from the pair's own, and
    as from each rollout's summary."""
    agents = [*AGENTS, "tests.highway.drivers:idle"]
    domain = domain_for(agents, "highway-traffic")
    states = domain.draw_states("highway-traffic", {}, np.random.default_rng(0), 2)
    fast = checked_rollouts(domain, agents, states, 20, 1).pair(0, 1)[0]
    assert (fast.contrast <= -1).any()  # crashes among them


def test_a_clip_longer_than_a_highway_episode_is_refused_before_any_work(tmp_path, capsys):
    from search.cli import main

    args = ["search", "--agents", ",".join(AGENTS), "--scenario", "highway-dense", "--solver", "nfirst"]
    assert main([*args, "--reward", "horizon=40", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "longer than an episode here (30 s)" in capsys.readouterr().err and not (tmp_path / "out").exists()


def test_a_reels_readout_at_each_moments_end_is_that_moments_score():
    """HIGHLIGHTS shows each car in moments of its own drives, one after the other: each moment's readout sums
    that moment alone and says so, so where the next moment starts it never reads as a mean over the reel."""
    job = SearchJob(
        agents=AGENTS,
        scenario="highway-traffic",
        solver="highlights-div",
        budget=400,
        solver_config=HighlightsDivConfig(episodes=3, highlights=2, context=5, lookahead=2),
        reward_settings={"horizon": 20},
    )
    files = run_search(job)
    moments = [json.loads(files[name]) for name in sorted(files) if name.startswith("summary-")]
    reels = [[m for m in moments if m["follow"]["leader"] == k] for k in range(2)]
    world = domain_for(list(AGENTS), "highway-traffic").world("highway-traffic")
    judged = VisibleReels.of_summaries(reels, ["Car 1", "Car 2"], world)
    assert [len(reel) for reel in judged.reels] == [2, 2]
    for k, reel in enumerate(reels):
        for moment, shown in zip(reel, judged.reels[k], strict=True):
            scene, _ = load_gym_scene(moment, [1, 2], 480)
            assert scene.caption(k, scene.end_time) == f"{shown.summed[0]:.0f} km/h mean speed this moment"
    ended = [m["outcomes"][m["follow"]["leader"]]["event"] for m in moments]
    assert "collision" in ended  # a crashed car's moment among them: its readout froze at the crash
