"""Clips of a crowd summary: a top-down view of the arena as the paper's Figure 1 draws it, drawn with the clip
toolkit (`search.clips.render`).

Participants judge two robots from a clip in a few seconds, so the picture must be readable at a glance: humans
are grey discs numbered 0-9 with short tails; each robot has its agent colour, shape and number and a fading
trail; markers keep a minimum size on a phone, so in a wide view they are drawn larger than to scale; a collision
is a burst with a tag where it happened and a pause; reaching the goal or running out of time gets a badge and a
line in the legend. The legend sits below the arena and never names the real agent, only "Robot 1", "Robot 2", ...
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
from PIL import Image, ImageDraw

from search.clips.render import (
    ARENA,
    BACKGROUND,
    CRASH_TAG_SECONDS,
    GRID,
    INK,
    MUTED,
    STATUS_RUNNING,
    AgentSprites,
    ClipRenderer,
    Frame,
    Layout,
    RenderOptions,
    RenderResult,
    Sprite,
    agent_label,
    agent_numbers,
    agent_style,
    centered_text,
    encode,
    fit_text,
    paste,
    sprite,
    status_text,
    tag_box,
)
from search.crowd.scene import Scene, load_scene

ROBOT = "Robot"  # the word a participant sees before a robot's number
HUMAN_FILL = (222, 222, 222)
HUMAN_EDGE = (90, 90, 90)
HUMAN_TAIL = (205, 205, 200)
PARTING_CAPTION = "Here the {count} robots would act differently"  # {count}: "two", "three", ...


def robot_label(number: int) -> str:
    """The only name a participant ever sees for a robot."""
    return agent_label(ROBOT, number)


def human_marker(index: int, radius: float) -> Sprite:
    """Human ``index``'s grey disc with its number."""

    def paint(draw, c, ppm):
        r = radius * ppm
        draw.ellipse((c - r, c - r, c + r, c + r), fill=HUMAN_FILL, outline=HUMAN_EDGE, width=max(1, int(r / 8)))
        centered_text(draw, c, str(index), int(r * (1.5 if index < 10 else 1.1)), INK)

    return sprite(radius * 1.05, 1.0, paint)


class Sprites(AgentSprites):
    """Humans, robots and marks pre-rendered once per clip: at the arena's scale, and at legend size."""

    def __init__(self, numbers: list[int], n_humans: int, human: float, robot: float, legend_text: int):
        """``human`` and ``robot``: their markers' radii in px; ``numbers``: the clip's robot numbers."""
        super().__init__(numbers, robot, legend_text)
        self.humans = [human_marker(i, human) for i in range(n_humans)]


def _leader_last(order: list[int], leader: int | None) -> list[int]:
    """A drawing order with the followed leader last, on top of those that move with it."""
    return order if leader is None else [k for k in order if k != leader] + [leader]


def faded(colour, amount: float, base=ARENA) -> tuple[int, int, int]:
    """``colour`` faded towards the arena's (``amount`` 1: the colour itself, 0: the arena)."""
    red, green, blue = (int(round(b + (c - b) * amount)) for c, b in zip(colour, base, strict=True))
    return red, green, blue


class CrowdClipRenderer(ClipRenderer):
    """Draws the frames of one crowd clip. ``numbers[k]`` is the robot number shown for the summary's agent ``k``."""

    scene: Scene
    layout: Layout

    def __init__(self, scene: Scene, numbers: list[int] | None = None, options: RenderOptions | None = None):
        self.scene = scene
        self.options = options or RenderOptions()
        numbers = agent_numbers(numbers, len(scene.agents))  # one per summary agent, drawn or not
        self.numbers = numbers if scene.shown is None else [numbers[k] for k in scene.shown]
        self.layout = Layout.make(scene, self.options)
        self.robot_px = self.layout.marker(scene.robot_radius)
        self.sprites = Sprites(
            self.numbers, scene.n_humans, self.layout.marker(scene.human_radius), self.robot_px, self.layout.text
        )
        # on-screen order: by robot number; panel p shows the agent self.order[p] when each robot has its own crowd
        self.order = sorted(range(scene.n_agents), key=lambda k: self.numbers[k])
        self.stack = _leader_last(self.order[::-1], scene.leader)  # drawing order: the last on top
        self.panel_of = [self.order.index(k) if scene.n_panels > 1 else 0 for k in range(scene.n_agents)]
        self.pixels_robots = np.stack(
            [self.layout.to_pixel(self.panel_of[k], scene.robots[:, k]) for k in range(scene.n_agents)], axis=1
        )  # (T, N, 2)
        crowd_of_panel = self.order if scene.n_panels > 1 else [0]
        self.pixels_humans = np.stack(
            [self.layout.to_pixel(p, scene.humans[:, crowd]) for p, crowd in enumerate(crowd_of_panel)], axis=1
        )  # (T, P, n, 2)
        self.texts = set()
        self.background = self._background()
        self.frames, self.event_starts = self.schedule()
        self.parting_video = self.parting_second()

    def _background(self) -> Image.Image:
        lay, scene = self.layout, self.scene
        image = Image.new("RGB", (lay.width, lay.height), BACKGROUND)
        draw = ImageDraw.Draw(image)
        first = math.ceil(min(lay.origin))
        last = math.floor(max(lay.origin) + lay.span)
        for p in range(lay.panels):
            x0 = p * lay.panel
            draw.rectangle((x0, lay.header, x0 + lay.panel - 1, lay.header + lay.panel - 1), fill=ARENA)
            for metre in range(first, last + 1):
                col, row = lay.to_pixel(p, (metre, metre))
                if x0 <= col < x0 + lay.panel:
                    draw.line([(col, lay.header), (col, lay.header + lay.panel)], fill=GRID, width=1)
                if lay.header <= row < lay.header + lay.panel:
                    draw.line([(x0, row), (x0 + lay.panel, row)], fill=GRID, width=1)
            draw.rectangle((x0, lay.header, x0 + lay.panel - 1, lay.header + lay.panel - 1), outline=MUTED, width=2)
        for k in range(scene.n_agents):
            self._draw_start_goal(image, k)
        self._clip_to_arenas(image, Image.new("RGB", image.size, BACKGROUND))
        self._draw_scale_bar(image)
        return image

    def _clip_to_arenas(self, image: Image.Image, clean: Image.Image) -> None:
        """Whatever a mark near an arena's edge drew over the header or the legend band goes: ``clean``'s bands
        are put back, so a goal never covers the scale bar and a tag never covers a status line."""
        lay = self.layout
        for band in ((0, 0, lay.width, lay.header), (0, lay.header + lay.panel, lay.width, lay.height)):
            image.paste(clean.crop(band), band[:2])

    def _draw_start_goal(self, image: Image.Image, k: int) -> None:
        """Start: a hollow ring; goal: a target. Neutral ink and labelled, so ends that robots share read once."""
        draw = ImageDraw.Draw(image)
        lay = self.layout
        panel = self.panel_of[k]
        r = self.robot_px
        size = max(12, int(lay.text * 0.75))
        width = max(2, int(r / 6))
        sx, sy = lay.to_pixel(panel, self.scene.starts[k])
        draw.ellipse((sx - r * 1.2, sy - r * 1.2, sx + r * 1.2, sy + r * 1.2), outline=MUTED, width=width)
        self.draw_text(image, (sx, sy + r * 1.35), "start", size, fill=MUTED, anchor="mt")
        gx, gy = lay.to_pixel(panel, self.scene.goals[k])
        for ring, fill in ((1.4, INK), (0.9, ARENA), (0.45, INK)):
            draw.ellipse((gx - r * ring, gy - r * ring, gx + r * ring, gy + r * ring), fill=fill)
        self.draw_text(image, (gx, gy + r * 1.6), "goal", size, fill=INK, anchor="mt")

    def _draw_scale_bar(self, image: Image.Image) -> None:
        draw = ImageDraw.Draw(image)
        lay = self.layout
        x1 = lay.width - lay.text * 0.6
        x0 = x1 - lay.scale
        y = lay.header / 2
        draw.line([(x0, y), (x1, y)], fill=INK, width=max(2, lay.text // 8))
        for x in (x0, x1):
            draw.line([(x, y - lay.text * 0.25), (x, y + lay.text * 0.25)], fill=INK, width=max(2, lay.text // 8))
        self.draw_text(image, (x0 - lay.text * 0.4, y), "1 m", lay.text, fill=INK, anchor="rm")

    def _state(self, t: float):
        """Interpolated positions at simulated time t: robots (N, 2) and humans (P, n, 2) in pixels."""
        times = self.scene.times
        i = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2))
        frac = float(np.clip((t - times[i]) / (times[i + 1] - times[i]), 0.0, 1.0))
        robots = self.pixels_robots[i] + frac * (self.pixels_robots[i + 1] - self.pixels_robots[i])
        humans = self.pixels_humans[i] + frac * (self.pixels_humans[i + 1] - self.pixels_humans[i])
        return i, robots, humans

    def _draw_trail(self, draw: ImageDraw.ImageDraw, k: int, i: int, t: float, head) -> None:
        """The path so far, fading with age to a faint floor; runs of equal shade are drawn as one polyline."""
        colour = agent_style(self.numbers[k])[0]
        points = [tuple(p) for p in self.pixels_robots[: i + 1, k]] + [tuple(head)]
        ages = t - np.append(self.scene.times[: i + 1], t)
        shades = np.round((0.25 + 0.75 * np.exp(-ages / self.options.trail_fade)) * 8) / 8
        width = max(3, int(self.robot_px * 0.35))
        start = 0
        for j in range(1, len(points)):
            if j == len(points) - 1 or shades[j] != shades[start]:
                draw.line(points[start : j + 1], fill=faded(colour, float(shades[start])), width=width, joint="curve")
                start = j

    def _draw_human_tails(self, draw: ImageDraw.ImageDraw, i: int, humans) -> None:
        """Short faint tails (the last 2 s) so the direction each person walks is visible in a still."""
        first = max(0, i - round(2.0 / self.scene.dt))
        for p in range(self.scene.n_panels):
            for h in range(self.scene.n_humans):
                run = [tuple(q) for q in self.pixels_humans[first : i + 1, p, h]] + [tuple(humans[p, h])]
                draw.line(run, fill=HUMAN_TAIL, width=max(2, int(self.scene.human_radius * self.layout.scale * 0.4)))

    def _event(self, k: int, t: float):
        """The agent's outcome if it has already happened at time t, else None."""
        event, when = self.scene.outcomes[k]
        return (event, when) if event != "running" and when <= t + 1e-9 else None

    def draw(self, frame: Frame) -> Image.Image:
        scene = self.scene
        image = self.background.copy()
        draw = ImageDraw.Draw(image)
        i, robots, humans = self._state(frame.time)
        self._draw_human_tails(draw, i, humans)
        for k in self.stack:
            self._draw_trail(draw, k, i, frame.time, robots[k])
        happened = [self._event(k, frame.time) for k in range(scene.n_agents)]
        for k in self.order:  # under everything, so the person who was hit stays visible
            if happened[k] and happened[k][0] == "collision":
                paste(image, self.sprites.crash, robots[k])
        for p in range(scene.n_panels):
            for h in range(scene.n_humans):
                paste(image, self.sprites.humans[h], humans[p, h])
        self._draw_robots(image, robots)
        for k in self.order:
            if happened[k]:
                self._draw_event(image, k, happened[k], robots[k], frame)
        self._clip_to_arenas(image, self.background)
        self.draw_header(image, frame.time + scene.clock)
        if scene.parting is not None and scene.leader is not None and self.parting_shown(frame):
            _, at, _ = self._state(scene.parting)
            self.draw_ring(image, at[scene.leader], self.robot_px * 2.3)
            self.draw_parting_caption(image, PARTING_CAPTION)
        self._draw_legend(image, frame.time)
        return image

    def _draw_robots(self, image: Image.Image, robots: np.ndarray) -> None:
        """Robots on top of each other (both start at the same place) are drawn as one split marker, a vertical
        slice of each, so none is hidden."""
        near = self.robot_px * 0.5
        for k in self.stack:
            together = [
                j
                for j in self.order
                if self.panel_of[j] == self.panel_of[k] and np.hypot(*(robots[j] - robots[k])) < near
            ]
            marker, half = self.sprites.markers[self.numbers[k]]
            if len(together) == 1:
                paste(image, (marker, half), robots[k])
                continue
            slot, m = together.index(k), len(together)
            left, right = round(2 * half * slot / m), round(2 * half * (slot + 1) / m)
            piece = marker.crop((left, 0, right, 2 * half))
            x, y = int(round(robots[k][0])) - half + left, int(round(robots[k][1])) - half
            image.paste(piece, (x, y), piece)

    def _draw_event(self, image: Image.Image, k: int, happened: tuple[str, float], xy, frame: Frame) -> None:
        """An expanding ring while the clip pauses on the event; then a badge (arrival, timeout) on the robot, or
        a CRASH tag for a few seconds (it would hide the people walking past later)."""
        event, when = happened
        r = self.robot_px
        since = self.since(when, frame)
        if 0 <= since < self.options.event_hold + 0.3:
            grow = 1.5 + 4.0 * min(1.0, since / max(self.options.event_hold, 1e-6))
            ring = (xy[0] - r * grow, xy[1] - r * grow, xy[0] + r * grow, xy[1] + r * grow)
            ImageDraw.Draw(image).ellipse(ring, outline=INK, width=max(3, int(r / 4)))
        if event != "collision":
            paste(image, self.sprites.badges[event], (xy[0] + r * 1.1, xy[1] - r * 1.1))
        elif since < self.options.event_hold + CRASH_TAG_SECONDS:
            at, anchor = self._crash_tag_place(k, xy)
            self.draw_tag(image, at, "CRASH", self._crash_tag_size(), anchor)

    def _crash_tag_size(self) -> int:
        return max(12, int(self.layout.text * 0.85))

    def _crash_tag_place(self, k: int, xy) -> tuple[tuple[float, float], str]:
        """Where the CRASH tag goes: above the crash unless that covers a goal or another robot (and its badge)
        or leaves the arena, then below, left or right of it, whichever stays clearest."""
        lay, r, size = self.layout, self.robot_px, self._crash_tag_size()
        panel = self.panel_of[k]
        others = [j for j in range(self.scene.n_agents) if j != k and self.panel_of[j] == panel]
        goals = [lay.to_pixel(panel, self.scene.goals[j]) for j in [k, *others]]
        _, robots, _ = self._state(self.scene.outcomes[k][1])
        # a goal's target and its label; the other robots at the crash and where they end, with their badges
        clear = [(g, r * 1.6) for g in goals] + [((g[0], g[1] + r * 2.2), r) for g in goals]
        clear += [(at, r * 2.2) for j in others for at in (robots[j], self.pixels_robots[-1, j])]
        arena = (panel * lay.panel, lay.header, (panel + 1) * lay.panel, lay.header + lay.panel)

        def score(place: tuple[tuple[float, float], str]) -> float:
            box = tag_box(place[0], "CRASH", size, place[1])
            outside = max(arena[0] - box[0], arena[1] - box[1], box[2] - arena[2], box[3] - arena[3], 0.0)
            room = min((_distance_to_box(p, box) - radius for p, radius in clear), default=math.inf)
            return min(room, r) - 1e6 * outside  # any side with a robot's width of room is as good as another

        sides = ((0, -3, "mb"), (0, 3, "mt"), (-3, 0, "rm"), (3, 0, "lm"))
        return max((((xy[0] + dx * r, xy[1] + dy * r), anchor) for dx, dy, anchor in sides), key=score)

    def _draw_legend(self, image: Image.Image, t: float) -> None:
        """One entry per robot: its icon, its name, and what has happened to it in words and a badge."""
        lay = self.layout
        top = lay.header + lay.panel + lay.text * 0.45
        row = lay.text * 1.5
        for slot, k in enumerate(self.order):
            number = self.numbers[k]
            if lay.panels == 1:
                x0, y = lay.text * 0.6, top + slot * row + row / 2
                status_xy, anchor = (lay.width - lay.text * 0.6, y), "rm"
            else:
                x0, y = self.panel_of[k] * lay.panel + lay.text * 0.6, top + row / 2
                status_xy, anchor = (x0 + lay.text * 1.8, y + row), "lm"
            icon = self.sprites.icons[number]
            paste(image, icon, (x0 + icon[1], y))
            label = self.draw_text(image, (x0 + lay.text * 1.8, y), robot_label(number), lay.text, INK, "lm", True)
            event, when = self._event(k, t) or ("", t)
            if not event and t >= self.scene.end_time:
                event = "running"
            to_goal = math.dist(self.scene.robots[-1, k], self.scene.goals[k])
            status = status_text(event, when + self.scene.clock, to_goal) if event else STATUS_RUNNING
            badge = self.sprites.small_badges.get(event)
            gap = lay.text * 0.4 + badge[1] if badge else 0.0
            # side by side, the status fits its panel's margins; alone, what its name and badge leave of the line
            room = lay.panel - lay.text * 3.0 if anchor == "lm" else status_xy[0] - label[2] - lay.text * 0.8 - 2 * gap
            status, size = fit_text(status, lay.text, room, event == "collision")
            if event == "collision":
                self.draw_tag(image, status_xy, status, size, anchor)
                continue
            box = self.draw_text(image, status_xy, status, size, INK if event else MUTED, anchor)
            if badge:
                centre = (box[0] - gap, y) if anchor == "rm" else (x0 + badge[1], status_xy[1])
                paste(image, badge, centre)


def render(
    scene: Scene, out: str | os.PathLike, numbers: list[int] | None = None, options: RenderOptions | None = None
) -> RenderResult:
    """Draw and encode a clip with its poster and contact sheet; the clip appears only once complete."""
    started = time.perf_counter()
    return encode(CrowdClipRenderer(scene, numbers, options), out, started)


def render_file(
    summary: str | os.PathLike,
    out: str | os.PathLike,
    numbers: list[int] | None = None,
    options: RenderOptions | None = None,
) -> RenderResult:
    """`foil render` for a crowd summary: the clip, its poster and its contact sheet."""
    return render(load_scene(summary), out, numbers, options)


def _distance_to_box(point, box) -> float:
    """Pixels from ``point`` to the nearest point of ``box`` (0 inside it)."""
    dx = max(box[0] - point[0], 0.0, point[0] - box[2])
    dy = max(box[1] - point[1], 0.0, point[1] - box[3])
    return math.hypot(dx, dy)
