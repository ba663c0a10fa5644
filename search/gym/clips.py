"""Clips of any Gymnasium summary: each agent's instance drawn by its environment's own ``render()``, with Foil's
clock, robot labels, colours and status panel, encoded as the crowd clips are (H.264, poster, contact sheet).

The summary is replayed with rendering environments (the scenario's settings with the adapter's
``view_settings`` over them: only the screen differs, so the replay is exact). A view is the environment's frame
scaled to the view's width, never squeezed; the views sit side by side, or one above the other where that shows
them larger (wide views such as a road's), and each has its robot's label, status and caption beneath it. A view
whose episode ended stays where it ended. A crash shows a burst for a moment, then a small mark, so the rest of
that view stays readable; both are open in the middle, so the agent the environment drew under them still shows.
The adapter's hooks (search/gym/adapter.py) say what this renderer cannot know; an adapter that names its own
``renderer`` gets that instead.

A summary's ``window`` and ``follow`` (docs/clips.md) are honoured as the crowd renderer honours them: the replay
follows the leader as the search did (``problem.override``), the clip shows the window's states with the run's
clock, a leader followed throughout is shown alone, and the moment the agents part is captioned in the adapter's
words (an optional ``parting_caption`` hook) with a ring where its ``crash_point`` puts the agent.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from app.formats import load_summary
from search.clips.render import (
    BACKGROUND,
    INK,
    MIN_PHONE_TEXT,
    MUTED,
    PHONE_WIDTH,
    AgentSprites,
    ClipRenderer,
    Frame,
    RenderOptions,
    RenderResult,
    agent_label,
    agent_numbers,
    agent_style,
    encode,
    fit_text,
    paint_open_burst,
    paste,
    round16,
    sprite,
    text_width,
)
from search.clips.windows import follow_of, window_of
from search.gym.adapter import Adapter, import_attribute, load_adapter
from search.gym.agents import load_agent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.gym.summary import replay
from search.solvers.follow import Follow
from search.solvers.reward import RewardConfig

SCREEN = (16, 10)  # the screen shape a clip is fitted into when choosing how to arrange its views
BURST_SECONDS = 1.5  # of video a crash's burst shows before the small mark replaces it
PARTING_CAPTION = "Here the {count} agents would act differently"  # unless the adapter has a parting_caption


@dataclass(frozen=True)
class GymLayout:
    """A header with the clock, then per agent its view and a status band below it, in ``columns`` columns."""

    columns: int
    panel: int  # px width of one view
    view_height: int
    header: int
    band: int
    width: int
    height: int
    text: int

    @classmethod
    def make(cls, agents: int, view_shape: tuple[int, int], options: RenderOptions) -> GymLayout:
        """The arrangement that shows each view largest on a SCREEN-shaped display; ties go to more columns."""
        layouts = [cls._arranged(agents, columns, view_shape, options) for columns in range(1, agents + 1)]
        return max(layouts, key=lambda lay: (round(lay.shown(), 6), lay.columns))

    @classmethod
    def _arranged(cls, agents: int, columns: int, view_shape: tuple[int, int], options: RenderOptions) -> GymLayout:
        width = options.width or 960
        panel = (width // columns) // 16 * 16
        width = panel * columns
        text = math.ceil(MIN_PHONE_TEXT * width / PHONE_WIDTH)
        view = round(panel * view_shape[0] / view_shape[1])  # the environment's own aspect
        band = round(text * (1.9 if columns == 1 else 3.9))  # one status line under a full-width view, else two
        total = round(text * 2.0) + math.ceil(agents / columns) * (view + band)
        return cls(columns, panel, view, round(text * 2.0), band, width, round16(total), text)

    def shown(self) -> float:
        """A view's width, as a fraction of the screen's, when the clip is fitted into a SCREEN-shaped display."""
        return self.panel * min(SCREEN[0] / self.width, SCREEN[1] / self.height) / SCREEN[0]

    def origin(self, slot: int) -> tuple[int, int]:
        """Top-left corner of the view in on-screen slot ``slot``."""
        row, column = divmod(slot, self.columns)
        return column * self.panel, self.header + row * (self.view_height + self.band)


class GymScene:
    """What a clip shows of each agent: its captured views and captions, its outcome and where a crash mark goes."""

    def __init__(
        self,
        views: list[list[np.ndarray]],
        captions: list[list[str]],
        outcomes: list[tuple[str, float]],
        crash_points: list[tuple[float, float] | None],
        end_time: float,
        frames_per_step: int,
        dt: float,
        shown: tuple[int, ...] | None = None,
        parting: float | None = None,
        parting_points: list[tuple[float, float] | None] | None = None,
        clock: float = 0.0,
    ):
        self.views, self.captions, self.outcomes, self.crash_points = views, captions, outcomes, crash_points
        self.end_time, self.frames_per_step, self.dt = end_time, frames_per_step, dt
        self.n_agents = len(views)
        self.shown = shown  # as the crowd's Scene: the agents drawn (None: all; a leader followed throughout alone)
        self.parting = parting  # when agents that followed a leader part (a disagreement clip), else None
        self.parting_points = parting_points or [None] * self.n_agents  # where each agent is then, as crash_point
        self.clock = clock  # the run's seconds before the first state shown (a window's start): what the clock adds

    def event_times(self) -> list[float]:
        return sorted({when for event, when in self.outcomes if event != "running"})

    def _at(self, items: list, t: float, per_step: int):
        return items[min(int(math.floor(t / self.dt * per_step + 1e-9)), len(items) - 1)]

    def view(self, k: int, t: float) -> np.ndarray:
        return self._at(self.views[k], t, self.frames_per_step)

    def caption(self, k: int, t: float) -> str:
        return self._at(self.captions[k], t, 1)


def frame(env: Any) -> np.ndarray:
    """A copy of the environment's RGB frame (an environment may reuse its buffer), or a clear error for one that
    draws none."""
    try:
        image = env.render()
    except NotImplementedError:
        image = None
    if image is None or np.asarray(image).ndim != 3:
        raise ValueError(
            f"{type(env.unwrapped).__name__} draws no RGB frame: a clip needs the adapter's make(render=True) to "
            "give an environment whose render() returns an RGB array (render_mode='rgb_array'), or an adapter "
            "renderer of its own (docs/gym.md)"
        )
    return np.array(image)


def load_gym_scene(summary: dict, numbers: list[int], width: int) -> tuple[GymScene, Adapter]:
    """Replay a summary with rendering environments (views at most ``width`` px wide), capturing each agent's
    frames and captions until its episode ends; then keep its window."""
    steps = len(summary["steps"])
    first, last = window_of(summary, steps)
    follow = follow_of(summary, len(summary["agents"]))
    parting_step = follow[1] if follow is not None and first <= follow[1] <= last and follow[1] < steps else None
    scenario = GymScenario.from_dict(summary["scenario"])
    adapter = load_adapter(scenario.adapter, scenario.settings | scenario.load_adapter().view_settings(width))
    agents = [load_agent(entry["name"], adapter) for entry in summary["agents"]]
    problem = GymCoupledProblem(
        agents, scenario, RewardConfig.from_dict(summary["reward_parameters"]), adapter, render=True
    )
    colours = [agent_style(n)[0] for n in numbers]
    views: list[list[np.ndarray]] = [[] for _ in agents]
    captions: list[list[str]] = [[] for _ in agents]
    measured: list[list[float]] = [[] for _ in agents]  # each state's visible score, where the adapter has one
    parting_points: list[tuple[float, float] | None] = [None] * len(agents)
    frames_per_step = 1

    def capture(p: GymCoupledProblem) -> None:
        nonlocal frames_per_step
        for k, instance in enumerate(p.rows[0]):
            env: Any = instance.env
            if not views[k]:  # just reset
                frames_per_step = adapter.record(env, lambda env=env, k=k: views[k].append(frame(env)))
            elif instance.event_step not in (0, int(p.t[0])):  # ended earlier: its view stays where it ended
                continue
            adapter.mark_agent(env, colours[k])
            views[k].append(frame(env))
            captions[k].append(adapter.caption(env))
            if adapter.score is not None:
                measured[k].append(float(adapter.measure(env)))
        if int(p.t[0]) == parting_step:
            parting_points[:] = [adapter.crash_point(instance.env) for instance in p.rows[0]]

    problem.override = Follow.of_summary(summary)  # the agents follow a leader as they did in the search
    env_actions = np.array(summary["env_actions"], dtype=np.float64).reshape(-1, *adapter.env_action_shape)
    replay(problem, env_actions, capture)
    outcomes = [(o["event"], float(o["time"]) if o["time"] is not None else math.inf) for o in summary["outcomes"]]
    crash_points = [adapter.crash_point(instance.env) for instance in problem.rows[0]]

    def time_of(state: int) -> float:
        return float(summary["steps"][state - 1]["t"]) if state else 0.0

    t0, t1 = time_of(first), time_of(last)
    if summary.get("window") is not None:  # its states, timed from its first; an outcome after it is running
        views = [_part(frames, first * frames_per_step, last * frames_per_step) for frames in views]
        captions = [_part(texts, first, last) for texts in captions]
        measured = [_part(values, first, last) for values in measured]
        outcomes = [
            ("running", math.inf) if e == "running" or w > t1 + 1e-6 else (e, max(w - t0, 0.0)) for e, w in outcomes
        ]
    shown = (follow[0],) if follow is not None and follow[1] >= steps else None  # followed throughout: alone
    if adapter.score is not None:  # a leader alone is a reel's moment (HIGHLIGHTS), whose sum starts with it
        moment = shown is not None
        captions = [scored(adapter, texts, values, moment) for texts, values in zip(captions, measured, strict=True)]
    scene = GymScene(
        views,
        captions,
        outcomes,
        crash_points,
        t1 - t0,
        frames_per_step,
        adapter.dt,
        shown=shown,
        parting=None if parting_step is None else time_of(parting_step) - t0,
        parting_points=parting_points,
        clock=t0,
    )
    return scene, adapter


def scored(adapter: Adapter, captions: list[str], measured: list[float], moment: bool) -> list[str]:
    """Each state's caption with the visible score after it (`app.visible.Score.caption`): its value, and for a mean
    or a band what the clip summed so far, from its first state shown (in a reel's ``moment``, said to be the
    moment's); a view that stopped keeps its last caption, as its last frame."""
    assert adapter.score is not None
    score, dt = adapter.score, adapter.dt
    texts = [score.caption(now, measured[1 : i + 1], dt, moment) for i, now in enumerate(measured)]
    return [" · ".join(filter(None, (caption, text))) for caption, text in zip(captions, texts, strict=True)]


def _part(items: list, first: int, last: int) -> list:
    """Items first..last of a capture; one that ended before ``first`` keeps its last item (it stays there)."""
    return items[min(first, len(items) - 1) : last + 1]


class GymClipRenderer(ClipRenderer):
    """Foil's timeline, clock and status panel (the clip toolkit's) around the environment's views."""

    scene: GymScene
    layout: GymLayout

    def __init__(self, summary: dict, numbers: list[int] | None = None, options: RenderOptions | None = None):
        agents = len(summary["agents"])
        self.options = options or RenderOptions()
        self.numbers = agent_numbers(numbers, agents)
        self.scene, self.adapter = load_gym_scene(summary, self.numbers, self.options.width or 960)
        shown = self.scene.shown if self.scene.shown is not None else range(agents)
        self.order = sorted(shown, key=lambda k: self.numbers[k])
        self.layout = GymLayout.make(len(self.order), self.scene.views[0][0].shape[:2], self.options)
        text = self.layout.text
        # a crash's burst and the mark that stays once it is over, drawn over the environment's picture of the
        # agent: open in the middle, so the agent under them still shows
        self.sprites = AgentSprites(self.numbers, text * 0.6, text, burst=paint_open_burst)
        self.crash_mark = sprite(text * 0.45, 1.0, paint_open_burst)
        self.digits = 0 if float(self.adapter.dt).is_integer() else 1  # of an event's time
        self.texts: set[str] = set()
        self._views: dict[int, tuple[int, Image.Image]] = {}  # per agent, its last scaled view
        self.frames, self.event_starts = self.schedule()
        self.parting_video = self.parting_second()

    def draw(self, frame: Frame) -> Image.Image:
        lay, t = self.layout, frame.time
        image = Image.new("RGB", (lay.width, lay.height), BACKGROUND)
        for slot, k in enumerate(self.order):
            x0, y0 = lay.origin(slot)
            image.paste(self._view(k, t), (x0, y0))
            if x0:  # a thin gap, so neighbouring views never read as one
                ImageDraw.Draw(image).rectangle((x0, y0, x0 + 1, y0 + lay.view_height), fill=BACKGROUND)
            event, when = self.scene.outcomes[k]
            happened = event != "running" and when <= t + 1e-9
            point = self.scene.crash_points[k]
            if happened and event == "collision" and point is not None:
                sprite = self.sprites.crash if self._bursting(when, frame) else self.crash_mark
                paste(image, sprite, self._in_view((x0, y0), point, sprite[1]))
            at = self.scene.parting_points[k]
            if at is not None and self.parting_shown(frame):
                self.draw_ring(image, self._in_view((x0, y0), at, lay.text * 1.1), lay.text * 1.1)
            shown = event if happened or t >= self.scene.end_time else ""
            self._draw_status(image, k, (x0, y0 + lay.view_height), shown, when, t)
        self.draw_header(image, t + self.scene.clock)
        if self.parting_shown(frame):
            self.draw_parting_caption(image, getattr(self.adapter, "parting_caption", PARTING_CAPTION))
        return image

    def _in_view(self, corner: tuple[int, int], point: tuple[float, float], half: float) -> tuple[float, float]:
        """The pixel of a point given as shares of a view, moved in so that a mark ``half`` px around it stays in
        the view: an agent that left the view (a car off the road) is marked at the view's edge, never in the
        status band beside it."""
        lay = self.layout
        x = min(max(point[0] * lay.panel, half), lay.panel - half)
        y = min(max(point[1] * lay.view_height, half), lay.view_height - half)
        return corner[0] + x, corner[1] + y

    def _view(self, k: int, t: float) -> Image.Image:
        """Agent k's view at time t, scaled to the layout (kept per agent: a view changes a few times a second)."""
        frame = self.scene.view(k, t)
        cached = self._views.get(k)
        if cached is None or cached[0] != id(frame):
            image = Image.fromarray(frame)
            size = (self.layout.panel, self.layout.view_height)
            cached = (id(frame), image if image.size == size else image.resize(size, Image.Resampling.LANCZOS))
            self._views[k] = cached
        return cached[1]

    def _bursting(self, when: float, frame: Frame) -> bool:
        """Whether a crash at ``when`` still shows its burst: for BURST_SECONDS of video from its pause (in a still,
        as long after it in simulated time)."""
        since = self.since(when, frame)
        return (since if math.isfinite(since) else frame.time - when) < BURST_SECONDS

    def _draw_status(self, image: Image.Image, k: int, corner: tuple[int, int], event: str, when: float, t: float):
        """Under a view: the agent's icon and label, then how it is doing (beside the label under a full-width view,
        else on a second line), and its caption at the right of whichever line leaves it more room. The status fits
        between its start and the view's right margin, the caption in what is left of its line (`fit_text`)."""
        lay = self.layout
        x0, y = corner[0], corner[1] + lay.text * 0.95
        right, gap = x0 + lay.panel - lay.text * 0.6, lay.text * 0.8
        icon = self.sprites.icons[self.numbers[k]]
        paste(image, icon, (x0 + lay.text * 0.6 + icon[1], y))
        label = self.draw_text(
            image,
            (x0 + lay.text * 2.4, y),
            agent_label(self.adapter.words.agent, self.numbers[k]),
            lay.text,
            INK,
            "lm",
            True,
        )
        status = self.adapter.status_words[event or "running"]
        if event in ("success", "collision"):
            status += f" · {when + self.scene.clock:.{self.digits}f} s"
        xy = (label[2] + gap, y) if lay.columns == 1 else (x0 + lay.text * 2.4, y + lay.text * 1.5)
        tagged, caption = event == "collision", self.scene.caption(k, t)
        pad = lay.text * 0.25 if tagged else 0.0  # of a tag's box beyond its text
        room = right - xy[0] - pad
        if lay.columns == 1 and caption:  # the status and the caption share the line: each keeps half of it
            room = max(room / 2, room - text_width(caption, lay.text) - gap)
        status, size = fit_text(status, lay.text, room, tagged)
        if caption:  # after the status, or under a view of a column after the label where that leaves more room
            lines = [(xy[0] + text_width(status, size, tagged) + pad, xy[1])]
            after, line = min(lines + ([(label[2], y)] if lay.columns > 1 else []))
            caption, caption_size = fit_text(caption, lay.text, right - after - gap)
            if caption:
                self.draw_text(image, (right, line), caption, caption_size, INK, "rm")
        if tagged:
            self.draw_tag(image, xy, status, size, "lm")
        else:
            self.draw_text(image, xy, status, size, INK if event else MUTED, "lm")


def render_gym(
    summary_path: str | os.PathLike,
    out: str | os.PathLike,
    numbers: list[int] | None = None,
    options: RenderOptions | None = None,
) -> RenderResult:
    """`foil render` for any Gymnasium summary: the clip, its poster and its contact sheet, by the adapter's own
    renderer where it names one."""
    started = time.perf_counter()
    summary: dict[str, Any] = dict(load_summary(Path(summary_path)))
    own = GymScenario.from_dict(summary["scenario"]).load_adapter().renderer
    if own:
        return import_attribute(own, "renderer")(summary_path, out, numbers, options)
    return encode(GymClipRenderer(summary, numbers, options), Path(out), started)
