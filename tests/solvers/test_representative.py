"""The representative solver: its vote and selection on hand-made rollouts, and whole searches through the real
command line (determinism, `foil verify`, the vote in run.json, the refusals)."""

import json
import math

import numpy as np
import pytest

from search.cli import main
from search.core.contrast import Rollouts, Vote, vote
from search.solvers.representative import candidates, choose, how_representative


def rollouts(contrast_by_state: list[list[float]]) -> Rollouts:
    contrast = [c for row in contrast_by_state for c in row]
    state = [s for s, row in enumerate(contrast_by_state) for _ in row]
    return Rollouts(
        state=np.array(state), actions=[np.zeros((1, 1, 2))] * len(contrast), contrast=np.array(contrast, dtype=float)
    )


def test_states_weigh_in_by_their_expected_votes_and_candidates_agree_with_the_direction():
    found = rollouts([[-1.0, -0.5, 0.8], [-2.0, 0.0, 0.0], [3.0, 0.6, -0.4], [-0.9, -0.7, -0.3]])
    result = vote(found, 4)
    assert result.state_votes.tolist() == [-1, -1, 1, -1] and result.direction == -1
    # each state weighs in by its rollouts' mean expected vote, erf(contrast) at the bots' noise of 0.5
    assert result.state_weights[1] == pytest.approx(math.erf(-2.0) / 3)
    # the largest agreeing contrast (3.0 of state 2 disagrees; -0.4 comes from a state that voted the other way)
    assert candidates(found, result) == [3, 0, 9, 10, 1, 11]
    record = result.record(found)
    assert record["for_first"] == 1 and record["for_second"] == 3 and not record["tied"]
    assert record["agreeing_share"] == pytest.approx(7 / 12)


def test_a_tied_vote_is_reported_and_falls_back_to_the_largest_contrast():
    found = rollouts([[1.0, 0.5], [-1.0, -0.5], [0.0, 0.0]])
    result = vote(found, 3)
    assert result.state_votes.tolist() == [1, -1, 0] and result.direction == 0
    assert result.record(found)["tied"] and result.record(found)["agreeing_share"] is None
    assert candidates(found, result) == [0, 2, 1, 3]  # every non-tie rollout, largest contrast first


def test_a_replay_that_turns_into_a_tie_or_the_other_way_is_passed_over():
    replays = {0: -3.0, 1: 0.0, 2: 1.5, 3: -0.5}  # the exact replay of rollout 1 shows no difference, 2 flips

    def replayed(chosen):
        return [(replays[i], f"summary {i}") for i in chosen]

    assert choose([1, 2, 0, 3], -1, replayed, top_k=2) == [(0, "summary 0"), (3, "summary 3")]
    assert choose([1, 2], -1, replayed, top_k=1) == []  # no agreeing candidate survives
    assert choose([1, 2], 0, replayed, top_k=1) == [(2, "summary 2")]  # a tied vote takes either way


@pytest.mark.parametrize("ahead", [2, 3, 8])
def test_candidates_replayed_several_at_a_time_are_chosen_as_one_at_a_time(ahead):
    replays = {0: -3.0, 1: 0.0, 2: 1.5, 3: -0.5, 4: -1.0, 5: -2.0}
    asked = []

    def replayed(chosen):
        asked.append(list(chosen))
        return [(replays[i], i) for i in chosen]

    order = [1, 2, 0, 3, 4, 5]
    assert choose(order, -1, replayed, 2, ahead) == [(0, 0), (3, 3)]
    # in order, ``ahead`` at a time, until the chunk holding the second kept (the fourth candidate)
    assert asked == [order[start : start + ahead] for start in range(0, 4, ahead)]


def test_no_agreeing_candidate_leaves_an_empty_list_for_the_fallback():
    found = rollouts([[-1.0, -1.0], [-1.0, 2.0, 2.0, -1.0, -1.0]])
    result = Vote(np.array([-1, -1]), -1)
    assert candidates(found, result) == [0, 1, 2, 5, 6]
    assert candidates(found, Vote(np.array([1, 1]), 1)) == [3, 4]


def representative_search(out, seed="2", budget="4000", states="6", top_k="2", batch_states: str | None = "3"):
    """A small representative search of goal against orca from the training distribution, by the command line."""
    batch = ["--set", f"batch_states={batch_states}"] if batch_states else []
    return main(
        ["search", "--agents", "goal,orca", "--scenario", "training", "--solver", "representative", "--seed", seed,
         "--budget", budget, "--top-k", top_k, "--set", f"states={states}", "--set", "pushes=5", *batch,
         "--reward", "horizon_steps=60", "--out", str(out), "--quiet"]
    )  # fmt: skip


@pytest.fixture(scope="module")
def searched(tmp_path_factory):
    out = tmp_path_factory.mktemp("representative")
    assert representative_search(out) == 0
    return out


def test_a_representative_search_records_its_vote_and_the_chosen_starting_state(searched):
    run = json.loads((searched / "run.json").read_text())
    vote_record = run["vote"]
    assert run["scenario"] == "training" and vote_record["drawn"] == 6
    assert 1 <= vote_record["states"] <= 6 and vote_record["rollouts"] == 6 * vote_record["states"]
    assert vote_record["for_first"] + vote_record["for_second"] + vote_record["no_majority"] == vote_record["states"]
    summary = json.loads((searched / "summary-001.json").read_text())
    state = summary["solver"]["state"]
    assert summary["scenario"]["name"] == f"training#{state}" and summary["solver"]["name"] == "representative"
    assert vote_record["chosen"][0]["state"] == state
    contrast = summary["solver"]["search_contrast"]
    if vote_record["direction"]:  # the clip shows what the vote says
        assert np.sign(contrast) == vote_record["direction"]
    assert summary["scenario"]["world"]["human_num"] == 10
    assert summary["solver"]["budget_used"] == run["sim_steps"] <= 4000 and vote_record["states"] == 6


def test_the_budget_bounds_the_states_rolled_out(tmp_path):
    assert representative_search(tmp_path, budget="500") == 0
    run = json.loads((tmp_path / "run.json").read_text())
    # a state's rollouts take at most (pushes + 1) x horizon = 360 steps: the first batch is one state, then
    # another only if it still fits, so the budget is never overspent
    assert 1 <= run["vote"]["states"] < 3 and run["vote"]["stopped"] == "budget"
    assert run["sim_steps"] <= 500


def test_representative_summaries_verify_and_the_same_seed_gives_the_same_clip(searched, tmp_path, capsys):
    assert main(["verify", *(str(p) for p in sorted(searched.glob("summary-*.json")))]) == 0
    assert "reproduced exactly" in capsys.readouterr().out
    assert representative_search(tmp_path) == 0
    for name in ("summary-001.json", "summary-002.json"):
        assert (tmp_path / name).read_text() == (searched / name).read_text()


def test_the_representative_solver_and_a_distribution_are_refused_where_they_do_not_fit(tmp_path, capsys):
    assert (
        main(
            [
                "search",
                "--agents",
                "goal,orca",
                "--scenario",
                "training",
                "--solver",
                "mcts",
                "--out",
                str(tmp_path),
                "--quiet",
            ]
        )
        != 0
    )
    assert "distribution of starting states" in capsys.readouterr().err
    assert (
        main(
            [
                "search",
                "--agents",
                "goal,orca",
                "--scenario",
                "paper-bl-tr",
                "--solver",
                "representative",
                "--out",
                str(tmp_path),
                "--quiet",
            ]
        )
        != 0
    )
    assert "draws starting states from a distribution" in capsys.readouterr().err
    assert (
        main(
            [
                "search",
                "--agents",
                "goal,orca,social_force",
                "--scenario",
                "training",
                "--solver",
                "representative",
                "--out",
                str(tmp_path),
                "--quiet",
            ]
        )
        != 0
    )
    assert "two agents" in capsys.readouterr().err


def test_a_scenario_that_agrees_as_often_as_the_states_sits_mid_percentile_and_a_few_rollouts_decide_nothing():
    drawn = rollouts([[1.0] * 9] * 4)  # 4 states, all vote for the first
    fixed = [("same", rollouts([[1.0] * 9])), ("few", rollouts([[-1.0, 1.0, -1.0]])), ("other", rollouts([[-1.0] * 9]))]
    same, few, other = how_representative(drawn, 4, fixed)
    assert same["percentile"] == 50.0 and not same["disagrees"]  # ties with every state count half
    assert few["disagrees"] and not few["decided"] and few["agreeing_p"] == 0.5  # 1 of 3 agree: no evidence
    assert other["disagrees"] and other["decided"] and other["agreeing_p"] == 1 / 2**9 and other["percentile"] == 0
