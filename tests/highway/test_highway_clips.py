"""Highway clips: highway-env's own offscreen views side by side with Foil's labels, colours, clock and status."""

from __future__ import annotations

import re

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from search.cli import main
from search.clips.render import robot_style
from search.gym.summary import run_gym_search
from search.highway.clips import EGO_AT, HighwayClipRenderer, HighwayLayout
from search.highway.scenarios import SCENARIOS
from search.solvers.runner import SearchJob, write_outputs
from tests.render.test_render import probe, top_level_boxes

DRIVERS = ("tests.highway.drivers:cruise", "tests.highway.drivers:cautious")


@pytest.fixture(scope="module")
def summary_file(tmp_path_factory):
    job = SearchJob(
        agents=DRIVERS, scenario="highway-dense", solver="random", budget=20, top_k=1, solver_settings={"batch": 1}
    )
    out = write_outputs(tmp_path_factory.mktemp("search"), run_gym_search(job, SCENARIOS["highway-dense"]))
    return out / "summary-001.json"


def test_foil_render_writes_browser_safe_h264_with_poster_and_contact_sheet(tmp_path, summary_file, capsys):
    clip = tmp_path / "clip.mp4"
    assert main(["render", str(summary_file), "--out", str(clip), "--numbers", "2,1", "--speed", "4"]) == 0
    assert "frames" in capsys.readouterr().out
    info = probe(clip)
    video = re.search(r"Video: (\w+).*?, (\w+)(?:\(.*?\))?, (\d+)x(\d+)", info)
    assert video and (video.group(1), video.group(2)) == ("h264", "yuv420p"), info
    assert int(video.group(3)) % 16 == 0 and int(video.group(4)) % 16 == 0
    boxes = top_level_boxes(clip)
    assert boxes.index("moov") < boxes.index("mdat")
    assert imageio_ffmpeg.count_frames_and_secs(str(clip))[0] > 24
    with Image.open(tmp_path / "clip.poster.png") as poster, Image.open(tmp_path / "clip.sheet.png") as sheet:
        assert poster.size == (int(video.group(3)), int(video.group(4))) and sheet.width > poster.width


def test_each_view_is_highway_envs_drawing_with_the_ego_in_its_robots_colour(summary_file):
    import json

    summary = json.loads(summary_file.read_text())
    renderer = HighwayClipRenderer(summary, [2, 1])
    lay = renderer.layout
    assert isinstance(lay, HighwayLayout) and lay.panels == 2
    image = np.asarray(renderer.draw(renderer.frames[0]))
    for slot, k in enumerate(renderer.order):
        view = image[lay.header : lay.header + lay.view_height, slot * lay.panel : (slot + 1) * lay.panel]
        assert view.std() > 10  # a drawn road, not a blank surface
        colour = np.array(robot_style(renderer.numbers[k])[0])
        near_ego = view[
            int(EGO_AT[1] * lay.view_height) - 12 : int(EGO_AT[1] * lay.view_height) + 12,
            int(EGO_AT[0] * lay.panel) - 30 : int(EGO_AT[0] * lay.panel) + 30,
        ]
        assert (np.abs(near_ego.astype(int) - colour).sum(axis=2) < 30).sum() > 20
    assert {"Robot 1", "Robot 2"} <= renderer.texts and any(t.startswith("Time") for t in renderer.texts)
    end = np.asarray(renderer.draw(renderer.frames[-1]))
    events = {o["event"] for o in summary["outcomes"]}
    words = {"success": "drove through", "collision": "CRASHED", "timeout": "out of time"}
    assert all(any(t.startswith(words[e]) for t in renderer.texts) for e in events)
    assert end.shape == image.shape
    assert not any(agent in text for agent in DRIVERS for text in renderer.texts)  # never the real names
