"""Clips of any Gymnasium environment: a tiny environment written here, with a 120x80 ``render()`` and an adapter
that defines none of the clip hooks, renders through the generic renderer; an adapter may name its own."""

from __future__ import annotations

import json
import math
import re

import gymnasium
import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from search.api import Adapter
from search.clips.render import CRASH, PARTING_SECONDS, RenderOptions, agent_style
from search.gym.clips import GymClipRenderer, render_gym
from search.solvers.baselines import SamplingConfig
from search.solvers.runner import SearchJob, run_search, write_outputs
from tests.clips.test_render import colour_mask, probe, top_level_boxes

FAST = dict(speed=4.0, hold_start=0.2, hold_end=0.2, event_hold=0.2, width=480)


class Track(gymnasium.Env):
    """A block runs along a track towards a wall the environment action pushes back and forth; touching it is a
    crash, six steps without one a timeout; a point for every step without one. Drawn 120 px wide and 80 px tall."""

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, render_mode=None):
        self.render_mode = render_mode
        self.action_space = gymnasium.spaces.Box(0.0, 1.0, (1,), dtype=np.float64)
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (2,), dtype=np.float64)
        self.push = 0.0

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.wall, self.steps = 0.0, float(self.np_random.uniform(2.5, 3.0)), 0
        return np.array([self.x, self.wall]), {}

    def step(self, action):
        self.x += float(action[0])
        self.wall += 0.2 * self.push
        self.steps += 1
        crashed = self.x >= self.wall
        return np.array([self.x, self.wall]), float(not crashed), crashed, self.steps >= 6, {"crashed": crashed}

    def render(self):
        frame = np.full((80, 120, 3), 230, dtype=np.uint8)
        frame[30:50, 10 + int(20 * self.x) : 20 + int(20 * self.x)] = (40, 40, 40)
        frame[:, min(119, 10 + int(20 * self.wall))] = (120, 60, 0)
        return frame


class TrackAdapter(Adapter):
    """The template filled in, and nothing for clips."""

    env_action_shape = (1,)
    dt = 0.5

    def make(self, render=False):
        return Track(render_mode="rgb_array" if render else None)

    def apply(self, env, action):
        env.unwrapped.push = float(action[0])

    def position(self, env):
        return np.array([env.unwrapped.x])


class OwnClipsAdapter(TrackAdapter):
    renderer = "tests.gym.test_gym_clips:own_renderer"


def own_renderer(summary_path, out, numbers=None, options=None):
    """A renderer of an adapter's own: here it only says it was called."""
    return ("own", str(summary_path), str(out), numbers, options)


def fast(observations):
    """Runs at the wall."""
    return np.ones((len(observations), 1))


def slow(observations):
    """Creeps along: out of time before it reaches the wall."""
    return np.full((len(observations), 1), 0.1)


@pytest.fixture(scope="module")
def summary_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("search")
    (folder / "track.toml").write_text('adapter = "tests.gym.test_gym_clips:TrackAdapter"\nseed = 3\n')
    job = SearchJob(
        agents=("tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"),
        scenario=str(folder / "track.toml"),
        solver="random",
        budget=12,
        top_k=1,
        solver_config=SamplingConfig(batch=1),
    )
    out = write_outputs(folder, run_search(job))
    return out / "summary-001.json"


def test_a_summary_of_any_environment_renders_as_browser_safe_h264_with_poster_and_sheet(tmp_path, summary_file):
    result = render_gym(summary_file, tmp_path / "clip.mp4", [3, 1], RenderOptions(**FAST))
    info = probe(result.clip)
    video = re.search(r"Video: (\w+).*?, (\w+)(?:\(.*?\))?, (\d+)x(\d+)", info)
    assert video and (video.group(1), video.group(2)) == ("h264", "yuv420p"), info
    assert (int(video.group(3)), int(video.group(4))) == (result.width, result.height)
    assert result.width % 16 == 0 and result.height % 16 == 0
    assert top_level_boxes(result.clip).index("moov") < top_level_boxes(result.clip).index("mdat")
    assert imageio_ffmpeg.count_frames_and_secs(str(result.clip))[0] == result.frames > 10
    with Image.open(result.poster) as poster, Image.open(result.sheet) as sheet:
        assert poster.size == (result.width, result.height) and sheet.width > poster.width


def test_views_keep_the_environments_shape_side_by_side_in_robot_number_order(summary_file):
    summary = json.loads(summary_file.read_text())
    assert [o["event"] for o in summary["outcomes"]] == ["collision", "timeout"]
    renderer = GymClipRenderer(summary, [3, 1], RenderOptions(width=480))
    lay = renderer.layout
    assert lay.columns == 2 and abs(lay.view_height / lay.panel - 80 / 120) < 1 / lay.panel  # never squeezed
    image = np.asarray(renderer.draw(renderer.frames[-1]))
    for slot, (k, number) in enumerate([(1, 1), (0, 3)]):  # Agent 1 (the slow agent) first
        assert renderer.order[slot] == k
        x0, y0 = lay.origin(slot)
        view = image[y0 : y0 + lay.view_height, x0 : x0 + lay.panel]
        expected = Image.fromarray(renderer.scene.views[k][-1]).resize((lay.panel, lay.view_height), Image.LANCZOS)
        assert np.abs(view.astype(int) - np.asarray(expected)).mean() < 30  # its frame (a crash mark aside)
        band = image[y0 + lay.view_height : y0 + lay.view_height + lay.band, x0 : x0 + lay.panel]
        colour = np.array(agent_style(number)[0])
        assert (np.abs(band.astype(int) - colour).sum(axis=2) < 30).sum() > 20  # its icon
    crash = renderer.event_starts[summary["outcomes"][0]["time"]]
    at_crash = next(frame for frame in renderer.frames if frame.video >= crash)
    x0, y0 = lay.origin(1)  # the crashed agent's view
    yellow = [
        (
            np.abs(np.asarray(renderer.draw(f))[y0 : y0 + lay.view_height, x0:].astype(int) - CRASH).sum(axis=2) < 30
        ).sum()
        for f in (at_crash, renderer.frames[-1])
    ]
    assert yellow[1] < yellow[0] / 4  # the burst gives way to a small mark
    words = TrackAdapter.status_words
    assert {"Agent 1", "Agent 3", words["timeout"]} <= renderer.texts
    assert any(text.startswith(words["collision"]) for text in renderer.texts)
    assert not any("fast" in text or "slow" in text for text in renderer.texts)  # never the real names


def test_an_adapter_may_name_its_own_renderer(tmp_path, summary_file):
    summary = json.loads(summary_file.read_text())
    summary["scenario"]["adapter"] = "tests.gym.test_gym_clips:OwnClipsAdapter"
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(summary))
    assert render_gym(path, tmp_path / "clip.mp4", [1, 2]) == (
        "own",
        str(path),
        str(tmp_path / "clip.mp4"),
        [1, 2],
        None,
    )


# Clips of the summaries of Agent Disagreements and HIGHLIGHTS (docs/clips.md): the keys written into the search's
# summary by hand; the replay follows the leader as a search that follows would.

PLAIN = dict(hold_start=0, hold_end=0, event_hold=0, width=480)  # one frame per 1/24 s of the summary


def with_keys(summary_file, **keys) -> dict:
    return json.loads(summary_file.read_text()) | keys


def test_a_window_shows_its_states_with_the_runs_clock(tmp_path, summary_file):
    """States 1..4 (0.5 s to 2 s) of a clip whose fast agent crashes at 1.5 s and whose slow one runs out of
    time at 3 s: 1.5 s of states, the crash 1.0 s into them, the slow agent still running at the end; the clock
    reads the run's time (0.5 s to 2.0 s)."""
    full = GymClipRenderer(json.loads(summary_file.read_text()), [3, 1], RenderOptions(**PLAIN))
    summary = with_keys(summary_file, window=[1, 4])
    renderer = GymClipRenderer(summary, [3, 1], RenderOptions(**PLAIN))
    scene = renderer.scene
    assert scene.end_time == 1.5 and scene.outcomes == [("collision", 1.0), ("running", math.inf)]
    for k in range(2):
        assert np.array_equal(scene.views[k][0], full.scene.views[k][1])  # s_1 first
    path = tmp_path / "window.json"
    path.write_text(json.dumps(summary))
    result = render_gym(path, tmp_path / "window.mp4", [3, 1], RenderOptions(**PLAIN))
    assert result.frames == 1.5 * 24 + 1 == imageio_ffmpeg.count_frames_and_secs(str(result.clip))[0]
    renderer.draw(renderer.frames[-1])
    assert scene.clock == 0.5 and {"Time  2.0 s", TrackAdapter.status_words["running"]} <= renderer.texts
    assert TrackAdapter.status_words["timeout"] not in renderer.texts


def test_a_leader_followed_throughout_is_shown_alone(summary_file):
    """Every agent took the slow agent's actions on every step: one full-width view, the slow agent's (Agent 1)."""
    renderer = GymClipRenderer(with_keys(summary_file, follow={"leader": 1, "steps": 6}), [3, 1], RenderOptions(**FAST))
    assert renderer.order == [1] and renderer.layout.columns == 1 and renderer.layout.panel == 480
    for frame in (renderer.frames[0], renderer.frames[-1]):
        image = renderer.draw(frame)
        assert colour_mask(image, agent_style(3)[0], tolerance=20).sum() == 0
        assert colour_mask(image, agent_style(1)[0], tolerance=3).sum() > 20
    assert "Agent 1" in renderer.texts and "Agent 3" not in renderer.texts


class PartingAdapter(TrackAdapter):
    parting_caption = "Here the {count} blocks would move differently"


def test_the_moment_the_agents_part_is_captioned_in_the_adapters_words(summary_file):
    """Both agents take the slow agent's actions on steps 1 and 2, then each its own: their views are one until
    s_2 and part after it; the header says so for about a second of video around s_2."""
    summary = with_keys(summary_file, follow={"leader": 1, "steps": 2})
    plain = GymClipRenderer(json.loads(summary_file.read_text()), [3, 1], RenderOptions(**FAST))
    renderer = GymClipRenderer(summary, [3, 1], RenderOptions(**FAST))
    views = renderer.scene.views
    assert all(np.array_equal(views[0][i], views[1][i]) for i in range(3))
    assert not np.array_equal(views[0][3], views[1][3])
    assert renderer.scene.parting == 1.0 and len(renderer.frames) == len(plain.frames)
    header = slice(0, renderer.layout.header)
    for frame in renderer.frames:
        differs = not np.array_equal(np.asarray(renderer.draw(frame))[header], np.asarray(plain.draw(frame))[header])
        assert differs == (abs(frame.video - renderer.parting_video) <= PARTING_SECONDS / 2), frame
    assert "Here the two agents would act differently" in renderer.texts

    summary["scenario"]["adapter"] = "tests.gym.test_gym_clips:PartingAdapter"
    own = GymClipRenderer(summary, [3, 1], RenderOptions(**FAST))
    own.draw(next(f for f in own.frames if f.video >= own.parting_video))
    assert "Here the two blocks would move differently" in own.texts


class OffTheViewAdapter(TrackAdapter):
    def crash_point(self, env):
        return (0.5, 1.6)  # below the view, as a car that left the road and its verge


def test_a_crash_outside_the_view_is_marked_at_its_edge_not_in_the_band_beside_it(summary_file):
    """The burst of a crash the adapter puts below the view is drawn whole inside the view, at its bottom edge."""
    summary = json.loads(summary_file.read_text())
    summary["scenario"]["adapter"] = "tests.gym.test_gym_clips:OffTheViewAdapter"
    renderer = GymClipRenderer(summary, [3, 1], RenderOptions(width=480))
    lay = renderer.layout
    crash = renderer.event_starts[summary["outcomes"][0]["time"]]
    image = np.asarray(renderer.draw(next(frame for frame in renderer.frames if frame.video >= crash)))
    x0, y0 = lay.origin(1)  # the crashed agent's view
    yellow = np.abs(image[:, x0 : x0 + lay.panel].astype(int) - CRASH).sum(axis=2) < 30
    burst = yellow[y0 : y0 + lay.view_height]
    assert burst.sum() > 50 and not burst[-1].any()  # whole inside the view
    band = yellow[y0 + lay.view_height :, : lay.text * 2]  # the band's icon column, left of the CRASHED tag
    assert not band.any()


def test_highway_cars_part_in_a_drivers_words(tmp_path):
    """A highway search's summary with its cars following the cautious driver (who lasts the drive) for 3 s:
    both egos are at one place at that moment, and the caption speaks of cars."""
    job = SearchJob(
        agents=("tests.highway.drivers:idle", "tests.highway.drivers:slower"),
        scenario="highway-dense",
        solver="random",
        budget=400,
        top_k=1,
        solver_config=SamplingConfig(batch=1),
    )
    summary = json.loads((write_outputs(tmp_path, run_search(job)) / "summary-001.json").read_text())
    assert summary["outcomes"][1]["event"] == "success"
    renderer = GymClipRenderer(summary | {"follow": {"leader": 1, "steps": 3}, "window": [1, 8]}, [1, 2])
    points = renderer.scene.parting_points
    assert renderer.scene.parting == 2.0 and points[0] is not None and points[0] == points[1]
    renderer.draw(next(f for f in renderer.frames if f.video >= renderer.parting_video))
    assert "Here the two cars would drive differently" in renderer.texts


def test_an_environment_that_draws_no_frame_gets_a_clear_error(tmp_path):
    """The corridor of tests/gym/corridor.py has no render(): its clip is refused with what to give instead."""
    from search.gym.clips import render_gym
    from search.solvers.runner import SearchJob, run_search, write_outputs
    from tests.gym.test_gym_problem import BOX, scenario_file

    job = SearchJob(agents=BOX, scenario=scenario_file(tmp_path), solver="nfirst", budget=60, top_k=1)
    out = write_outputs(tmp_path / "out", run_search(job))
    with pytest.raises(ValueError, match=r"Corridor draws no RGB frame: .*render\(\) returns an RGB array"):
        render_gym(out / "summary-001.json", tmp_path / "clip.mp4", [1, 2], None)
    assert not (tmp_path / "clip.mp4").exists()
