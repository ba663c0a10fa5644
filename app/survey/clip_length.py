"""A clip's playing time and picture size, read from the MP4 file itself (its `moov` box): what the participant's
browser plays, whatever the manifest says. The server holds a clip's answers until the participant has had the
screen for at least this long, and the plan records it so the export can compare time on screen with it.

Reads only box headers: a clip written with `-movflags +faststart` has `moov` in its first kilobytes.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class ClipShape:
    ms: int  # playing time in milliseconds
    width: int
    height: int


CONTAINERS = {b"moov", b"trak", b"mdia", b"minf", b"stbl", b"edts"}


def _boxes(data: bytes, start: int, end: int) -> Iterator[tuple[bytes, int, int]]:
    at = start
    while at + 8 <= end:
        size, kind = struct.unpack(">I4s", data[at : at + 8])
        header = 8
        if size == 1:
            size, header = struct.unpack(">Q", data[at + 8 : at + 16])[0], 16
        elif size == 0:
            size = end - at
        if size < header or at + size > end:
            return
        yield kind, at + header, at + size
        at += size


def _moov(path: Path) -> bytes:
    """The `moov` box's contents, wherever it lies in the file."""
    with path.open("rb") as handle:
        offset = 0
        while True:
            handle.seek(offset)
            head = handle.read(16)
            if len(head) < 8:
                raise ValueError(f"{path}: no moov box (not an MP4 file?)")
            size, kind = struct.unpack(">I4s", head[:8])
            header = 8
            if size == 1:
                size, header = struct.unpack(">Q", head[8:16])[0], 16
            elif size == 0:
                size = path.stat().st_size - offset
            if size < header:
                raise ValueError(f"{path}: malformed MP4 box at byte {offset}")
            if kind == b"moov":
                handle.seek(offset + header)
                return handle.read(size - header)
            offset += size


@functools.cache
def clip_shape(path: str | Path) -> ClipShape:
    """Duration (the movie header's) and the first video track's picture size."""
    data = _moov(Path(path))
    ms, width, height = None, 0, 0

    def walk(start: int, end: int) -> None:
        nonlocal ms, width, height
        for kind, body, stop in _boxes(data, start, end):
            if kind == b"mvhd":
                version = data[body]
                if version == 1:
                    timescale, duration = struct.unpack(">IQ", data[body + 20 : body + 32])
                else:
                    timescale, duration = struct.unpack(">II", data[body + 12 : body + 20])
                ms = round(1000 * duration / timescale) if timescale else 0
            elif kind == b"tkhd" and not width:
                w, h = struct.unpack(">II", data[stop - 8 : stop])
                width, height = w >> 16, h >> 16
            elif kind in CONTAINERS:
                walk(body, stop)

    walk(0, len(data))
    if ms is None:
        raise ValueError(f"{path}: no movie header (mvhd) in its moov box")
    return ClipShape(ms=ms, width=width, height=height)
