"""Summaries for the renderer's tests, written by the search's own summary writer from scripted robots."""

from __future__ import annotations

import json

import pytest

from search.crowd.sim.scenarios import load_scenario
from tests.support.summaries import summary_from_simulation


@pytest.fixture(scope="session")
def shared_summary() -> dict:
    return summary_from_simulation(
        ["goal", "orca"], load_scenario("paper-bl-tr"), names=["SECRET-ALPHA", "SECRET-BETA"]
    )


@pytest.fixture
def summary_file(tmp_path, shared_summary):
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(shared_summary))
    return path
