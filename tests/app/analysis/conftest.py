"""Fixtures for the analysis tests. They build on the fixtures every folder has (the paper study with secret names,
a real database per test, the real app); the bundle here differs in two ways the bots need: every clip is a
different file (the bots know a clip by its address) and every clip has a summary.json saying what it shows."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.store.database import Database, migrate
from app.survey.study import parse_study
from tests.support.analysis import write_bot_bundle
from tests.support.survey import study_text


@pytest.fixture(scope="session")
def bundle_dir(tmp_path_factory) -> Path:
    return write_bot_bundle(tmp_path_factory.mktemp("analysis-clips"), tmp_path_factory.mktemp("analysis-bundle"))


@pytest.fixture
def paper_study(tmp_path):
    """The paper study (secret names) as a file and as parsed, with balanced assignment on no platform."""
    path = tmp_path / "study.toml"
    path.write_text(study_text(platform='"none"', assignment='"balanced"'))
    return path, parse_study(path.read_text())


@pytest.fixture
def survey_db(tmp_path):
    """A migrated SQLite file, for databases built by hand."""
    url = f"sqlite:///{tmp_path / 'hand.sqlite3'}"
    migrate(url)
    db = Database(url)
    yield db
    db.dispose()
