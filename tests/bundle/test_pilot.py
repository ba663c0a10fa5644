"""`foil bundle --pilot`: the representative scheme's vote as the build's search takes it, before the build, with
what would decide a weak one, and each shown pair's ground truth on a few paired episodes; on the tiny track of
tests/gym/test_any_world.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.bundle.build import prepare
from search.bundle.pilot import pilot_votes, states_needed
from search.bundle.searches import search_pools
from search.cli import main
from search.solvers.reward import RewardConfig
from search.solvers.runner import run_search
from tests.gym.test_any_world import FAST, SLOW, world  # noqa: F401  (the researcher's folder)


def test_the_pilot_votes_as_the_builds_search_does(world):  # noqa: F811
    [search] = [s for s in prepare("study.toml").searches if s.solver == "representative"]
    built = json.loads(run_search(search)["run.json"])["vote"]
    [pool] = search_pools([search])
    [(_, _, _, result, piloted)] = pilot_votes(search, pool, [RewardConfig.from_dict(search.reward_settings).horizon])
    weights = result.state_weights
    same = ("states", "for_first", "for_second", "no_majority", "weight", "p", "decided", "looks", "stopped")
    assert {key: piloted[key] for key in same} == {key: built[key] for key in same}
    assert len(weights) == built["states"]


def test_the_pilot_says_each_vote_and_each_pairs_truth_and_builds_nothing(world, capsys):  # noqa: F811
    assert main(["bundle", "study.toml", "--out", "piloted", "--pilot", "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"pilot representative {FAST} vs {SLOW} from track-starts.toml (400 steps, seed 0):"
    assert lines[1].startswith("  at ") and "(the study's): " in lines[1] and "starting states" in lines[1]
    assert lines[-1].startswith(f"pilot ground truth {FAST} vs {SLOW} on 4 paired episodes: ")
    assert not (world / "piloted" / "manifest.json").exists() and not (world / "piloted" / "clips").exists()


@pytest.mark.parametrize("lean", [0.05, 0.1, 0.2])
def test_the_states_a_lean_needs_shrink_as_it_grows_and_a_simulation_agrees(lean):
    """A vote of the suggested number of states, each weighing in at ``lean`` plus noise, decides at its level about
    as often as `POWER` says (the normal approximation of the sign-flip test), and needs fewer states for a larger
    lean."""
    from search.core.contrast import weighted_test

    rng = np.random.default_rng(0)
    pilot = rng.normal(lean, 0.5, 64)
    needed = states_needed(pilot, looks=1)
    decided = [
        weighted_test(rng.normal(float(np.mean(pilot)), float(np.std(pilot, ddof=1)), needed)) < 0.05
        for _ in range(100)
    ]
    assert 0.65 <= np.mean(decided) <= 0.95
    assert states_needed(np.zeros(8), 1) is None
    assert states_needed(np.full(8, 0.3), 1) == 6  # alike: six of six decide the sign test (p = 1/32 < 0.05)


def test_a_weak_vote_is_said_with_what_would_decide_it(world, capsys):  # noqa: F811
    """Two states never decide a vote (p >= 1/2): the pilot says so at the study's length, tries longer clips the
    budget fits, and names roughly how many states would decide it, or that none can."""
    study = (world / "study.toml").read_text().replace("states = 4, pushes = 2 }", "states = 2, pushes = 2 }")
    (world / "study.toml").write_text(study)
    assert main(["bundle", "study.toml", "--out", "piloted", "--pilot", "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "(the study's): weak: of 2 starting states" in lines[1]
    advice = next(line for line in lines if line.startswith("  -> "))
    assert "about 6 states would at" in advice  # both states show the slow runner as better, alike
