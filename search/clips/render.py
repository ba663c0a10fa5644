"""The clip toolkit every world's renderer draws with: agents' colours, shapes and numbers, a top-down arena's
layout, anti-aliased sprites, the status panel, the clip's timeline (holds, pauses at events, the moment agents
part), and the encoder (H.264, poster, contact sheet). It names no world: each world's own renderer, in its
folder, brings what its clips show and the word it labels its agents with.

A clip must be readable at a glance on a laptop or a 360-px-wide phone: each agent has a strong colour, its own
shape and its number (colour-blind viewers get shape and number); markers and text keep a minimum size on a
phone; a collision is a yellow-and-black burst with a tag and a pause; reaching the goal or running out of time
gets a badge and a line in the legend. Frames are drawn with Pillow from pre-rendered sprites and streamed to
ffmpeg (imageio-ffmpeg) while they are drawn: H.264, yuv420p, sizes in multiples of 16, explicit CRF, faststart.
"""

from __future__ import annotations

import math
import os
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, lru_cache
from pathlib import Path
from typing import Protocol

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from app.visible import one_decimal

# Colours that stay apart under the common colour-vision deficiencies: Okabe-Ito's blue, vermillion, bluish green,
# orange, sky blue and reddish purple, and Paul Tol's purple (darker than Okabe-Ito's pink so its trail shows);
# Okabe-Ito's yellow is kept for collisions. Agent N gets colour (N-1) mod 7 and shape (N-1) mod 6: 7 and 6 are
# coprime, so the 42 numbers of a cycle each have a style of their own and any 6 consecutive numbers differ in both
# colour and shape. The look-alikes (blue and sky blue, purple and reddish purple, vermillion and orange) sit 3
# apart in the cycle, so any 3 consecutive numbers (a clip's pair or a ranking round, which `foil bundle` numbers
# in a block) get clearly different colours. The number is always drawn, so colour-blind viewers get shape and
# number.
AGENT_COLOURS = (
    (0, 114, 178),  # blue
    (213, 94, 0),  # vermillion
    (0, 158, 115),  # bluish green
    (204, 121, 167),  # reddish purple
    (86, 180, 233),  # sky blue
    (230, 159, 0),  # orange
    (170, 51, 119),  # purple
)
AGENT_SHAPES = ("circle", "square", "diamond", "triangle", "triangle-down", "plus")
AGENT_STYLES = tuple(
    (AGENT_COLOURS[i % len(AGENT_COLOURS)], AGENT_SHAPES[i % len(AGENT_SHAPES)])
    for i in range(len(AGENT_COLOURS) * len(AGENT_SHAPES))
)
BACKGROUND = (255, 255, 255)
ARENA = (247, 247, 245)
GRID = (228, 228, 224)
INK = (34, 34, 34)
MUTED = (110, 110, 110)
CRASH = (240, 228, 66)  # Okabe-Ito yellow, always with black outline and text
SUCCESS = (0, 158, 115)
SUPERSAMPLE = 4
PHONE_WIDTH = 360  # the narrowest screen a clip must stay readable on
MIN_PHONE_TEXT = 13  # px of legend text on that screen
MIN_PHONE_MARKER = 10  # px radius of a marker on that screen, so an agent's number is about 10 px tall
CRASH_TAG_SECONDS = 3.0  # of video after a collision's pause
OPEN_BURST_HOLE = 0.42  # an open burst's hole, in its radii: inside the points' inner ends (0.55)
PARTING_SECONDS = 1.0  # of video around the moment agents that followed a leader part, during which it is marked


@dataclass(frozen=True)
class RenderOptions:
    """How a clip looks and plays; the defaults suit the study (24 fps, real time, holds at both ends)."""

    fps: int = 24
    speed: float = 1.0  # simulated seconds per second of video
    hold_start: float = 1.0  # seconds the first frame stays, so viewers can find every agent
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


def agent_label(word: str, number: int) -> str:
    """The only name a participant ever sees for an agent: the world's word for one, and its number."""
    return f"{word} {number}"


def agent_style(number: int) -> tuple[tuple[int, int, int], str]:
    """Agent ``number``'s colour and shape (numbers from 1; the styles repeat after len(AGENT_STYLES))."""
    return AGENT_STYLES[(number - 1) % len(AGENT_STYLES)]


def agent_numbers(numbers: list[int] | None, agents: int) -> list[int]:
    """The number shown for each of a summary's agents (default 1, 2, ...), checked: every clip renderer must tell
    its agents apart by colour and shape."""
    numbers = list(numbers) if numbers is not None else list(range(1, agents + 1))
    if (
        len(numbers) != agents
        or not all(isinstance(n, int) and n >= 1 for n in numbers)
        or len({agent_style(n) for n in numbers}) != agents
    ):
        raise ValueError(
            f"give one agent number (1 or more) per agent, each with its own colour and shape "
            f"(numbers {len(AGENT_STYLES)} apart share one); the summary has {agents} agents, got {numbers}"
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
def font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """Pillow's bundled scalable font, so clips look the same on every machine."""
    return ImageFont.load_default(size=size)


def round16(value: float) -> int:
    """``value`` rounded up to a multiple of 16 px: H.264's macroblock, so no encoder pads or scales a frame."""
    return int(math.ceil(value / 16.0) * 16)


class ArenaScene(Protocol):
    """What an arena's layout reads of a scene."""

    @property
    def n_agents(self) -> int: ...

    @property
    def n_panels(self) -> int: ...

    def extent(self) -> tuple[np.ndarray, np.ndarray]: ...


@dataclass(frozen=True)
class Layout:
    """Where everything goes in a top-down view: a header with the clock, one square arena per panel, the legend
    below."""

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
    def make(cls, scene: ArenaScene, options: RenderOptions) -> Layout:
        panels = scene.n_panels
        width = options.width or (720 if panels == 1 else 960)
        panel = (width // panels) // 16 * 16
        width = panel * panels
        text = math.ceil(MIN_PHONE_TEXT * width / PHONE_WIDTH)
        header = round(text * 2.0)
        rows = scene.n_agents if panels == 1 else 2
        legend = round(text * (0.9 + 1.5 * rows))
        total = header + panel + legend
        legend += round16(total) - total
        low, high = scene.extent()
        span = float(max(high - low))
        centre = (low + high) / 2
        return cls(
            panels=panels,
            panel=panel,
            header=header,
            legend=legend,
            width=width,
            height=round16(total),
            origin=(float(centre[0] - span / 2), float(centre[1] - span / 2)),
            span=span,
            text=text,
        )

    @property
    def scale(self) -> float:
        """Pixels per metre."""
        return self.panel / self.span

    def marker(self, radius_m: float) -> float:
        """Pixel radius of a marker: to scale, but never under MIN_PHONE_MARKER on a phone."""
        return max(radius_m * self.scale, MIN_PHONE_MARKER * self.width / PHONE_WIDTH)

    def to_pixel(self, panel: int, xy) -> np.ndarray:
        """World coordinates (..., 2) to pixel (column, row) in the frame; y points up on screen."""
        xy = np.asarray(xy, dtype=np.float64)
        col = panel * self.panel + (xy[..., 0] - self.origin[0]) * self.scale
        row = self.header + self.panel - (xy[..., 1] - self.origin[1]) * self.scale
        return np.stack([col, row], axis=-1)


Sprite = tuple[Image.Image, int]  # an RGBA image and its half size in px


def sprite(size: float, scale: float, paint) -> Sprite:
    """An anti-aliased RGBA sprite of half size ``size * scale`` px drawn at SUPERSAMPLE x by ``paint(draw, centre,
    scale)`` (scale: px per unit of ``size``), and its half size."""
    half = max(4, math.ceil(size * scale))
    big = Image.new("RGBA", (2 * half * SUPERSAMPLE, 2 * half * SUPERSAMPLE), (0, 0, 0, 0))
    paint(ImageDraw.Draw(big), half * SUPERSAMPLE, scale * SUPERSAMPLE)
    return big.resize((2 * half, 2 * half), Image.Resampling.LANCZOS), half


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


def centered_text(draw: ImageDraw.ImageDraw, c: float, text: str, size: int, fill, dy: float = 0) -> None:
    """``text`` centred on a sprite's centre ``c`` (``dy`` px lower)."""
    draw.text((c, c + dy), text, font=font(size), fill=fill, anchor="mm")


@lru_cache(maxsize=4096)
def text_stamp(text: str, size: int, fill, anchor: str, bold: bool) -> tuple[Image.Image, tuple[int, int]]:
    """Text as an RGBA image and the offset of its corner from the anchor point."""
    stroke = 1 if bold else 0
    box = ImageDraw.Draw(Image.new("RGBA", (1, 1))).textbbox(
        (0, 0), text, font=font(size), anchor=anchor, stroke_width=stroke
    )
    x0, y0, x1, y1 = (int(v) for v in box)  # whole pixels: Pillow's scalable font measures in them
    stamp = Image.new("RGBA", (max(1, x1 - x0), max(1, y1 - y0)), fill + (0,))
    ImageDraw.Draw(stamp).text(
        (-x0, -y0), text, font=font(size), fill=fill, anchor=anchor, stroke_width=stroke, stroke_fill=fill
    )
    return stamp, (x0, y0)


def tag_box(xy, text: str, size: int, anchor: str) -> tuple[float, float, float, float]:
    """The box (left, top, right, bottom, px) a tag of ``text`` anchored at ``xy`` covers, its padding included."""
    stamp, (x0, y0) = text_stamp(text, size, (0, 0, 0), anchor, True)
    pad = size * 0.25
    left, top = xy[0] + x0, xy[1] + y0
    return left - pad, top - pad, left + stamp.width + pad, top + stamp.height + pad


def text_width(text: str, size: int, bold: bool = False) -> int:
    """Pixels wide ``text`` is drawn (the width of its stamp)."""
    return text_stamp(text, size, (0, 0, 0), "lm", bold)[0].width


FIT_SHRINK = 0.75  # the smallest share of its size a fitted text is drawn at, so it stays readable on a phone


def fit_text(text: str, size: int, room: float, bold: bool = False) -> tuple[str, int]:
    """``text`` and the font size that fit it into ``room`` px: its own ``size`` where it fits, else a smaller one
    down to FIT_SHRINK of it, then shortened with an ellipsis ("" where not even one letter fits), so that a status
    or caption never runs past its view's edge or over a label."""
    smallest = max(1, math.ceil(size * FIT_SHRINK))
    for fitted in range(size, smallest - 1, -1):
        if text_width(text, fitted, bold) <= room:
            return text, fitted
    for end in range(len(text) - 1, 0, -1):
        shortened = text[:end].rstrip() + "…"
        if text_width(shortened, smallest, bold) <= room:
            return shortened, smallest
    return "", smallest


def agent_marker(number: int, radius: float, scale: float) -> Sprite:
    """Agent ``number``'s marker: its shape in its colour with a white halo and its number on it."""
    colour, shape = agent_style(number)
    size = {1: 1.45, 2: 1.2}.get(len(str(number)), 0.85)  # font size in radii: wider numbers, smaller type
    size *= 0.85 if shape in NUMBER_DROP else 1

    def paint(draw, c, ppm):
        r = radius * ppm
        _shape(draw, shape, c, r * 1.15, fill=(255, 255, 255))
        _shape(draw, shape, c, r, fill=colour, outline=INK, width=max(1, int(r / 10)))
        centered_text(draw, c, str(number), int(r * size), number_ink(colour), r * NUMBER_DROP.get(shape, 0))

    return sprite(radius * 1.75, scale, paint)


class AgentSprites:
    """Agents' markers and marks pre-rendered once per clip: at the view's scale, and at legend size."""

    def __init__(self, numbers: list[int], marker: float, legend_text: int, burst: Callable | None = None):
        """``marker``: an agent marker's radius in px; ``numbers``: the clip's agent numbers; ``burst``: how a
        collision's burst is painted (`paint_burst`, or `paint_open_burst` over an agent drawn before it)."""
        self.markers = {n: agent_marker(n, marker, 1.0) for n in numbers}
        self.icons = {n: agent_marker(n, marker, legend_text * 0.85 / (marker * 1.5)) for n in numbers}
        self.crash = sprite(marker * 2.6, 1.0, burst or paint_burst)
        self.badges = {
            "success": sprite(marker * 0.75, 1.0, paint_check),
            "timeout": sprite(marker * 0.75, 1.0, paint_clock),
        }
        small = legend_text * 0.5 / (marker * 0.75)
        self.small_badges = {
            "success": sprite(marker * 0.75, small, paint_check),
            "timeout": sprite(marker * 0.75, small, paint_clock),
        }


def paint_burst(draw, c, ppm):
    """A collision's yellow-and-black burst."""
    points = []
    for k in range(24):
        angle = math.pi * k / 12
        r = c * (0.98 if k % 2 == 0 else 0.55)
        points.append((c + r * math.cos(angle), c + r * math.sin(angle)))
    draw.polygon(points, fill=CRASH, outline=(0, 0, 0), width=max(2, int(c / 14)))


def paint_open_burst(draw, c, ppm):
    """A collision's burst with its middle open (a black-rimmed hole inside its inner points), for a burst drawn
    over the agent that crashed: the agent's own colour still shows through it."""
    paint_burst(draw, c, ppm)
    r = c * OPEN_BURST_HOLE
    draw.ellipse((c - r, c - r, c + r, c + r), fill=(0, 0, 0, 0), outline=(0, 0, 0), width=max(2, int(c / 14)))


def paint_check(draw, c, ppm):
    """The badge of an agent that reached its goal."""
    draw.ellipse((0, 0, 2 * c, 2 * c), fill=SUCCESS, outline=(255, 255, 255), width=max(2, int(c / 6)))
    draw.line(
        [(c * 0.5, c * 1.05), (c * 0.85, c * 1.4), (c * 1.5, c * 0.6)],
        fill=(255, 255, 255),
        width=max(2, int(c / 4)),
        joint="curve",
    )


def paint_clock(draw, c, ppm):
    """The badge of an agent that ran out of time."""
    draw.ellipse((0, 0, 2 * c, 2 * c), fill=INK, outline=(255, 255, 255), width=max(2, int(c / 6)))
    w = max(2, int(c / 5))
    draw.line([(c, c * 0.45), (c, c), (c * 1.45, c * 1.2)], fill=(255, 255, 255), width=w, joint="curve")


def paste(frame: Image.Image, sprite: Sprite, xy) -> None:
    """``sprite`` centred on ``xy`` (px) in ``frame``."""
    image, half = sprite
    frame.paste(image, (int(round(xy[0])) - half, int(round(xy[1])) - half), image)


STATUS_RUNNING = "on its way"
COUNTS = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}  # how many agents a caption speaks of


def status_text(event: str, when: float, to_goal: float = math.nan) -> str:
    """The legend line for an outcome, short enough for one side-by-side panel on a phone; an agent still on its
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


class TimedScene(Protocol):
    """What a clip's timeline reads of a scene."""

    @property
    def end_time(self) -> float: ...

    @property
    def parting(self) -> float | None:
        """When agents that followed a leader part (a disagreement clip's moment), else None."""

    def event_times(self) -> list[float]: ...


class FrameLayout(Protocol):
    """What the encoder, header, tags and rings read of a layout: sizes in px, the text's too."""

    @property
    def width(self) -> int: ...

    @property
    def height(self) -> int: ...

    @property
    def header(self) -> int: ...

    @property
    def text(self) -> int: ...


class ClipRenderer(ABC):
    """What every world's clip renderer shares: the timeline (holds, a pause at each event, the moment agents part)
    and the header, text, tags and rings it draws around the world's own picture. A subclass sets ``scene``,
    ``layout``, ``options``, ``numbers`` (the shown agents' numbers) and ``texts``, then ``frames``,
    ``event_starts`` (`schedule`) and ``parting_video`` (`parting_second`), and draws a frame in ``draw``."""

    scene: TimedScene
    layout: FrameLayout
    options: RenderOptions
    numbers: list[int]
    texts: set[str]  # every string drawn, so tests can check that no real name appears
    frames: list[Frame]
    event_starts: dict[float, float]
    parting_video: float

    @abstractmethod
    def draw(self, frame: Frame) -> Image.Image:
        """The picture of one frame."""

    # -- timeline -----------------------------------------------------------------------------------------------

    def schedule(self) -> tuple[list[Frame], dict[float, float]]:
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

    def parting_second(self) -> float:
        """The second of video at which the agents part (the first frame that reaches it after the opening
        hold), or inf in a clip without that moment."""
        if self.scene.parting is None:
            return math.inf
        played = self.frames[round(self.options.hold_start * self.options.fps) :]
        return next((f.video for f in played if f.time >= self.scene.parting - 1e-9), math.inf)

    def parting_shown(self, frame: Frame) -> bool:
        """Whether a frame marks the moment the agents part: PARTING_SECONDS of video around it, or a still of it."""
        if self.scene.parting is None:
            return False
        if not math.isfinite(frame.video):
            return abs(frame.time - self.scene.parting) < 1e-9
        return abs(frame.video - self.parting_video) <= PARTING_SECONDS / 2

    def since(self, when: float, frame: Frame) -> float:
        """Seconds of video since the pause for the event at ``when`` began (inf in a still)."""
        return frame.video - self.event_starts.get(when, math.inf) if math.isfinite(frame.video) else math.inf

    # -- drawing ------------------------------------------------------------------------------------------------

    def draw_text(
        self, image: Image.Image, xy, text: str, size: int, fill=INK, anchor: str = "la", bold: bool = False
    ) -> tuple[float, float, float, float]:
        """Draw text from a cache of stamps (text rendering dominates a frame otherwise); returns its box."""
        self.texts.add(text)
        stamp, (x0, y0) = text_stamp(text, size, fill, anchor, bold)
        left, top = int(round(xy[0] + x0)), int(round(xy[1] + y0))
        image.paste(stamp, (left, top), stamp)
        return left, top, left + stamp.width, top + stamp.height

    def draw_tag(self, image: Image.Image, xy, text: str, size: int, anchor: str) -> None:
        """Black text on a yellow box with a black border: the collision colours, readable in greyscale too."""
        box = tag_box(xy, text, size, anchor)
        ImageDraw.Draw(image).rectangle(box, fill=CRASH, outline=(0, 0, 0), width=max(2, size // 12))
        self.draw_text(image, xy, text, size, (0, 0, 0), anchor, bold=True)

    def draw_header(self, image: Image.Image, t: float) -> None:
        """The clock at the header's left, and the speed in its middle when the clip does not play in real time."""
        lay = self.layout
        y = lay.header / 2
        self.draw_text(image, (lay.text * 0.6, y), f"Time {t:4.1f} s", lay.text, INK, "lm")
        if self.options.speed != 1.0:
            self.draw_text(image, (lay.width / 2, y), f"playing {self.options.speed:g}x", lay.text, MUTED, "mm")

    def draw_parting_caption(self, image: Image.Image, caption: str) -> None:
        """The caption of the moment agents part: white on ink at the header's right, over the scale bar and the
        speed but never the clock."""
        lay = self.layout
        text = caption.format(count=COUNTS.get(len(self.numbers), str(len(self.numbers))))
        right = lay.width - lay.text * 0.6
        stamp, (x0, _) = text_stamp(text, lay.text, (255, 255, 255), "rm", True)
        box = (right + x0 - lay.text * 0.5, lay.header * 0.1, lay.width, lay.header * 0.9)
        ImageDraw.Draw(image).rectangle(box, fill=INK)
        self.draw_text(image, (right, lay.header / 2), text, lay.text, (255, 255, 255), "rm", bold=True)

    def draw_ring(self, image: Image.Image, xy, radius: float) -> None:
        """A ring at the place the agents part: ink with a white halo, so it reads on any background."""
        draw = ImageDraw.Draw(image)
        width = max(3, int(self.layout.text / 8))
        for extra, colour in ((width, (255, 255, 255)), (0, INK)):
            r = radius + extra / 2
            draw.ellipse((xy[0] - r, xy[1] - r, xy[0] + r, xy[1] + r), outline=colour, width=width + extra)


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
        sheet.paste(thumb.resize((w, h), Image.Resampling.LANCZOS), ((n % columns) * w, (n // columns) * h))
    return sheet


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


def encode(renderer: ClipRenderer, out: str | os.PathLike, started: float) -> RenderResult:
    """Encode a renderer's frames as the clip, its poster and its contact sheet; the clip appears only once
    complete. ``started``: when the rendering began (perf_counter), for the result's render time."""
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
    if poster is None:
        partial.unlink(missing_ok=True)
        raise ValueError(f"{type(renderer).__name__} scheduled no frames: a clip needs at least one")
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
