"""Crowd clips of the summaries of Agent Disagreements and HIGHLIGHTS: a ``window`` shows only its states with the
run's clock, a leader followed throughout is drawn alone, and the moment agents that followed a leader part is
captioned and ringed for about a second of video. Summaries from a real simulation, the keys written in by hand
(the renderer reads them; it does not re-simulate)."""

from __future__ import annotations

import json

import imageio_ffmpeg
import numpy as np
from PIL import Image

from search.clips.render import (
    INK,
    PARTING_SECONDS,
    Frame,
    RenderOptions,
    agent_style,
    contact_sheet,
)
from search.crowd.render import CrowdClipRenderer, faded, render_file
from search.crowd.scene import scene_from_summary
from search.crowd.sim.scenarios import load_scenario
from tests.clips.test_render import colour_mask
from tests.support.summaries import summary_from_simulation, visible

PLAIN = RenderOptions(hold_start=0, hold_end=0, event_hold=0)  # one frame per 1/24 s of the summary, no more


def variant(summary: dict, **keys) -> dict:
    return json.loads(json.dumps(summary)) | keys


def test_a_window_shows_only_its_states_with_the_runs_clock(tmp_path, shared_summary):
    """Window [4, 24] of a summary whose first robot crashes at 2.75 s and whose second arrives at 16.75 s: 5 s
    of states from 1.0 s, the crash 1.75 s into them, the arrival not yet (still on its way at the window's end);
    the clock and the crash read the run's time (1.0 s to 6.0 s, crashed at 2.8 s), as a whole run's clip would."""
    full = scene_from_summary(shared_summary)
    summary = variant(shared_summary, window=[4, 24])
    scene = scene_from_summary(summary)
    np.testing.assert_allclose(scene.times, full.times[4:25] - full.times[4])
    np.testing.assert_array_equal(scene.robots, full.robots[4:25])
    np.testing.assert_array_equal(scene.humans, full.humans[4:25])
    assert scene.outcomes == (("collision", 2.75 - 1.0), ("running", 5.0))

    path = tmp_path / "window.json"
    path.write_text(json.dumps(summary))
    result = render_file(path, tmp_path / "window.mp4", options=PLAIN)
    assert result.frames == 5 * 24 + 1 == imageio_ffmpeg.count_frames_and_secs(str(result.clip))[0]
    assert result.seconds == result.frames / 24

    renderer = CrowdClipRenderer(scene, options=PLAIN)
    with Image.open(result.poster) as poster:  # the window's first state
        assert np.array_equal(np.asarray(poster.convert("RGB")), np.asarray(renderer.draw(renderer.frames[0])))
    renderer.draw(renderer.frames[-1])
    assert scene.clock == 1.0
    assert {"Time  1.0 s", "Time  6.0 s", "CRASHED · 2.8 s"} <= renderer.texts
    assert any(text.startswith("still on its way · ") for text in renderer.texts)
    assert not any("reached goal" in text or "Time  0.0 s" in text for text in renderer.texts)


def test_trails_start_at_the_window(shared_summary):
    """Robot 2's path before the window (its first 4 s) leaves no trail in the window's first frame, where the
    whole clip's frame of the same state has one: trail colours in the arena away from the robots' markers."""
    full = CrowdClipRenderer(scene_from_summary(shared_summary), options=PLAIN)
    windowed = CrowdClipRenderer(scene_from_summary(variant(shared_summary, window=[16, 36])), options=PLAIN)
    shades = [faded(agent_style(2)[0], k / 8) for k in range(2, 9)]
    lay = full.layout
    rows, cols = np.mgrid[: lay.height, : lay.width]
    away = (rows > lay.header) & (rows < lay.header + lay.panel)
    for xy in full.pixels_robots[16]:
        away &= np.hypot(cols - xy[0], rows - xy[1]) > 2 * full.robot_px

    def trail_pixels(image) -> int:
        return int(sum((colour_mask(image, shade, tolerance=2) & away).sum() for shade in shades))

    assert trail_pixels(full.draw(Frame(4.0))) > 50
    assert trail_pixels(windowed.draw(Frame(0.0))) == 0


def test_a_leader_followed_throughout_is_drawn_alone(shared_summary):
    """follow.steps = every step: only the leader's robot, with the number given for it, in the arena and the
    legend; the other robot's colour appears nowhere."""
    summary = variant(shared_summary, follow={"leader": 1, "steps": len(shared_summary["steps"])})
    renderer = CrowdClipRenderer(scene_from_summary(summary), numbers=[2, 1])
    both = CrowdClipRenderer(scene_from_summary(shared_summary), numbers=[2, 1])
    assert renderer.numbers == [1] and renderer.scene.n_agents == 1
    assert renderer.scene.outcomes == (both.scene.outcomes[1],)
    assert renderer.layout.height < both.layout.height  # a legend of one line
    for t in (0.0, 5.0, renderer.scene.end_time):
        image = renderer.draw(Frame(t))
        assert colour_mask(image, agent_style(2)[0], tolerance=20).sum() == 0
        assert colour_mask(image, agent_style(1)[0], tolerance=3).sum() > 100
        assert colour_mask(both.draw(Frame(t)), agent_style(2)[0], tolerance=20).sum() > 100
    assert "Robot 1" in renderer.texts and "Robot 2" not in renderer.texts


def test_a_leader_alone_with_visible_robots_is_one_arena_of_its_own_crowd():
    summary = summary_from_simulation(["goal", "orca"], visible(load_scenario("paper-bl-tr")))
    full = scene_from_summary(summary)
    alone = scene_from_summary(variant(summary, follow={"leader": 0, "steps": len(summary["steps"])}))
    assert (full.n_panels, alone.n_panels) == (2, 1)
    np.testing.assert_array_equal(alone.humans[:, 0], full.humans[:, 0])
    assert CrowdClipRenderer(alone).layout.panels == 1


def test_the_moment_the_robots_part_is_captioned_for_about_a_second(shared_summary):
    """follow = {leader 1, steps 12} in window [4, 40]: the moment is s_12, 2.0 s into the window. The header
    carries the caption exactly in the frames within half a second of video of it, and a ring marks the leader's
    place then; elsewhere the clip looks as it would without the moment."""
    plain = CrowdClipRenderer(scene_from_summary(variant(shared_summary, window=[4, 40])), numbers=[2, 1])
    summary = variant(shared_summary, window=[4, 40], follow={"leader": 1, "steps": 12})
    renderer = CrowdClipRenderer(scene_from_summary(summary), numbers=[2, 1])
    scene = renderer.scene
    assert scene.parting == 2.0 and scene.leader == 1
    assert renderer.stack[-1] == 1  # the leader is drawn last, on top of the robot that moves with it
    assert len(renderer.frames) == len(plain.frames)
    header = slice(0, renderer.layout.header)
    marked = []
    for frame in renderer.frames[::3]:
        differs = not np.array_equal(np.asarray(renderer.draw(frame))[header], np.asarray(plain.draw(frame))[header])
        assert differs == (abs(frame.video - renderer.parting_video) <= PARTING_SECONDS / 2), frame
        marked.append(differs)
    assert 0.8 * PARTING_SECONDS < sum(marked) * 3 / renderer.options.fps <= 1.2 * PARTING_SECONDS
    assert "Here the two robots would act differently" in renderer.texts
    assert "Here the two robots would act differently" not in plain.texts

    moment = next(f for f in renderer.frames if f.video >= renderer.parting_video)
    _, robots, _ = renderer._state(scene.parting)
    ring = renderer.robot_px * 2.3
    rows, cols = np.mgrid[: renderer.layout.height, : renderer.layout.width]
    near = np.abs(np.hypot(cols - robots[1][0], rows - robots[1][1]) - ring) < 3
    inked = [(colour_mask(r.draw(moment), INK, tolerance=10) & near).sum() for r in (renderer, plain)]
    assert inked[0] > inked[1] + 2 * ring  # a ring around the leader

    sheet_only = CrowdClipRenderer(scene, numbers=[2, 1])
    contact_sheet(sheet_only)
    assert "Here the two robots would act differently" in sheet_only.texts  # the moment is one of its stills


def test_a_moment_outside_the_window_is_not_marked(shared_summary):
    for follow in ({"leader": 0, "steps": 2}, {"leader": 0, "steps": 50}):
        scene = scene_from_summary(variant(shared_summary, window=[4, 40], follow=follow))
        assert scene.parting is None and scene.n_agents == 2
