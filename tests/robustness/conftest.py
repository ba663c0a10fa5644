"""The robustness tests use the analysis tests' bundle: every clip its own file with a summary, as the bots need."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.support.analysis import write_bot_bundle


@pytest.fixture(scope="session")
def bundle_dir(tmp_path_factory) -> Path:
    return write_bot_bundle(tmp_path_factory.mktemp("robustness-clips"), tmp_path_factory.mktemp("robustness-bundle"))
