"""Clips, served by content hash: the address says nothing about the agents, and it can be cached for good.

FileResponse answers Range requests with 206 (Safari will not play a video otherwise); only files listed in the
manifest, checked at start-up, can be reached, so no path from the request ever touches the file system.
"""

from __future__ import annotations

import re

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, Response

from app.context import ContextDep

router = APIRouter()
CLIP_NAME = re.compile(r"^([0-9a-f]{64})\.mp4$")
CACHE = "public, max-age=31536000, immutable"  # the name is the content's hash: it never changes


@router.api_route("/clips/{name}", methods=["GET", "HEAD"])
async def clip(name: str, request: Request, ctx: ContextDep):  # no blocking call: no thread pool needed
    match = CLIP_NAME.match(name)
    path = ctx.bundle.paths.get(match.group(1)) if match else None
    if path is None:
        raise HTTPException(404, "No such clip.")
    headers = {"cache-control": CACHE, "etag": f'"{match.group(1)}"'}
    if request.headers.get("if-none-match") == headers["etag"]:
        return Response(status_code=304, headers=headers)
    return FileResponse(path, media_type="video/mp4", headers=headers)
