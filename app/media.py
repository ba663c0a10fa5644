"""Clips, served by content hash: the address says nothing about the agents, and it can be cached for good.

FileResponse answers Range requests with 206 (Safari will not play a video otherwise); only files listed in the
manifest, checked at start-up, can be reached, so no path from the request ever touches the file system. A single
range of at most SMALL_RANGE bytes (what players ask first, and whole short clips) is read at once on the event
loop, which from the file cache costs a fraction of FileResponse's thread-pool hops; anything else streams.
"""

from __future__ import annotations

import os
import re

from fastapi import HTTPException, Request
from fastapi.responses import FileResponse, Response
from starlette.routing import Route

CLIP_NAME = re.compile(r"^([0-9a-f]{64})\.mp4$")
CACHE = "public, max-age=31536000, immutable"  # the name is the content's hash: it never changes
SIMPLE_RANGE = re.compile(r"^bytes=(\d{1,15})-(\d{0,15})$")
SMALL_RANGE = 1 << 20


def _small_range(path, request: Request, headers: dict) -> Response | None:
    """The 206 reply to a simple, small Range request; None for FileResponse to handle."""
    match = SIMPLE_RANGE.match(request.headers.get("range", ""))
    if match is None or request.method != "GET" or "if-range" in request.headers:
        return None
    fd = os.open(path, os.O_RDONLY)
    try:
        size = os.fstat(fd).st_size
        start, end = int(match.group(1)), min(int(match.group(2) or size - 1), size - 1)
        if start > end or end - start >= SMALL_RANGE:
            return None  # unsatisfiable (416) or large: FileResponse
        body = os.pread(fd, end - start + 1, start)
    finally:
        os.close(fd)
    return Response(body, status_code=206, media_type="video/mp4", headers={
        **headers, "accept-ranges": "bytes", "content-range": f"bytes {start}-{start + len(body) - 1}/{size}"})


async def clip(request: Request):  # no blocking call: no thread pool needed
    match = CLIP_NAME.match(request.path_params["name"])
    path = request.app.state.context.bundle.paths.get(match.group(1)) if match else None
    if path is None:
        raise HTTPException(404, "No such clip.")
    headers = {"cache-control": CACHE, "etag": f'"{match.group(1)}"'}
    if request.headers.get("if-none-match") == headers["etag"]:
        return Response(status_code=304, headers=headers)
    return _small_range(path, request, headers) or FileResponse(path, media_type="video/mp4", headers=headers)


ROUTES = [Route("/clips/{name}", clip, methods=["GET", "HEAD"])]
