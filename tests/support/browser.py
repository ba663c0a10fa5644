"""Debian's Chromium as the browser tests launch it, axe-core, where screenshots go, the page sizes tried, and a
live server with clips long enough for the viewing check."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.support.live_server import REPO, LiveServer
from tests.support.survey import ADMIN_PASSWORD, study_text, write_long_bundle

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
AXE = REPO / ".cache" / "axe" / "node_modules" / "axe-core" / "axe.min.js"
ARTIFACTS = REPO / "test-artifacts" / "browser"
DESKTOP = {"width": 1280, "height": 900}
PHONE = {"width": 360, "height": 740}
SERIOUS = {"serious", "critical"}  # axe impacts a page must not have


@contextmanager
def study_server(work: Path, bundle: Path, study: str) -> Iterator[LiveServer]:
    """`foil serve` of the study file text `study` over `bundle`, its study file and database in `work`."""
    (work / "study.toml").write_text(study)
    with LiveServer(
        bundle=bundle,
        study=work / "study.toml",
        database_url=f"sqlite:///{work / 'survey.sqlite3'}",
        workdir=work,
        admin_password=ADMIN_PASSWORD,
    ) as live:
        yield live


@contextmanager
def long_clip_server(work: Path, prepare: Callable[[Path], None] = lambda bundle: None) -> Iterator[LiveServer]:
    """`study_server` of the paper study (balanced, no platform) with clips of a few seconds; `prepare(bundle)` may
    add to the bundle before the server starts."""
    bundle = write_long_bundle(work / "clips", work / "bundle")
    prepare(bundle)
    with study_server(work, bundle, study_text(platform='"none"', assignment='"balanced"')) as live:
        yield live
