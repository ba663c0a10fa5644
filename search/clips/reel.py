"""Reels: several summaries' clips joined into one video, the way HIGHLIGHTS and Agent Disagreements show a summary
(a few short moments of an agent's behaviour, one after the other).

Each segment is rendered by the domain's own renderer into a temporary folder and the clips are joined by
ffmpeg's concat demuxer: copied as they are when they share size and frame rate (the usual case: one domain, one
set of render options), else re-encoded with the clips' encoder settings, each padded to the largest size. A short
card ("Moment 2 of 3") between segments tells a viewer where one moment ends; it names no world, so any domain's
reel reads the same. Like a clip, the reel appears only once complete.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

from search.clips.render import (
    BACKGROUND,
    INK,
    MIN_PHONE_TEXT,
    PHONE_WIDTH,
    RenderOptions,
    RenderResult,
    encoder_args,
    h264_writer,
    side_paths,
    text_stamp,
)

CARD_SECONDS = 0.5  # of video each card between two segments shows


def card(text: str, width: int, height: int) -> Image.Image:
    """A separator card: ``text`` large and centred on the clips' background."""
    image = Image.new("RGB", (width, height), BACKGROUND)
    size = 2 * int(np.ceil(MIN_PHONE_TEXT * width / PHONE_WIDTH))
    stamp, (x0, y0) = text_stamp(text, size, INK, "mm", True)
    image.paste(stamp, (round(width / 2 + x0), round(height / 2 + y0)), stamp)
    return image


def _write_still(image: Image.Image, frames: int, fps: int, out: Path, options: RenderOptions) -> None:
    """``frames`` frames of one image, encoded as the clips are."""
    writer = h264_writer(out, image.size, fps, options)
    for _ in range(frames):
        writer.send(image.tobytes())
    writer.close()


def _stacked(sheets: list[Path]) -> Image.Image:
    """The segments' contact sheets one above the other, left-aligned on the background."""
    images = [Image.open(path).convert("RGB") for path in sheets]
    stack = Image.new("RGB", (max(i.width for i in images), sum(i.height for i in images)), BACKGROUND)
    top = 0
    for image in images:
        stack.paste(image, (0, top))
        top += image.height
    return stack


def render_reel(
    segments: list[Path],
    out: Path,
    render_segment: Callable[[Path, Path], RenderResult],
    options: RenderOptions | None = None,
) -> RenderResult:
    """One H.264 clip of ``segments`` (summary files) in order, each rendered by ``render_segment(summary,
    clip)`` (a domain's renderer with its agent numbers and options), each announced by a card ("Moment 2 of 3")
    where there are several; the
    poster is the first segment's, the contact sheet the segments' sheets stacked. ``options`` gives the cards'
    encoder settings (crf, preset); use the segments' own."""
    import imageio_ffmpeg

    started = time.perf_counter()
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise ValueError(f"the reel must be an .mp4 file, got {out}")
    if not segments:
        raise ValueError("a reel needs at least one segment")
    options = options or RenderOptions()
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(f".{out.stem}.partial.mp4")
    with tempfile.TemporaryDirectory(prefix=f".{out.stem}.", dir=out.parent) as folder:
        work = Path(folder)
        results = [render_segment(Path(s), work / f"segment-{n}.mp4") for n, s in enumerate(segments)]
        rates = [round(r.frames / r.seconds) for r in results]  # a clip's frame rate is a whole number
        fps, width, height = rates[0], max(r.width for r in results), max(r.height for r in results)
        same = len(set(rates)) == 1 and all((r.width, r.height) == (width, height) for r in results)
        card_frames = round(CARD_SECONDS * fps)
        parts, frames, seconds = [], 0, 0.0
        for n, result in enumerate(results):
            if len(results) > 1:  # each moment announced, the first too: it starts partway into a run
                still = work / f"card-{n}.mp4"
                _write_still(card(f"Moment {n + 1} of {len(results)}", width, height), card_frames, fps, still, options)
                parts.append(still.name)
                frames, seconds = frames + card_frames, seconds + card_frames / fps
            parts.append(Path(result.clip).name)
            frames, seconds = frames + result.frames, seconds + result.seconds
        (work / "parts.txt").write_text("".join(f"file '{name}'\n" for name in parts))
        if same:
            coding = ["-c", "copy", "-movflags", "+faststart", "-map_metadata", "-1"]
        else:  # pad every part to the largest size, at the first segment's frame rate
            pad = f"pad={width}:{height}:(ow-iw)/2:(oh-ih)/2:color=white,fps={fps},setsar=1"
            coding = ["-vf", pad, "-r", str(fps), "-c:v", "libx264", "-pix_fmt", "yuv420p", *encoder_args(options)]
        command = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-hide_banner", "-loglevel", "error", "-f", "concat"]
        try:
            subprocess.run([*command, "-i", "parts.txt", *coding, str(partial.resolve())], cwd=work, check=True)
        except BaseException:
            partial.unlink(missing_ok=True)
            raise
        if not same:
            frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(partial))
        partial.replace(out)
        poster, sheet = side_paths(out)
        shutil.copyfile(results[0].poster, poster)
        _stacked([Path(r.sheet) for r in results]).save(sheet, optimize=True)
    return RenderResult(
        clip=out,
        poster=poster,
        sheet=sheet,
        frames=frames,
        seconds=seconds,
        width=width,
        height=height,
        render_s=time.perf_counter() - started,
    )
