"""Clips of a highway summary: each agent's instance drawn by highway-env's own offscreen renderer, side by side,
with Foil's clock, robot labels, colours and status panel drawn on.

The summary is replayed with rendering environments (same dynamics: only the screen settings differ); the ego
car wears its robot's colour, and every simulation step of highway-env (5 per simulated second) is captured
through its video-recording hook, so the motion updates 5 times a simulated second. A car whose episode ended
stays where it ended. The encoding (H.264, poster, contact sheet) is the crowd clips' own.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from app.formats import load_summary
from search.clips.render import (
    BACKGROUND,
    INK,
    MUTED,
    PHONE_WIDTH,
    ClipRenderer,
    Frame,
    RenderOptions,
    RenderResult,
    Sprites,
    _paste,
    _round16,
    encode,
    robot_label,
    robot_style,
)
from search.gym.agents import load_agent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.gym.summary import replay
from search.highway.adapter import HighwayAdapter
from search.solvers.reward import RewardConfig

PANEL_ASPECT = 0.45  # height / width of one road view
EGO_AT = (0.3, 0.5)  # where highway-env keeps the ego in its view (its centering_position)
WORDS = {"success": "drove through", "collision": "CRASHED", "timeout": "out of time", "running": "on its way"}


@dataclass(frozen=True)
class HighwayLayout:
    """A header with the clock, one road view per agent side by side, the status panel below."""

    panels: int
    panel: int  # px width of one view
    view_height: int
    header: int
    legend: int
    width: int
    height: int
    text: int

    @classmethod
    def make(cls, panels: int, options: RenderOptions) -> HighwayLayout:
        width = options.width or 960
        panel = (width // panels) // 16 * 16
        width = panel * panels
        text = math.ceil(13 * width / PHONE_WIDTH)
        header = round(text * 2.0)
        view = _round16(panel * PANEL_ASPECT)
        legend = round(text * 3.9)
        total = header + view + legend
        legend += _round16(total) - total
        return cls(panels, panel, view, header, legend, width, _round16(total), text)


class HighwayScene:
    """What a highway clip shows: per agent its captured views, its outcome, and the clip's length."""

    def __init__(
        self, views: list[list[np.ndarray]], outcomes: list[tuple[str, float]], end_time: float, frames_per_s: float
    ):
        self.views, self.outcomes, self.end_time, self.frames_per_s = views, outcomes, end_time, frames_per_s
        self.n_agents = len(views)

    def event_times(self) -> list[float]:
        return sorted({when for event, when in self.outcomes if event != "running"})

    def view(self, k: int, t: float) -> np.ndarray:
        frames = self.views[k]
        return frames[min(int(math.floor(t * self.frames_per_s + 1e-9)), len(frames) - 1)]


class _Capture:
    """highway-env's video-recording hook: it asks for a frame after every intermediate simulation step."""

    frames_per_sec = 0

    def __init__(self, env, frames: list):
        self.env, self.frames = env, frames

    def _capture_frame(self) -> None:
        self.frames.append(self.env.render())


def load_highway_scene(summary: dict, numbers: list[int], layout: HighwayLayout) -> HighwayScene:
    """Replay a highway summary with rendering environments and capture every simulation step of each agent."""
    scenario = GymScenario.from_dict(summary["scenario"])
    screen = {
        "screen_width": layout.panel,
        "screen_height": layout.view_height,
        "centering_position": list(EGO_AT),
        "scaling": 9.0 * layout.panel / 480,
    }  # px per metre: about 53 m of road in view
    adapter = HighwayAdapter(scenario.settings | screen)
    agents = [load_agent(entry["name"], adapter) for entry in summary["agents"]]
    problem = GymCoupledProblem(
        agents, scenario, RewardConfig.from_dict(summary["reward_parameters"]), adapter, render=True
    )
    views: list[list[np.ndarray]] = [[] for _ in agents]

    def capture(p: GymCoupledProblem) -> None:
        for k, instance in enumerate(p.rows[0]):
            env = instance.env.unwrapped
            if not views[k]:  # just reset: colour the ego, hook the capture, draw the start
                env.vehicle.color = robot_style(numbers[k])[0]
                env.set_record_video_wrapper(_Capture(instance.env, views[k]))
                views[k].append(instance.env.render())
            elif instance.event_step in (0, int(p.t[0])):  # it moved on this step: draw where it ended up
                views[k].append(instance.env.render())

    env_actions = np.array(summary["env_actions"], dtype=np.float64).reshape(-1, *adapter.env_action_shape)
    replay(problem, env_actions, capture)
    config = problem.rows[0][0].env.unwrapped.config
    outcomes = [(o["event"], float(o["time"]) if o["time"] is not None else math.inf) for o in summary["outcomes"]]
    end = float(summary["steps"][-1]["t"])
    return HighwayScene(views, outcomes, end, config["simulation_frequency"] / adapter.dt)


class HighwayClipRenderer(ClipRenderer):
    """Foil's timeline, clock and status panel around highway-env's views (the crowd renderer's schedule,
    header and tags reused)."""

    def __init__(self, summary: dict, numbers: list[int] | None = None, options: RenderOptions | None = None):
        agents = len(summary["agents"])
        self.options = options or RenderOptions()
        self.numbers = list(numbers) if numbers is not None else list(range(1, agents + 1))
        if len(self.numbers) != agents or len({robot_style(n) for n in self.numbers}) != agents:
            raise ValueError(f"give one robot number per agent, each with its own colour; got {self.numbers}")
        self.layout = HighwayLayout.make(agents, self.options)
        self.order = sorted(range(agents), key=lambda k: self.numbers[k])
        self.scene = load_highway_scene(summary, self.numbers, self.layout)
        self.sprites = Sprites(self.numbers, 0, 1.0, self.layout.text * 0.6, self.layout.text)
        self.texts: set[str] = set()
        self.frames, self.event_starts = self._schedule()

    def draw(self, frame: Frame) -> Image.Image:
        lay, t = self.layout, frame.time
        image = Image.new("RGB", (lay.width, lay.height), BACKGROUND)
        for slot, k in enumerate(self.order):
            x0 = slot * lay.panel
            image.paste(Image.fromarray(self.scene.view(k, t)).resize((lay.panel, lay.view_height)), (x0, lay.header))
            event, when = self.scene.outcomes[k]
            happened = event != "running" and when <= t + 1e-9
            if happened and event == "collision":
                ego = (x0 + EGO_AT[0] * lay.panel, lay.header + EGO_AT[1] * lay.view_height)
                _paste(image, self.sprites.crash, ego)
            self._draw_status(image, k, x0, event if happened or t >= self.scene.end_time else "", when)
        self._draw_header(image, t)
        return image

    def _draw_status(self, image: Image.Image, k: int, x0: float, event: str, when: float) -> None:
        lay = self.layout
        y = lay.header + lay.view_height + lay.text * 1.2
        icon = self.sprites.icons[self.numbers[k]]
        _paste(image, icon, (x0 + lay.text * 0.6 + icon[1], y))
        self._text(image, (x0 + lay.text * 2.4, y), robot_label(self.numbers[k]), lay.text, INK, "lm", bold=True)
        text = WORDS[event or "running"] + (f" · {when:.0f} s" if event in ("success", "collision") else "")
        xy = (x0 + lay.text * 2.4, y + lay.text * 1.5)
        if event == "collision":
            self._tag(image, xy, text, lay.text, "lm")
        else:
            self._text(image, xy, text, lay.text, INK if event else MUTED, "lm")


def render_highway(
    summary_path: str | os.PathLike,
    out: str | os.PathLike,
    numbers: list[int] | None = None,
    options: RenderOptions | None = None,
) -> RenderResult:
    """`foil render` for a highway summary: the clip, its poster and its contact sheet."""
    started = time.perf_counter()
    return encode(HighwayClipRenderer(load_summary(summary_path), numbers, options), Path(out), started)
