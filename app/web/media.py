"""Clips, served by content hash: the address says nothing about the agents, and it can be cached for good.

FileResponse answers Range requests with 206 (Safari will not play a video otherwise); only files listed in the
manifest, checked at start-up, can be reached, so no path from the request ever touches the file system. Clips of
at most SMALL_CLIP bytes are kept in memory once read (up to KEPT_BYTES in all, per process), and a single range
of theirs (what players ask first, and whole short clips) is answered from there on the event loop: opening and
reading the file for every request costs more than the rest of the reply, and the thread pool that
FileResponse reads in may be full of database work. Anything else streams from the file.
"""

from __future__ import annotations

import re
from pathlib import Path

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, Response

router = APIRouter()
CLIP_NAME = re.compile(r"^([0-9a-f]{64})\.mp4$")
CACHE = "public, max-age=31536000, immutable"  # the name is the content's hash: it never changes
SIMPLE_RANGE = re.compile(r"^bytes=(\d{1,15})-(\d{0,15})$")
SMALL_CLIP = 1 << 20
KEPT_BYTES = 64 << 20


class KeptClips:
    """The contents of small clips, read once each while they fit in `limit` bytes in all."""

    clips: dict[Path, bytes]

    def __init__(self, limit: int = KEPT_BYTES) -> None:
        self.limit, self.size, self.clips = limit, 0, {}
        self.streamed: set[Path] = set()  # too large to keep: asked about once, not on every request

    def get(self, path: Path) -> bytes | None:
        data = self.clips.get(path)
        if data is None and path not in self.streamed:
            if path.stat().st_size <= min(SMALL_CLIP, self.limit - self.size):
                data = self.clips[path] = path.read_bytes()
                self.size += len(data)
            else:
                self.streamed.add(path)
        return data


def _small_range(data: bytes, request: Request, headers: dict[str, str]) -> Response | None:
    """The 206 reply to a simple Range request of a kept clip; None for FileResponse to handle."""
    match = SIMPLE_RANGE.match(request.headers.get("range", ""))
    if match is None or request.method != "GET" or "if-range" in request.headers:
        return None
    size = len(data)
    start, end = int(match.group(1)), min(int(match.group(2) or size - 1), size - 1)
    if start > end:
        return None  # unsatisfiable: FileResponse answers 416
    return Response(
        data[start : end + 1],
        status_code=206,
        media_type="video/mp4",
        headers={**headers, "accept-ranges": "bytes", "content-range": f"bytes {start}-{end}/{size}"},
    )


@router.api_route("/clips/{name}", methods=["GET", "HEAD"])
async def clip(name: str, request: Request) -> Response:  # no blocking call on the usual path: no thread pool needed
    match = CLIP_NAME.match(name)
    path = request.app.state.context.bundle.paths.get(match.group(1)) if match else None
    if match is None or path is None:
        raise HTTPException(404, "No such clip.")
    headers = {"cache-control": CACHE, "etag": f'"{match.group(1)}"'}
    if request.headers.get("if-none-match") == headers["etag"]:
        return Response(status_code=304, headers=headers)
    data = request.app.state.context.kept_clips.get(path)
    return (data is not None and _small_range(data, request, headers)) or FileResponse(
        path, media_type="video/mp4", headers=headers
    )
