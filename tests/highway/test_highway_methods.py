"""The summary methods on the highway: found on the kernel, replayed in highway-env itself (`foil verify`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.solvers.disagreements import DisagreementsConfig
from search.solvers.highlights import HighlightsDivConfig
from search.solvers.runner import SearchJob, run_search, write_outputs
from search.solvers.summary import verify

pytestmark = pytest.mark.slow


def test_a_kernel_disagreement_is_one_in_highway_env_too(tmp_path):
    job = SearchJob(
        agents=("highway-med", "highway-hi"),
        scenario="highway-dense",
        solver="disagreements",
        budget=400,
        top_k=2,
        solver_config=DisagreementsConfig(horizon=6),
    )
    out = write_outputs(tmp_path, run_search(job))
    for path in sorted(out.glob("summary-*.json")):
        assert verify(path) == []  # rebuilt in highway-env
        data = json.loads(path.read_text())
        fork = data["follow"]["steps"]
        actions = [np.array(step["agent_actions"]) for step in data["steps"]]
        assert all(np.array_equal(a[0], a[1]) for a in actions[:fork])  # one car's actions for both, up to it
        # where the kernel saw them part (an action gap above 0.25; the actions lie in [-1, 1]), highway-env does too
        assert np.linalg.norm(actions[fork][0] - actions[fork][1]) > 0.25


def test_highlights_reels_of_highway_cars_verify(tmp_path):
    job = SearchJob(
        agents=("highway-lo", "highway-hi"),
        scenario="highway-dense",
        solver="highlights-div",
        budget=600,
        solver_config=HighlightsDivConfig(highlights=1, context=4, lookahead=2),
    )
    out = write_outputs(tmp_path, run_search(job))
    leaders = []
    for path in sorted(out.glob("summary-*.json")):
        assert verify(path) == []
        leaders.append(json.loads(path.read_text())["follow"]["leader"])
    assert leaders == [0, 1]
