"""Clips of a summary: a top-down view of the arena as the paper's Figure 1 draws it, encoded for every browser.

Participants judge two robots from a clip in a few seconds, on a laptop or a 360-px-wide phone, so the picture
must be readable at a glance: humans are grey discs numbered 0-9; each robot has a strong colour, its own shape
and its number (colour-blind viewers get shape and number); markers and their numbers keep a minimum size on a
phone, so in a wide view they are drawn larger than to scale; a collision is a yellow-and-black burst with a tag
where it happened and a pause; reaching the goal or running out of time gets a badge and a line in the legend.
The legend sits below the arena and never names the real agent, only "Robot 1", "Robot 2", ...

Frames are drawn with Pillow onto a cached background from pre-rendered, anti-aliased sprites, and streamed to
ffmpeg (imageio-ffmpeg) while they are drawn: H.264, yuv420p, sizes in multiples of 16, explicit CRF, faststart.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from functools import cache, lru_cache
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from app.visible import one_decimal
from search.clips.scene import Scene, load_scene

# Colours that stay apart under the common colour-vision deficiencies: Okabe-Ito's blue, vermillion, bluish green,
# orange, sky blue and reddish purple, and Paul Tol's purple (darker than Okabe-Ito's pink so its trail shows);
# Okabe-Ito's yellow is kept for collisions. Robot N gets colour (N-1) mod 7 and shape (N-1) mod 6: 7 and 6 are
# coprime, so the 42 numbers of a cycle each have a style of their own and any 6 consecutive numbers differ in both
# colour and shape. The look-alikes (blue and sky blue, purple and reddish purple, vermillion and orange) sit 3
# apart in the cycle, so any 3 consecutive numbers (a clip's pair or a ranking round, which `foil bundle` numbers
# in a block) get clearly different colours. The number is always drawn, so colour-blind viewers get shape and
# number.
ROBOT_COLOURS = (
    (0, 114, 178),  # blue
    (213, 94, 0),  # vermillion
    (0, 158, 115),  # bluish green
    (204, 121, 167),  # reddish purple
    (86, 180, 233),  # sky blue
    (230, 159, 0),  # orange
    (170, 51, 119),  # purple
)
ROBOT_SHAPES = ("circle", "square", "diamond", "triangle", "triangle-down", "plus")
ROBOT_STYLES = tuple(
    (ROBOT_COLOURS[i % len(ROBOT_COLOURS)], ROBOT_SHAPES[i % len(ROBOT_SHAPES)])
    for i in range(len(ROBOT_COLOURS) * len(ROBOT_SHAPES))
)
BACKGROUND = (255, 255, 255)
ARENA = (247, 247, 245)
GRID = (228, 228, 224)
INK = (34, 34, 34)
MUTED = (110, 110, 110)
HUMAN_FILL = (222, 222, 222)
HUMAN_EDGE = (90, 90, 90)
HUMAN_TAIL = (205, 205, 200)
CRASH = (240, 228, 66)  # Okabe-Ito yellow, always with black outline and text
SUCCESS = (0, 158, 115)
SUPERSAMPLE = 4
PHONE_WIDTH = 360  # the narrowest screen a clip must stay readable on
MIN_PHONE_TEXT = 13  # px of legend text on that screen
MIN_PHONE_MARKER = 10  # px radius of a person's or robot's marker on that screen, so its number is about 10 px tall
CRASH_TAG_SECONDS = 3.0  # of video after a collision's pause
PARTING_SECONDS = 1.0  # of video around the moment agents that followed a leader part, during which it is marked
PARTING_CAPTION = "Here the {count} robots would act differently"  # {count}: "two", "three", ...


@dataclass(frozen=True)
class RenderOptions:
    """How a clip looks and plays; the defaults suit the study (24 fps, real time, holds at both ends)."""

    fps: int = 24
    speed: float = 1.0  # simulated seconds per second of video
    hold_start: float = 1.0  # seconds the first frame stays, so viewers can find both robots
    hold_end: float = 1.5
    event_hold: float = 0.6  # seconds the clip pauses on a collision, arrival or timeout
    width: int | None = None  # total width in px; default 720 (one arena) or 960 (side by side)
    crf: int = 23
    preset: str = "veryfast"
    trail_fade: float = 6.0  # seconds for a trail to fade to its faint floor

    def __post_init__(self):
        checks = [
            (self.fps >= 20, "fps must be at least 20 (smooth motion)"),
            (self.fps <= 60, "fps must be at most 60"),
            (0.05 <= self.speed <= 20, "speed must lie between 0.05 and 20"),
            (min(self.hold_start, self.hold_end, self.event_hold) >= 0, "holds must not be negative"),
            (self.width is None or 320 <= self.width <= 3840, "width must lie between 320 and 3840 px"),
            (0 <= self.crf <= 51, "crf must lie between 0 and 51"),
            (self.trail_fade > 0, "trail_fade must be positive"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid render options: {message}")


def robot_label(number: int) -> str:
    """The only name a participant ever sees for a robot."""
    return f"Robot {number}"


def robot_style(number: int) -> tuple[tuple[int, int, int], str]:
    """Robot ``number``'s colour and shape (numbers from 1; the styles repeat after len(ROBOT_STYLES))."""
    return ROBOT_STYLES[(number - 1) % len(ROBOT_STYLES)]


def robot_numbers(numbers: list[int] | None, agents: int) -> list[int]:
    """The robot number shown for each of a summary's agents (default 1, 2, ...), checked: every clip renderer
    must tell its robots apart by colour and shape."""
    numbers = list(numbers) if numbers is not None else list(range(1, agents + 1))
    if (
        len(numbers) != agents
        or not all(isinstance(n, int) and n >= 1 for n in numbers)
        or len({robot_style(n) for n in numbers}) != agents
    ):
        raise ValueError(
            f"give one robot number (1 or more) per agent, each with its own colour and shape "
            f"(numbers {len(ROBOT_STYLES)} apart share one); the summary has {agents} agents, got {numbers}"
        )
    return numbers


def _luminance(colour) -> float:
    linear = [v / 255 / 12.92 if v / 255 <= 0.03928 else ((v / 255 + 0.055) / 1.055) ** 2.4 for v in colour]
    return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]


def number_ink(colour) -> tuple[int, int, int]:
    """White or ink for a number on ``colour``, whichever contrasts more (WCAG contrast ratio)."""
    white = 1.05 / (_luminance(colour) + 0.05)
    ink = (_luminance(colour) + 0.05) / (_luminance(INK) + 0.05)
    return (255, 255, 255) if white >= ink else INK


@cache
def font(size: int) -> ImageFont.FreeTypeFont:
    """Pillow's bundled scalable font, so clips look the same on every machine."""
    return ImageFont.load_default(size=size)


def _round16(value: float) -> int:
    return int(math.ceil(value / 16.0) * 16)


@dataclass(frozen=True)
class Layout:
    """Where everything goes: a header with the clock, one square arena per panel, the legend below."""

    panels: int
    panel: int  # px per side of one arena
    header: int
    legend: int
    width: int
    height: int
    origin: tuple[float, float]  # world (x, y) at the arena's bottom-left corner
    span: float  # metres across one arena
    text: int  # legend font size

    @classmethod
    def make(cls, scene: Scene, options: RenderOptions) -> Layout:
        panels = scene.n_panels
        width = options.width or (720 if panels == 1 else 960)
        panel = (width // panels) // 16 * 16
        width = panel * panels
        text = math.ceil(MIN_PHONE_TEXT * width / PHONE_WIDTH)
        header = round(text * 2.0)
        rows = scene.n_agents if panels == 1 else 2
        legend = round(text * (0.9 + 1.5 * rows))
        total = header + panel + legend
        legend += _round16(total) - total
        low, high = scene.extent()
        span = float(max(high - low))
        centre = (low + high) / 2
        return cls(
            panels=panels,
            panel=panel,
            header=header,
            legend=legend,
            width=width,
            height=_round16(total),
            origin=(float(centre[0] - span / 2), float(centre[1] - span / 2)),
            span=span,
            text=text,
        )

    @property
    def scale(self) -> float:
        """Pixels per metre."""
        return self.panel / self.span

    def marker(self, radius_m: float) -> float:
        """Pixel radius of a person or robot: to scale, but never under MIN_PHONE_MARKER on a phone."""
        return max(radius_m * self.scale, MIN_PHONE_MARKER * self.width / PHONE_WIDTH)

    def to_pixel(self, panel: int, xy) -> np.ndarray:
        """World coordinates (..., 2) to pixel (column, row) in the frame; y points up on screen."""
        xy = np.asarray(xy, dtype=np.float64)
        col = panel * self.panel + (xy[..., 0] - self.origin[0]) * self.scale
        row = self.header + self.panel - (xy[..., 1] - self.origin[1]) * self.scale
        return np.stack([col, row], axis=-1)


def _sprite(size: float, scale: float, paint) -> tuple[Image.Image, int]:
    """An anti-aliased RGBA sprite of half size ``size * scale`` px drawn at SUPERSAMPLE x by ``paint(draw, centre,
    scale)`` (scale: px per unit of ``size``), and its half size."""
    half = max(4, math.ceil(size * scale))
    big = Image.new("RGBA", (2 * half * SUPERSAMPLE, 2 * half * SUPERSAMPLE), (0, 0, 0, 0))
    paint(ImageDraw.Draw(big), half * SUPERSAMPLE, scale * SUPERSAMPLE)
    return big.resize((2 * half, 2 * half), Image.LANCZOS), half


def _shape(draw: ImageDraw.ImageDraw, shape: str, c: float, r: float, **style) -> None:
    if shape == "circle":
        draw.ellipse((c - r, c - r, c + r, c + r), **style)
    elif shape == "square":
        s = r * 0.95
        draw.rectangle((c - s, c - s, c + s, c + s), **style)
    elif shape == "diamond":
        s = r * 1.25
        draw.polygon([(c, c - s), (c + s, c), (c, c + s), (c - s, c)], **style)
    elif shape in ("triangle", "triangle-down"):
        s = r * 1.55 * (1 if shape == "triangle" else -1)
        draw.polygon([(c, c - s), (c + s * 0.87, c + s * 0.5), (c - s * 0.87, c + s * 0.5)], **style)
    else:  # a plus, arms wide enough for two digits
        s, w = r * 1.3, r * 0.6
        draw.polygon(
            [
                (c - w, c - s),
                (c + w, c - s),
                (c + w, c - w),
                (c + s, c - w),
                (c + s, c + w),
                (c + w, c + w),
                (c + w, c + s),
                (c - w, c + s),
                (c - w, c + w),
                (c - s, c + w),
                (c - s, c - w),
                (c - w, c - w),
            ],
            **style,
        )


# a number in a triangle sits towards its wide side (by this many radii) and a size smaller
NUMBER_DROP = {"triangle": 0.3, "triangle-down": -0.3}


def _centered_text(draw: ImageDraw.ImageDraw, c: float, text: str, size: int, fill, dy: float = 0) -> None:
    draw.text((c, c + dy), text, font=font(size), fill=fill, anchor="mm")


@lru_cache(maxsize=4096)
def _text_stamp(text: str, size: int, fill, anchor: str, bold: bool) -> tuple[Image.Image, tuple[int, int]]:
    """Text as an RGBA image and the offset of its corner from the anchor point."""
    stroke = 1 if bold else 0
    x0, y0, x1, y1 = ImageDraw.Draw(Image.new("RGBA", (1, 1))).textbbox(
        (0, 0), text, font=font(size), anchor=anchor, stroke_width=stroke
    )
    stamp = Image.new("RGBA", (max(1, x1 - x0), max(1, y1 - y0)), fill + (0,))
    ImageDraw.Draw(stamp).text(
        (-x0, -y0), text, font=font(size), fill=fill, anchor=anchor, stroke_width=stroke, stroke_fill=fill
    )
    return stamp, (x0, y0)


class Sprites:
    """Humans, robots and marks pre-rendered once per clip: at the arena's scale, and at legend size."""

    def __init__(self, numbers: list[int], n_humans: int, human: float, robot: float, legend_text: int):
        """``human`` and ``robot``: their markers' radii in px; ``numbers``: the clip's robot numbers."""
        self.humans = [self._human(i, human) for i in range(n_humans)]
        self.robots = {n: self._robot(n, robot, 1.0) for n in numbers}
        self.icons = {n: self._robot(n, robot, legend_text * 0.85 / (robot * 1.5)) for n in numbers}
        self.crash = _sprite(robot * 2.6, 1.0, _paint_burst)
        self.badges = {
            "success": _sprite(robot * 0.75, 1.0, _paint_check),
            "timeout": _sprite(robot * 0.75, 1.0, _paint_clock),
        }
        small = legend_text * 0.5 / (robot * 0.75)
        self.small_badges = {
            "success": _sprite(robot * 0.75, small, _paint_check),
            "timeout": _sprite(robot * 0.75, small, _paint_clock),
        }

    @staticmethod
    def _human(index: int, radius: float):
        def paint(draw, c, ppm):
            r = radius * ppm
            draw.ellipse((c - r, c - r, c + r, c + r), fill=HUMAN_FILL, outline=HUMAN_EDGE, width=max(1, int(r / 8)))
            _centered_text(draw, c, str(index), int(r * (1.5 if index < 10 else 1.1)), INK)

        return _sprite(radius * 1.05, 1.0, paint)

    @staticmethod
    def _robot(number: int, radius: float, scale: float):
        colour, shape = robot_style(number)
        size = {1: 1.45, 2: 1.2}.get(len(str(number)), 0.85)  # font size in radii: wider numbers, smaller type
        size *= 0.85 if shape in NUMBER_DROP else 1

        def paint(draw, c, ppm):
            r = radius * ppm
            _shape(draw, shape, c, r * 1.15, fill=(255, 255, 255))
            _shape(draw, shape, c, r, fill=colour, outline=INK, width=max(1, int(r / 10)))
            _centered_text(draw, c, str(number), int(r * size), number_ink(colour), r * NUMBER_DROP.get(shape, 0))

        return _sprite(radius * 1.75, scale, paint)

    def robot(self, number: int):
        return self.robots[number]


def _paint_burst(draw, c, ppm):
    points = []
    for k in range(24):
        angle = math.pi * k / 12
        r = c * (0.98 if k % 2 == 0 else 0.55)
        points.append((c + r * math.cos(angle), c + r * math.sin(angle)))
    draw.polygon(points, fill=CRASH, outline=(0, 0, 0), width=max(2, int(c / 14)))


def _paint_check(draw, c, ppm):
    draw.ellipse((0, 0, 2 * c, 2 * c), fill=SUCCESS, outline=(255, 255, 255), width=max(2, int(c / 6)))
    draw.line(
        [(c * 0.5, c * 1.05), (c * 0.85, c * 1.4), (c * 1.5, c * 0.6)],
        fill=(255, 255, 255),
        width=max(2, int(c / 4)),
        joint="curve",
    )


def _paint_clock(draw, c, ppm):
    draw.ellipse((0, 0, 2 * c, 2 * c), fill=INK, outline=(255, 255, 255), width=max(2, int(c / 6)))
    w = max(2, int(c / 5))
    draw.line([(c, c * 0.45), (c, c), (c * 1.45, c * 1.2)], fill=(255, 255, 255), width=w, joint="curve")


def _paste(frame: Image.Image, sprite: tuple[Image.Image, int], xy) -> None:
    image, half = sprite
    frame.paste(image, (int(round(xy[0])) - half, int(round(xy[1])) - half), image)


def _leader_last(order: list[int], leader: int | None) -> list[int]:
    """A drawing order with the followed leader last, on top of those that move with it."""
    return order if leader is None else [k for k in order if k != leader] + [leader]


def _mix(colour, amount: float, base=ARENA) -> tuple[int, int, int]:
    return tuple(int(round(b + (c - b) * amount)) for c, b in zip(colour, base, strict=True))


STATUS_RUNNING = "on its way"
COUNTS = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}  # how many agents a caption speaks of


def status_text(event: str, when: float, to_goal: float = math.nan) -> str:
    """The legend line for an outcome, short enough for one side-by-side panel on a phone; a robot still on its
    way at the end says how far from its goal it stopped (one on the goal's rings has not reached it yet)."""
    words = {"success": "reached goal", "collision": "CRASHED", "timeout": "out of time", "running": "still on its way"}
    if event != "running":
        return f"{words[event]} · {one_decimal(when)} s"
    return words[event] if math.isnan(to_goal) else f"{words[event]} · {one_decimal(to_goal)} m to goal"


@dataclass(frozen=True)
class Frame:
    """One frame: the simulated time it shows and where it sits in the video (inf: a still, such as the poster)."""

    time: float
    video: float = math.inf


class ClipRenderer:
    """Draws the frames of one clip. ``numbers[k]`` is the robot number shown for the summary's agent ``k``."""

    def __init__(self, scene: Scene, numbers: list[int] | None = None, options: RenderOptions | None = None):
        self.scene = scene
        self.options = options or RenderOptions()
        numbers = robot_numbers(numbers, len(scene.agents))  # one per summary agent, drawn or not
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
        self.texts: set[str] = set()  # every string drawn, so tests can check that no real name appears
        self.background = self._background()
        self.frames, self.event_starts = self._schedule()
        self.parting_video = self._parting_video()

    # -- timeline -----------------------------------------------------------------------------------------------

    def _schedule(self) -> tuple[list[Frame], dict[float, float]]:
        """Every frame (hold, play at ``speed`` with a pause at each event, hold) and, per event time, the second
        of video at which its pause starts."""
        o, end = self.options, self.scene.end_time
        step, tick = o.speed / o.fps, 1 / o.fps
        pause = round(o.event_hold * o.fps)
        pending = sorted({t for t in self.scene.event_times() if 0 < t <= end})
        times = [i * step for i in range(int(math.floor(end / step + 1e-9)) + 1)]
        if times[-1] < end:
            times.append(end)
        frames = [Frame(0.0, h * tick) for h in range(round(o.hold_start * o.fps))]
        starts = {}
        for t in times:
            while pending and pending[0] <= t:
                event = pending.pop(0)
                starts[event] = len(frames) * tick
                frames += [Frame(event, len(frames) * tick + h * tick) for h in range(pause)]
            frames.append(Frame(t, len(frames) * tick))
        frames += [Frame(end, (len(frames) + h) * tick) for h in range(round(o.hold_end * o.fps))]
        return frames, starts

    def _parting_video(self) -> float:
        """The second of video at which the agents part (the first frame that reaches it after the opening
        hold), or inf in a clip without that moment."""
        if self.scene.parting is None:
            return math.inf
        played = self.frames[round(self.options.hold_start * self.options.fps) :]
        return next((f.video for f in played if f.time >= self.scene.parting - 1e-9), math.inf)

    def _parting_shown(self, frame: Frame) -> bool:
        """Whether a frame marks the moment the agents part: PARTING_SECONDS of video around it, or a still of it."""
        if self.scene.parting is None:
            return False
        if not math.isfinite(frame.video):
            return abs(frame.time - self.scene.parting) < 1e-9
        return abs(frame.video - self.parting_video) <= PARTING_SECONDS / 2

    def _since(self, when: float, frame: Frame) -> float:
        """Seconds of video since the pause for the event at ``when`` began (inf in a still)."""
        return frame.video - self.event_starts.get(when, math.inf) if math.isfinite(frame.video) else math.inf

    # -- drawing ------------------------------------------------------------------------------------------------

    def _text(
        self, image: Image.Image, xy, text: str, size: int, fill=INK, anchor: str = "la", bold: bool = False
    ) -> tuple[float, float, float, float]:
        """Draw text from a cache of stamps (text rendering dominates a frame otherwise); returns its box."""
        self.texts.add(text)
        stamp, (x0, y0) = _text_stamp(text, size, fill, anchor, bold)
        left, top = int(round(xy[0] + x0)), int(round(xy[1] + y0))
        image.paste(stamp, (left, top), stamp)
        return left, top, left + stamp.width, top + stamp.height

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
        self._draw_scale_bar(image)
        return image

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
        self._text(image, (sx, sy + r * 1.35), "start", size, fill=MUTED, anchor="mt")
        gx, gy = lay.to_pixel(panel, self.scene.goals[k])
        for ring, fill in ((1.4, INK), (0.9, ARENA), (0.45, INK)):
            draw.ellipse((gx - r * ring, gy - r * ring, gx + r * ring, gy + r * ring), fill=fill)
        self._text(image, (gx, gy + r * 1.6), "goal", size, fill=INK, anchor="mt")

    def _draw_scale_bar(self, image: Image.Image) -> None:
        draw = ImageDraw.Draw(image)
        lay = self.layout
        x1 = lay.width - lay.text * 0.6
        x0 = x1 - lay.scale
        y = lay.header / 2
        draw.line([(x0, y), (x1, y)], fill=INK, width=max(2, lay.text // 8))
        for x in (x0, x1):
            draw.line([(x, y - lay.text * 0.25), (x, y + lay.text * 0.25)], fill=INK, width=max(2, lay.text // 8))
        self._text(image, (x0 - lay.text * 0.4, y), "1 m", lay.text, fill=INK, anchor="rm")

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
        colour = robot_style(self.numbers[k])[0]
        points = [tuple(p) for p in self.pixels_robots[: i + 1, k]] + [tuple(head)]
        ages = t - np.append(self.scene.times[: i + 1], t)
        shades = np.round((0.25 + 0.75 * np.exp(-ages / self.options.trail_fade)) * 8) / 8
        width = max(3, int(self.robot_px * 0.35))
        start = 0
        for j in range(1, len(points)):
            if j == len(points) - 1 or shades[j] != shades[start]:
                draw.line(points[start : j + 1], fill=_mix(colour, float(shades[start])), width=width, joint="curve")
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
                _paste(image, self.sprites.crash, robots[k])
        for p in range(scene.n_panels):
            for h in range(scene.n_humans):
                _paste(image, self.sprites.humans[h], humans[p, h])
        self._draw_robots(image, robots)
        for k in self.order:
            if happened[k]:
                self._draw_event(image, happened[k], robots[k], frame)
        self._draw_header(image, frame.time)
        if scene.parting is not None and scene.leader is not None and self._parting_shown(frame):
            _, at, _ = self._state(scene.parting)
            self._draw_ring(image, at[scene.leader], self.robot_px * 2.3)
            self._draw_parting_caption(image, PARTING_CAPTION)
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
            sprite, half = self.sprites.robot(self.numbers[k])
            if len(together) == 1:
                _paste(image, (sprite, half), robots[k])
                continue
            slot, m = together.index(k), len(together)
            left, right = round(2 * half * slot / m), round(2 * half * (slot + 1) / m)
            piece = sprite.crop((left, 0, right, 2 * half))
            x, y = int(round(robots[k][0])) - half + left, int(round(robots[k][1])) - half
            image.paste(piece, (x, y), piece)

    def _tag(self, image: Image.Image, xy, text: str, size: int, anchor: str) -> None:
        """Black text on a yellow box with a black border: the collision colours, readable in greyscale too."""
        stamp, (x0, y0) = _text_stamp(text, size, (0, 0, 0), anchor, True)
        pad = size * 0.25
        left, top = xy[0] + x0, xy[1] + y0
        box = (left - pad, top - pad, left + stamp.width + pad, top + stamp.height + pad)
        ImageDraw.Draw(image).rectangle(box, fill=CRASH, outline=(0, 0, 0), width=max(2, size // 12))
        self._text(image, xy, text, size, (0, 0, 0), anchor, bold=True)

    def _draw_event(self, image: Image.Image, happened: tuple[str, float], xy, frame: Frame) -> None:
        """An expanding ring while the clip pauses on the event; then a badge (arrival, timeout) on the robot, or
        a CRASH tag for a few seconds (it would hide the people walking past later)."""
        event, when = happened
        r = self.robot_px
        since = self._since(when, frame)
        if 0 <= since < self.options.event_hold + 0.3:
            grow = 1.5 + 4.0 * min(1.0, since / max(self.options.event_hold, 1e-6))
            ring = (xy[0] - r * grow, xy[1] - r * grow, xy[0] + r * grow, xy[1] + r * grow)
            ImageDraw.Draw(image).ellipse(ring, outline=INK, width=max(3, int(r / 4)))
        if event != "collision":
            _paste(image, self.sprites.badges[event], (xy[0] + r * 1.1, xy[1] - r * 1.1))
        elif since < self.options.event_hold + CRASH_TAG_SECONDS:
            self._tag(image, (xy[0], xy[1] - r * 3.0), "CRASH", max(12, int(self.layout.text * 0.85)), "mb")

    def _draw_header(self, image: Image.Image, t: float) -> None:
        lay = self.layout
        y = lay.header / 2
        self._text(image, (lay.text * 0.6, y), f"Time {t:4.1f} s", lay.text, INK, "lm")
        if self.options.speed != 1.0:
            self._text(image, (lay.width / 2, y), f"playing {self.options.speed:g}x", lay.text, MUTED, "mm")

    def _draw_parting_caption(self, image: Image.Image, caption: str) -> None:
        """The caption of the moment agents part: white on ink at the header's right, over the scale bar and the
        speed but never the clock."""
        lay = self.layout
        text = caption.format(count=COUNTS.get(len(self.numbers), str(len(self.numbers))))
        right = lay.width - lay.text * 0.6
        stamp, (x0, _) = _text_stamp(text, lay.text, (255, 255, 255), "rm", True)
        box = (right + x0 - lay.text * 0.5, lay.header * 0.1, lay.width, lay.header * 0.9)
        ImageDraw.Draw(image).rectangle(box, fill=INK)
        self._text(image, (right, lay.header / 2), text, lay.text, (255, 255, 255), "rm", bold=True)

    def _draw_ring(self, image: Image.Image, xy, radius: float) -> None:
        """A ring at the place the agents part: ink with a white halo, so it reads on any background."""
        draw = ImageDraw.Draw(image)
        width = max(3, int(self.layout.text / 8))
        for extra, colour in ((width, (255, 255, 255)), (0, INK)):
            r = radius + extra / 2
            draw.ellipse((xy[0] - r, xy[1] - r, xy[0] + r, xy[1] + r), outline=colour, width=width + extra)

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
            _paste(image, icon, (x0 + icon[1], y))
            self._text(image, (x0 + lay.text * 1.8, y), robot_label(number), lay.text, INK, "lm", bold=True)
            event, when = self._event(k, t) or ("", t)
            if not event and t >= self.scene.end_time:
                event = "running"
            to_goal = math.dist(self.scene.robots[-1, k], self.scene.goals[k])
            status = status_text(event, when, to_goal) if event else STATUS_RUNNING
            if event == "collision":
                self._tag(image, status_xy, status, lay.text, anchor)
                continue
            box = self._text(image, status_xy, status, lay.text, INK if event else MUTED, anchor)
            badge = self.sprites.small_badges.get(event)
            if badge:
                gap = lay.text * 0.4 + badge[1]
                centre = (box[0] - gap, y) if anchor == "rm" else (x0 + badge[1], status_xy[1])
                _paste(image, badge, centre)


@dataclass(frozen=True)
class RenderResult:
    clip: Path
    poster: Path
    sheet: Path
    frames: int
    seconds: float  # length of the clip
    width: int
    height: int
    render_s: float  # wall time to draw and encode


def side_paths(clip: str | os.PathLike) -> tuple[Path, Path]:
    """The poster and contact sheet written next to a clip: NAME.poster.png, NAME.sheet.png."""
    clip = Path(clip)
    return clip.with_suffix(".poster.png"), clip.with_suffix(".sheet.png")


def encoder_args(options: RenderOptions) -> list[str]:
    """ffmpeg output flags every mainstream browser (iOS Safari included) plays, with the moov atom first."""
    return [
        "-crf",
        str(options.crf),
        "-preset",
        options.preset,
        "-profile:v",
        "high",
        "-level",
        "4.1",
        "-movflags",
        "+faststart",
        "-map_metadata",
        "-1",
    ]


def contact_sheet(renderer: ClipRenderer, columns: int = 3) -> Image.Image:
    """Key frames (start, every event, the end, evenly spaced in between) in a grid with their times."""
    parting = [] if renderer.scene.parting is None else [renderer.scene.parting]
    times = sorted({0.0, renderer.scene.end_time, *renderer.scene.event_times(), *parting})
    while len(times) < 2 * columns:
        j = int(np.argmax(np.diff(times)))
        times.insert(j + 1, (times[j] + times[j + 1]) / 2)
    if len(times) > 3 * columns:
        times = [times[i] for i in np.linspace(0, len(times) - 1, 3 * columns).round().astype(int)]
    thumbs = [renderer.draw(Frame(t)) for t in times]
    w, h = thumbs[0].width // 2, thumbs[0].height // 2
    rows = math.ceil(len(thumbs) / columns)
    sheet = Image.new("RGB", (w * columns, h * rows), BACKGROUND)
    for n, thumb in enumerate(thumbs):
        sheet.paste(thumb.resize((w, h), Image.LANCZOS), ((n % columns) * w, (n // columns) * h))
    return sheet


def render(
    scene: Scene, out: str | os.PathLike, numbers: list[int] | None = None, options: RenderOptions | None = None
) -> RenderResult:
    """Draw and encode a clip with its poster and contact sheet; the clip appears only once complete."""
    started = time.perf_counter()
    return encode(ClipRenderer(scene, numbers, options), out, started)


def h264_writer(path: Path, size: tuple[int, int], fps: float, options: RenderOptions):
    """A started imageio-ffmpeg writer of RGB frames of ``size`` into an H.264 clip every browser plays."""
    import imageio_ffmpeg

    writer = imageio_ffmpeg.write_frames(
        str(path),
        size,
        fps=fps,
        codec="libx264",
        pix_fmt_out="yuv420p",
        quality=None,
        macro_block_size=16,
        output_params=encoder_args(options),
        ffmpeg_log_level="error",
    )
    writer.send(None)
    return writer


def encode(renderer, out: str | os.PathLike, started: float) -> RenderResult:
    """Encode a renderer's frames (anything with ``options``, ``layout.width/height``, ``frames``, ``draw`` and
    the ``scene`` a contact sheet reads) as the clip, its poster and its contact sheet."""
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise ValueError(f"the clip must be an .mp4 file, got {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    o, lay = renderer.options, renderer.layout
    frames = renderer.frames
    partial = out.with_name(f".{out.stem}.partial.mp4")
    writer = h264_writer(partial, (lay.width, lay.height), o.fps, o)
    poster = None
    try:
        for n, frame in enumerate(frames):
            image = renderer.draw(frame)
            if n == 0:
                poster = image
            writer.send(image.tobytes())
    except BaseException:
        writer.close()
        partial.unlink(missing_ok=True)
        raise
    writer.close()
    partial.replace(out)
    poster_path, sheet_path = side_paths(out)
    poster.save(poster_path, optimize=True)
    contact_sheet(renderer).save(sheet_path, optimize=True)
    return RenderResult(
        clip=out,
        poster=poster_path,
        sheet=sheet_path,
        frames=len(frames),
        seconds=len(frames) / o.fps,
        width=lay.width,
        height=lay.height,
        render_s=time.perf_counter() - started,
    )


def render_file(
    summary: str | os.PathLike,
    out: str | os.PathLike,
    numbers: list[int] | None = None,
    options: RenderOptions | None = None,
) -> RenderResult:
    return render(load_scene(summary), out, numbers, options)
