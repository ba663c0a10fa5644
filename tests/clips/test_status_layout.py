"""The text under a clip's views, measured as drawn (each text's box): an agent's caption never lies over its label
or its status, and no status or caption runs past its view's edges, at every width a study renders clips at (the
defaults, 720 and 960 px, a phone's 360 and the narrower and wider widths `[build.render]` allows), for the
Gymnasium renderer with long words and for the crowd's legend."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.clips.render import FIT_SHRINK, INK, RenderOptions, agent_label
from search.crowd.render import CrowdClipRenderer, robot_label
from search.crowd.scene import scene_from_summary
from search.crowd.sim.scenarios import load_scenario
from search.gym.clips import GymClipRenderer
from tests.gym.test_gym_clips import Track, TrackAdapter, summary_file  # noqa: F401  (the fixture)
from tests.support.summaries import summary_from_simulation, visible

WIDTHS = [None, 320, 360, 480, 720, 960, 1280]


class Measured:
    """A renderer that keeps the box of every text it draws in the frame it draws last."""

    boxes: list[tuple[str, int, tuple[float, float, float, float]]]

    def __init__(self, *args):
        self.boxes = []  # the crowd's renderer draws the start and goal labels once, before any frame
        super().__init__(*args)  # type: ignore[call-arg]

    def draw(self, frame):
        self.boxes = []
        return super().draw(frame)  # type: ignore[misc]

    def draw_text(self, image, xy, text, size, fill=INK, anchor="la", bold=False):
        box = super().draw_text(image, xy, text, size, fill, anchor, bold)  # type: ignore[misc]
        self.boxes.append((text, size, box))
        return box


class MeasuredGym(Measured, GymClipRenderer):
    pass


class MeasuredCrowd(Measured, CrowdClipRenderer):
    pass


class LongWordsAdapter(TrackAdapter):
    """Statuses and a caption longer than a narrow view holds."""

    status_words = {
        "success": "reached the far end of its track",
        "collision": "ran into the moving wall and failed",
        "timeout": "ran out of time before reaching the wall",
        "running": "still running along its track",
    }

    def caption(self, env):
        return f"wall {env.unwrapped.wall:.2f} m away after {env.unwrapped.steps} steps"


class WideTrack(Track):
    """The track drawn 300 px wide and 30 px tall: its views stack, one full-width view above the other."""

    def render(self):
        return np.repeat(np.repeat(super().render()[::4, ::4], 10, axis=1), 3, axis=0)[:30, :300]


class WideLongWordsAdapter(LongWordsAdapter):
    def make(self, render=False):
        return WideTrack(render_mode="rgb_array" if render else None)


def overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


@pytest.mark.parametrize("adapter", ["LongWordsAdapter", "WideLongWordsAdapter"])
@pytest.mark.parametrize("width", WIDTHS)
def test_a_gym_status_and_caption_keep_off_the_label_and_inside_the_view(summary_file, adapter, width):  # noqa: F811
    summary = json.loads(summary_file.read_text())
    summary["scenario"]["adapter"] = f"tests.clips.test_status_layout:{adapter}"
    renderer = MeasuredGym(summary, [3, 1], RenderOptions(width=width))
    lay = renderer.layout
    assert lay.columns == (2 if adapter == "LongWordsAdapter" else 1)
    for frame in (renderer.frames[len(renderer.frames) // 2], renderer.frames[-1]):
        renderer.draw(frame)
        for slot, k in enumerate(renderer.order):
            x0, y0 = lay.origin(slot)
            top = y0 + lay.view_height  # the view's status band
            band = [entry for entry in renderer.boxes if top <= entry[2][1] < top + lay.band]
            mine = [(text, size, box) for text, size, box in band if x0 <= box[0] < x0 + lay.panel]
            name = agent_label(renderer.adapter.words.agent, renderer.numbers[k])
            label = next(box for text, _, box in mine if text == name)
            others = [(text, size, box) for text, size, box in mine if box != label]
            assert len(others) == 2, others  # the status and the caption
            for text, size, box in others:
                assert x0 <= box[0] and box[2] + size * 0.25 <= x0 + lay.panel, (text, box, x0, lay.panel)
                assert not overlap(box, label), (text, box, label)
                assert size >= lay.text * FIT_SHRINK
            assert not overlap(others[0][2], others[1][2]), others


def test_a_text_that_fits_keeps_its_size_and_words(summary_file):  # noqa: F811
    """At the study's default width the track's own words fit: drawn whole, at the legend's size."""
    renderer = MeasuredGym(json.loads(summary_file.read_text()), [3, 1], RenderOptions())
    renderer.draw(renderer.frames[-1])
    assert {size for _, size, _ in renderer.boxes} == {renderer.layout.text}
    assert not any(text.endswith("…") for text, _, _ in renderer.boxes)


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("robots_visible", [False, True])
def test_a_crowd_status_stays_in_its_panel_and_off_the_robots_name(width, robots_visible):
    """Both robots still on their way when the clip (a window of the run) ends: the longest status, with how far
    each is from its goal."""
    scenario = load_scenario("paper-bl-tr")
    summary = summary_from_simulation(["goal", "orca"], visible(scenario) if robots_visible else scenario)
    scene = scene_from_summary(summary | {"window": [1, 4]})
    renderer = MeasuredCrowd(scene, [7, 12], RenderOptions(width=width))
    lay = renderer.layout
    assert lay.panels == (2 if robots_visible else 1)
    renderer.draw(renderer.frames[-1])
    legend = [entry for entry in renderer.boxes if entry[2][1] >= lay.header + lay.panel]
    labels = {text: box for text, _, box in legend if text in (robot_label(7), robot_label(12))}
    statuses = [(text, size, box) for text, size, box in legend if text.startswith("still on its way")]
    assert len(labels) == len(statuses) == 2, legend
    for text, size, box in statuses:
        panel = int(box[0] // lay.panel) * lay.panel if lay.panels > 1 else 0
        assert panel <= box[0] and box[2] <= panel + (lay.panel if lay.panels > 1 else lay.width), (text, box)
        assert not any(overlap(box, label) for label in labels.values()), (text, box, labels)
        assert size >= lay.text * FIT_SHRINK
