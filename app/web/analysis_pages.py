"""Admin pages of the analysis: the report (`foil report` for the served study, computed on request) and the
downloads (long.csv streamed; the whole export as a zip). Behind the same login as the other admin pages."""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import FileResponse, HTMLResponse, StreamingResponse
from starlette.background import BackgroundTask

from app.analysis.exclusions import ExclusionRules
from app.analysis.export_csv import export_study, long_csv_chunks
from app.analysis.report import render_report, tally_study
from app.web.admin_pages import Admin
from app.web.context import ContextDep

router = APIRouter(prefix="/admin", dependencies=[Admin])
# The report inlines its styles and SVG figures and has no scripts: allow exactly that, on this page only.
REPORT_POLICY = (
    "default-src 'none'; style-src 'unsafe-inline'; img-src data:; base-uri 'none'; "
    "form-action 'none'; frame-ancestors 'none'"
)


# Numbers from the query string: finite and in range, or the request is refused with a message naming the field.
MinSeconds = Annotated[float | None, Query(ge=0, le=7 * 24 * 3600, allow_inf_nan=False)]
MedianFraction = Annotated[float, Query(ge=0, lt=1, allow_inf_nan=False)]


def _rules(min_seconds: float | None, median_fraction: float) -> ExclusionRules:
    try:
        return ExclusionRules(min_seconds=min_seconds, median_fraction=median_fraction)
    except ValueError as error:
        raise HTTPException(400, str(error)) from None


@router.get("/report")
def report_page(
    ctx: ContextDep, min_seconds: MinSeconds = None, median_fraction: MedianFraction = 1 / 3
) -> HTMLResponse:
    data = tally_study(ctx.db, ctx.study, _rules(min_seconds, median_fraction))
    data.audits = {clip.id: clip.audit.model_dump() for clip in ctx.bundle.clips.values() if clip.audit is not None}
    html = render_report(data)
    return HTMLResponse(html, headers={"content-security-policy": REPORT_POLICY})


@router.get("/export.csv")
def long_csv(ctx: ContextDep) -> StreamingResponse:
    filename = f"{ctx.study.study.id}-long.csv"
    return StreamingResponse(
        long_csv_chunks(ctx.db, ctx.study),
        media_type="text/csv; charset=utf-8",
        headers={"content-disposition": f'attachment; filename="{filename}"'},
    )


@router.get("/export.zip")
def export_zip(
    ctx: ContextDep, min_seconds: MinSeconds = None, median_fraction: MedianFraction = 1 / 3
) -> FileResponse:
    """`foil export` into a temporary folder, zipped; both are deleted once the download has been sent."""
    rules = _rules(min_seconds, median_fraction)
    folder = Path(tempfile.mkdtemp(prefix="foil-export-"))
    try:
        name = f"{ctx.study.study.id}-export"
        export_study(ctx.db, ctx.study, folder / name, rules)
        archive = folder / f"{name}.zip"
        with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_DEFLATED) as zipped:
            for path in sorted((folder / name).iterdir()):
                zipped.write(path, f"{name}/{path.name}")
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return FileResponse(
        archive,
        media_type="application/zip",
        filename=archive.name,
        background=BackgroundTask(shutil.rmtree, folder, ignore_errors=True),
    )
