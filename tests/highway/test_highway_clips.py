"""Highway clips through the generic Gymnasium renderer: highway-env's own offscreen views with Foil's labels,
colours, clock and status, grey traffic, the ego's speed, and a crash burst that gives way to a small mark."""

from __future__ import annotations

import re

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from search.clips.render import AGENT_COLOURS, RenderOptions, agent_style
from search.gym.clips import GymClipRenderer, render_gym
from search.highway.adapter import EGO_AT, TRAFFIC
from search.solvers.baselines import SamplingConfig
from search.solvers.runner import SearchJob, run_search, write_outputs
from tests.clips.test_render import probe, top_level_boxes

DRIVERS = ("tests.highway.drivers:idle", "tests.highway.drivers:slower")


@pytest.fixture(scope="module")
def summary_file(tmp_path_factory):
    job = SearchJob(
        agents=DRIVERS,
        scenario="highway-dense",
        solver="random",
        budget=60,
        top_k=1,
        solver_config=SamplingConfig(batch=1),
    )
    out = write_outputs(tmp_path_factory.mktemp("search"), run_search(job))
    return out / "summary-001.json"


def test_a_highway_clip_is_browser_safe_h264_with_poster_and_contact_sheet(tmp_path, summary_file):
    result = render_gym(summary_file, tmp_path / "clip.mp4", [2, 1], RenderOptions(speed=4))
    info = probe(result.clip)
    video = re.search(r"Video: (\w+).*?, (\w+)(?:\(.*?\))?, (\d+)x(\d+)", info)
    assert video and (video.group(1), video.group(2)) == ("h264", "yuv420p"), info
    assert int(video.group(3)) % 16 == 0 and int(video.group(4)) % 16 == 0
    boxes = top_level_boxes(result.clip)
    assert boxes.index("moov") < boxes.index("mdat")
    assert imageio_ffmpeg.count_frames_and_secs(str(result.clip))[0] > 24
    with Image.open(result.poster) as poster, Image.open(result.sheet) as sheet:
        assert poster.size == (int(video.group(3)), int(video.group(4))) and sheet.width > poster.width


def test_each_view_is_highway_envs_road_with_the_ego_in_its_colour_grey_traffic_and_its_speed(summary_file):
    import json

    summary = json.loads(summary_file.read_text())
    renderer = GymClipRenderer(summary, [6, 1])  # Car 6's sky blue was highway-env's own traffic blue
    lay = renderer.layout
    assert lay.columns == 1 and lay.panel == lay.width  # wide road views: one above the other, the clip's width
    image = np.asarray(renderer.draw(renderer.frames[0]))
    for slot, k in enumerate(renderer.order):
        x0, y0 = lay.origin(slot)
        view = image[y0 : y0 + lay.view_height, x0 : x0 + lay.panel].astype(int)
        assert view.std() > 10  # a drawn road, not a blank surface
        own = np.array(agent_style(renderer.numbers[k])[0])
        ego = near(view, own)
        rows, columns = np.nonzero(ego)
        assert ego.sum() > 20 and abs(columns.mean() / lay.panel - EGO_AT) < 0.05
        phone = (360 - 32) / lay.width  # the clip as a 360-px phone shows it, the page's margins aside
        assert (columns.max() - columns.min() + 1) * phone >= 30  # a car long enough to follow on a phone
        assert near(view, TRAFFIC).sum() > 200  # the traffic, in grey
        assert not any(near(view, colour).any() for colour in AGENT_COLOURS if tuple(colour) != tuple(own))
    assert {"Car 1", "Car 6"} <= renderer.texts and any(t.startswith("Time") for t in renderer.texts)
    # each car's mean speed so far, never negative: the meta-actions cannot stop or reverse
    assert any(re.fullmatch(r"\d+ km/h mean speed", t) for t in renderer.texts)
    assert not any("-" in t for t in renderer.texts if "km/h" in t)
    end = np.asarray(renderer.draw(renderer.frames[-1]))
    events = {o["event"] for o in summary["outcomes"]}
    words = {"success": "drove through", "collision": "CRASHED", "timeout": "out of time"}
    assert all(any(t.startswith(words[e]) for t in renderer.texts) for e in events)
    assert end.shape == image.shape
    assert not any(agent in text for agent in DRIVERS for text in renderer.texts)  # never the real names


def test_a_crashed_car_shows_its_colour_through_the_crash_burst(summary_file):
    """The burst is drawn over highway-env's picture of the car that crashed: open in the middle, so the car's own
    colour (Car 6's orange, close to the burst's yellow) still fills the place it crashed."""
    import json

    summary = json.loads(summary_file.read_text())
    renderer = GymClipRenderer(summary, [6, 1])
    k = next(k for k, outcome in enumerate(summary["outcomes"]) if outcome["event"] == "collision")
    start = renderer.event_starts[summary["outcomes"][k]["time"]]
    image = np.asarray(renderer.draw(next(f for f in renderer.frames if f.video >= start))).astype(int)
    lay, half = renderer.layout, renderer.sprites.crash[1]
    x0, y0 = lay.origin(renderer.order.index(k))
    point = renderer.scene.crash_points[k]
    x, y = round(x0 + point[0] * lay.panel), round(y0 + point[1] * lay.view_height)
    r = half // 4  # the burst's middle: a quarter of its radius around the place the car crashed
    rows, columns = np.ogrid[-r : r + 1, -r : r + 1]
    middle = near(image[y - r : y + r + 1, x - r : x + r + 1], agent_style(renderer.numbers[k])[0])
    assert middle[rows**2 + columns**2 <= r * r].mean() > 0.9


def near(view: np.ndarray, colour) -> np.ndarray:
    """Where a view's pixels are (nearly) ``colour``."""
    return np.abs(view - np.array(colour)).sum(axis=2) < 30
