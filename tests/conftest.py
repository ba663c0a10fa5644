"""Fixtures every test folder may use: a bundle of tiny real H.264 clips with the paper study's secret names, a
fresh database per test (SQLite, and PostgreSQL on a throwaway server), and the real app on it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.store.database import migrate
from app.web.main import create_app
from app.web.settings import ServerSettings
from search.core.workers import JOBS
from tests.support import postgres
from tests.support.survey import ADMIN_PASSWORD, AGENT_RANK, SECRET_NAMES, make_clip, study_text, write_bundle

# The suite's commands keep their work in one process (their default is one worker per core) unless a test asks
# for workers with --jobs: 2 cores shared by every test run at once, and the same results either way.
os.environ.setdefault(JOBS, "1")


@pytest.fixture(scope="session")
def clip_files(tmp_path_factory) -> list[Path]:
    folder = tmp_path_factory.mktemp("clips")
    files = [folder / "a.mp4", folder / "b.mp4"]
    make_clip(files[0], "testsrc")
    make_clip(files[1], "testsrc2")
    return files


@pytest.fixture(scope="session")
def bundle_dir(tmp_path_factory, clip_files) -> Path:
    names = SECRET_NAMES
    return write_bundle(
        tmp_path_factory.mktemp("bundle"),
        clip_files,
        schemes=[names["adaptive"], names["nfirst"]],
        scenarios=[names["paper-bl-tr"], names["paper-tl-br"]],
        agents=AGENT_RANK,
        example=(names["nfirst"], names["paper-code"], (names["lo"], names["hi"])),
    )


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.slow)])
def database_url(request, tmp_path) -> str:
    """A fresh database per test: a SQLite file, and an emptied PostgreSQL database (with the slow tests: the fast
    loop runs every database test on SQLite, `make test` on both)."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'survey.sqlite3'}"
    url = postgres.session_url(request.config)
    if url is None:
        pytest.fail(
            "no PostgreSQL binaries: `make test` and `make check` install them (or set "
            "FOIL_TEST_DATABASE_URL); the database tests run on both databases"
        )
    postgres.reset(url)
    return url


@pytest.fixture
def make_client(tmp_path, bundle_dir, database_url):
    """Build the real app on a migrated database; returns a function taking study-line changes and settings."""
    apps = []

    def build(changes: dict | None = None, **settings) -> TestClient:
        study = tmp_path / f"study-{len(apps)}.toml"
        study.write_text(study_text(**(changes or {})))
        migrate(database_url)
        config = {
            "bundle_dir": bundle_dir,
            "study_file": study,
            "database_url": database_url,
            "admin_password": ADMIN_PASSWORD,
            **settings,
        }
        app = create_app(ServerSettings(**config))
        apps.append(app)
        return TestClient(app, follow_redirects=True)

    yield build
    for app in apps:
        app.state.context.db.dispose()
