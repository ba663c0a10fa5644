"""The clip audit: what a clip visibly shows about the better robot, judged by the bots' observer rule."""

from __future__ import annotations

import json

import pytest

from app.visible import CROWD, Observer, VisibleClip, VisibleReels, Words, World, audit


def summary(*outcomes: dict, ends: tuple[tuple[float, float], ...] = ((0.0, 0.0), (0.0, 0.0)), t: float = 25.0):
    """A hand-made summary of agents lo and hi going from (-5, -5) to (5, 5), ending at ``ends``."""
    return {
        "agents": [{"name": "lo"}, {"name": "hi"}],
        "scenario": {"robot": {"start": [-5.0, -5.0], "goal": [5.0, 5.0]}},
        "steps": [{"t": t, "agent_positions": [list(end) for end in ends]}],
        "outcomes": list(outcomes),
    }


SUCCESS = {"event": "success", "time": 14.0, "min_other_distance": 0.9}
LATE = {"event": "success", "time": 24.0, "min_other_distance": 0.9}
CRASH = {"event": "collision", "time": 3.5, "min_other_distance": -0.05}
RUNNING = {"event": "running", "time": None, "min_other_distance": 0.8}


@pytest.mark.parametrize(
    "lo, hi, ends, shows",
    [
        (CRASH, SUCCESS, ((-3, -3), (5, 5)), "better"),  # the worse robot crashes, the better one arrives
        (SUCCESS, CRASH, ((5, 5), (-3, -3)), "worse"),  # the better robot crashes early: the paper's failure
        (RUNNING, LATE, ((0, 0), (5, 5)), "better"),
        (LATE, RUNNING, ((5, 5), (0, 0)), "worse"),  # the worse robot arrives while the better is on its way
        (RUNNING, RUNNING, ((0.1, 0.1), (0.3, 0.3)), "tie"),  # both on their way, about as far
        (SUCCESS, SUCCESS, ((5, 5), (5, 5)), "tie"),
    ],
)
def test_audit_judges_what_the_clip_shows_against_the_ground_truth(lo, hi, ends, shows):
    for agents, labels in ((["lo", "hi"], ["Robot 1", "Robot 2"]), (["hi", "lo"], ["Robot 1", "Robot 2"])):
        clip = VisibleClip.of_summary(summary(lo, hi, ends=ends), agents, labels)
        verdict = audit(clip, labels[agents.index("hi")])
        assert verdict["shows"] == shows
        assert all(label in verdict["why"] for label in labels)


def test_audit_names_what_happened():
    clip = VisibleClip.of_summary(
        summary(CRASH, SUCCESS, ends=((-3, -3), (5, 5))), ["lo", "hi"], ["Robot 1", "Robot 2"]
    )
    why = audit(clip, "Robot 2")["why"]
    assert why == "Robot 2 reached the goal after 14.0 seconds. Robot 1 bumped into a person."
    with pytest.raises(ValueError, match="compares two agents"):
        audit(clip, "Robot 3")


def test_the_audit_says_what_the_clip_says_of_a_robot_still_moving_at_its_end():
    """A robot still moving when the clip ends is "still on its way" in the clip's legend and in the audit, never
    "did not reach the goal in time"; one whose episode ran out of time is "out of time" in both."""
    from search.clips.render import status_text

    clip = VisibleClip.of_summary(summary(RUNNING, LATE, ends=((0, 0), (5, 5))), ["lo", "hi"], ["Robot 1", "Robot 2"])
    why = audit(clip, "Robot 2")["why"]
    assert "Robot 1 was still on its way when the clip ended, 7.1 m from the goal." in why and "in time" not in why
    assert status_text("running", 25.0, 7.07) == "still on its way · 7.1 m to goal"
    timed_out = {"event": "timeout", "time": 50.0, "min_other_distance": 0.8}
    clip = VisibleClip.of_summary(summary(timed_out, LATE, ends=((0, 0), (5, 5))), ["lo", "hi"], ["A", "B"])
    assert "A ran out of time before reaching the goal" in audit(clip, "B")["why"]
    assert status_text("timeout", 50.0).startswith("out of time")


HIGHWAY = World(domain="highway", rule="survival", words=Words(collision="crashed after {seconds} seconds"))


@pytest.mark.parametrize(
    "lo, hi, shows",
    [
        ({"event": "collision", "time": 4.0}, {"event": "collision", "time": 15.0}, "better"),  # lasted 11 s longer
        ({"event": "collision", "time": 15.0}, {"event": "collision", "time": 4.0}, "worse"),
        ({"event": "collision", "time": 20.0}, {"event": "success", "time": 25.0}, "better"),
        ({"event": "collision", "time": 20.0}, {"event": "timeout", "time": 25.0}, "better"),
        ({"event": "success", "time": 25.0}, {"event": "success", "time": 25.0}, "tie"),  # both drove through
        ({"event": "running", "time": None}, {"event": "timeout", "time": 25.0}, "tie"),  # both lasted the clip
    ],
)
def test_the_survival_rule_judges_how_long_a_robot_lasted(lo, hi, shows):
    """Where the task is to last (driving, balancing) there is no goal: crashing later is better, and two robots
    that both last the clip look alike, whatever their progress towards a goal the clip never shows."""
    clip = VisibleClip.of_summary(summary(lo, hi, ends=((5, 5), (-5, -5))), ["lo", "hi"], ["A", "B"], HIGHWAY)
    assert audit(clip, "B")["shows"] == shows


def test_a_world_describes_its_clips_in_its_own_words():
    crashes = summary({"event": "collision", "time": 4.0}, {"event": "collision", "time": 15.4})
    clip = VisibleClip.of_summary(crashes, ["lo", "hi"], ["A", "B"], HIGHWAY)
    assert audit(clip, "B")["why"] == "B crashed after 15.4 seconds. A crashed after 4.0 seconds."
    assert VisibleClip.of_summary(crashes, ["lo", "hi"], ["A", "B"]).describe("A") == "A bumped into a person."


def test_a_world_goes_through_the_manifest_unchanged():
    assert World.from_manifest(None) == CROWD and World.from_manifest({}) == World()  # no world object: the crowd
    assert World.from_manifest(json.loads(json.dumps(HIGHWAY.to_manifest()))) == HIGHWAY
    assert World.from_manifest({"domain": "cartpole", "rule": "survival"}).words == Words()


@pytest.mark.parametrize(
    "data, message",
    [
        ({"domain": "highway", "rules": "survival"}, "world has unknown key.*'rules'"),
        ({"rule": "longest"}, "world.rule must be one of 'goal', 'survival', 'score', not 'longest'"),
        ({"domain": ""}, "world.domain must be a world's name"),
        ({"words": {"crash": "crashed"}}, "world.words has unknown key.*'crash'"),
        ({"words": {"collision": "crashed after {time} seconds"}}, "world.words.collision: .* may name only {seconds}"),
        ({"words": {"success": 3}}, "world.words.success must be a text"),
        ({"words": ["drove through"]}, "world.words must be an object of texts"),
        ("highway", "world must be an object"),
    ],
)
def test_a_world_this_version_cannot_read_is_refused_by_name(data, message):
    with pytest.raises(ValueError, match=message):
        World.from_manifest(data)


def test_a_clip_is_judged_by_a_known_rule():
    with pytest.raises(ValueError, match="not 'fastest'"):
        Observer().visible_score({"event": "success", "time": 3.0}, 10.0, 1.0, rule="fastest")


@pytest.mark.parametrize("time, shown", [(7.5, "7.5"), (10.5, "10.5"), (8.0, "8.0"), (17.25, "17.2")])
def test_a_page_says_the_time_its_clip_says(time, shown):
    """Not rounded another way: a clip showing "7.5 s" is not summarised "after 8 seconds"."""
    from search.clips.render import status_text

    arrived = {"event": "success", "time": time, "min_other_distance": 0.9}
    clip = VisibleClip.of_summary(summary(arrived, LATE, ends=((5, 5), (5, 5))), ["lo", "hi"], ["A", "B"])
    assert clip.describe("A") == f"A reached the goal after {shown} seconds."
    assert status_text("success", time) == f"reached goal · {shown} s"


def test_a_robot_that_stops_beside_its_goal_says_how_close_it_got():
    """A robot whose marker sits on the goal's rings at the end has not reached the goal (the world judges its
    centre within its radius of the goal): clip and page both say how far it still was."""
    from search.clips.render import Frame
    from search.crowd.render import CrowdClipRenderer
    from search.crowd.scene import scene_from_summary
    from search.crowd.sim.scenarios import load_scenario
    from tests.support.summaries import summary_from_simulation

    data = summary_from_simulation(["goal", "orca"], load_scenario("paper-bl-tr"))
    goal = data["scenario"]["robot"]["goal"]
    data["outcomes"][0] = {"event": "running", "time": None, "min_other_distance": 0.9}
    data["steps"][-1]["agent_positions"][0] = [goal[0] + 0.4, goal[1]]
    clip = VisibleClip.of_summary(data, [agent["name"] for agent in data["agents"]], ["A", "B"])
    assert clip.describe("A") == "A was still on its way when the clip ended, 0.4 m from the goal."
    renderer = CrowdClipRenderer(scene_from_summary(data))
    renderer.draw(Frame(renderer.scene.end_time))
    assert "still on its way · 0.4 m to goal" in renderer.texts


def segment(leader: int, *outcomes: dict, ends=((0.0, 0.0), (0.0, 0.0))) -> dict:
    """A segment of a reel: ``summary`` whose robots all follow robot ``leader``, whose outcome it shows."""
    return summary(*outcomes, ends=ends) | {"follow": {"leader": leader, "steps": 100}}


def test_a_robots_reel_is_judged_by_its_moments_on_average_read_at_the_robot_followed():
    """A reel shows one robot in moments of its own runs: its score is the mean of its segments' scores, each the
    outcome of the robot the segment's robots follow (not of the others, whose instances only move with it)."""
    lo = [segment(0, SUCCESS, CRASH), segment(1, SUCCESS, CRASH)]  # arrives after 14 s (2.44), then crashes (-1)
    hi = [segment(1, CRASH, LATE), segment(0, RUNNING, CRASH)]  # arrives after 24 s (2.04), then halfway (0.5)
    reels = VisibleReels.of_summaries([lo, hi], ["Robot 1", "Robot 2"])
    scores = reels.scores(Observer())
    assert scores == pytest.approx({"Robot 1": (2.44 - 1) / 2, "Robot 2": (2.04 + 0.5) / 2})
    assert reels.end_s == 100.0 and reels.reel_s == (50.0, 50.0)
    verdict = audit(reels, "Robot 2")
    assert verdict == {
        "shows": "better",
        "why": "Robot 2, in 2 moments of its own: reached the goal after 24.0 seconds; was still on its way when the "
        "clip ended, 7.1 m from the goal. Robot 1, in 2 moments of its own: reached the goal after 14.0 seconds; "
        "bumped into a person.",
    }
    assert audit(VisibleReels.of_summaries([hi, lo], ["Robot 1", "Robot 2"]), "Robot 2")["shows"] == "worse"
    assert audit(VisibleReels.of_summaries([lo, lo[::-1]], ["A", "B"]), "B")["shows"] == "tie"


def test_a_reel_needs_segments_that_say_whom_they_follow():
    with pytest.raises(ValueError, match="says whom its agents follow"):
        VisibleReels.of_summaries([[summary(SUCCESS, CRASH)], [segment(0, SUCCESS, CRASH)]], ["A", "B"])
    with pytest.raises(ValueError, match="at least one segment"):
        VisibleReels.of_summaries([[], [segment(0, SUCCESS, CRASH)]], ["A", "B"])


def test_a_windowed_clip_is_judged_from_the_window_and_says_the_runs_time_as_its_clock_does():
    """A disagreement or HIGHLIGHTS moment shows only its window, its clock at the run's time: the audit and the bots
    judge what the window shows, and the ranking page's lines say the run's time, so a page never says another time
    than its clip."""
    from app.visible import VisibleClip

    steps = [{"t": 0.25 * (i + 1), "agent_positions": [[0.0, 0.0], [0.0, 0.0]]} for i in range(40)]
    summary = {
        "agents": [{"name": "a"}, {"name": "b"}],
        "scenario": {"robot": {"start": [0.0, -4.0], "goal": [0.0, 4.0]}},
        "steps": steps,
        "outcomes": [
            {"event": "success", "time": 7.5, "min_other_distance": 1.0},
            {"event": "collision", "time": 2.0, "min_other_distance": -0.1},  # before the window: at its start
        ],
        "window": [20, 40],  # from the state at 5.0 s to the one at 10.0 s
    }
    clip = VisibleClip.of_summary(summary, ["a", "b"], ["Robot 1", "Robot 2"])
    assert clip.end_s == 5.0
    assert clip.describe("Robot 1").startswith("Robot 1 reached the goal after 7.5 seconds")
    assert clip.outcomes[1]["time"] == 0.0
    whole = VisibleClip.of_summary({k: v for k, v in summary.items() if k != "window"}, ["a", "b"], ["1", "2"])
    assert whole.end_s == 10.0 and whole.outcomes[0]["time"] == 7.5
