"""A representative vote that knows its strength: the sign-flip test of the states' weights (with equal weights,
the sign test: scipy's binomial test is the reference), states weighed as a viewer weighs them, drawing states until
the vote is decided or the budget fits no further state (never past it), the same result for the same seed, and the
warnings of a weak vote in the search's output, its run record, a bundle clip's audit and the representativeness
line."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest
from scipy.stats import binomtest

from app.formats import ClipAudit
from app.visible import Observer, Score, VisibleClip, World
from search.bundle.clips import vote_warnings
from search.bundle.representativeness import describe_representativeness
from search.core.contrast import Rollouts, visible_contrast, vote, weighted_test
from search.core.rollout import Tracker
from search.solvers.representative import Representative, RepresentativeConfig, clip_lengths, representative, weak_vote
from tests.solvers.test_representative import representative_search

HORIZON = 10


def roll_out(states: list[int], pushes: int, rng: np.random.Generator, tracker: Tracker) -> Rollouts:
    """Made-up rollouts: a state's ``lean`` (+1, -1, 0) is each of its contrasts (0: no agent looks better), so
    every state that leans weighs the same; each rollout takes 1 to HORIZON steps, the most when the lean is 2
    (then it counts as +1)."""
    rows = pushes + 1
    contrast, state, actions = [], [], []
    for index, lean in enumerate(states):
        steps = np.full(rows, HORIZON) if lean == 2 else rng.integers(1, HORIZON + 1, rows)
        tracker.count(int(steps.sum()))
        contrast += [float(np.sign(lean))] * rows
        state += [index] * rows
        actions += [np.zeros((int(n), 1, 2)) for n in steps]
    return Rollouts(np.array(state), actions, np.array(contrast))


def bound(config: RepresentativeConfig, seed: int = 0, flip: bool = False):
    """`roll_out` as a pool reads it for a search of ``config`` (every state leaning to the second agent where
    ``flip``), its rollouts' lengths drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    return lambda states, tracker: roll_out([-1] * len(states) if flip else states, config.pushes, rng, tracker)


def replay(candidates: list) -> list[tuple[float, dict]]:
    return [(float(np.sign(lean)), {"lean": int(lean), "steps": len(actions)}) for lean, actions in candidates]


def search(leans: list[int], budget: int = 10**6, seed: int = 0, **settings) -> tuple[list, dict, Tracker]:
    tracker = Tracker(budget, 1)
    config = RepresentativeConfig(states=len(leans), **({"pushes": 3, "batch_states": 2} | settings))
    chosen, record = representative(
        lambda n: bound(config, seed), lambda n: leans, tracker, config, lambda n: replay, [HORIZON]
    )
    return chosen, record, tracker


def sign_test(wins: int, losses: int) -> float:
    """The exact two-sided sign test (scipy's binomial test at one half); 1 without any state that leans."""
    return binomtest(wins, wins + losses).pvalue if wins + losses else 1.0


@pytest.mark.parametrize("wins, losses", [(3, 4), (0, 7), (6, 0), (5, 1), (10, 3), (0, 0), (13, 0)])
def test_equal_weights_are_tested_exactly_as_the_sign_test(wins, losses):
    weights = np.array([0.7] * wins + [-0.7] * losses + [0.0] * 5)  # states of weight 0 are left out
    assert weighted_test(weights) == pytest.approx(sign_test(wins, losses), rel=1e-12)


def test_beyond_thirteen_states_the_sign_flips_are_drawn_near_the_exact_test_and_the_same_every_time():
    weights = np.array([1.0] * 26 + [-1.0] * 12)
    assert weighted_test(weights) == pytest.approx(sign_test(26, 12), abs=0.006)  # 0.034; 9,999 flips
    assert weighted_test(weights) == weighted_test(weights.copy())


def highway_clip(events: tuple[str | None, str | None], speeds: tuple[float, float], crash_s: float = 4.0) -> float:
    """The visible contrast of a 20-s clip of two cars in a world judged by lasting, each showing its mean speed
    (km/h; 20 km/h look as plain as lasting against crashing at once)."""
    world = World(domain="road", rule="survival", score=Score("speed", "km/h", "higher", "mean", digits=0, span=20.0))
    outcomes = tuple({"event": e, "time": crash_s if e else None} for e in events)
    return visible_contrast(VisibleClip(("first", "second"), outcomes, (0.0, 0.0), 20.0, world=world, summed=speeds))


def test_a_crash_against_a_slower_car_that_drives_on_outweighs_a_small_speed_difference():
    """Half the states show the first car crash while the second drives on slower; the other half show both drive
    on, the first 7 km/h faster. A viewer picks the second car where the first crashes, almost surely, and barely
    prefers the first where it is a little faster: the vote is decided for the second car, though its states split
    evenly by which car each shows as better."""
    crash = highway_clip(("collision", None), (96.0, 80.0))
    faster = highway_clip((None, None), (87.0, 80.0))
    assert crash <= -1 and 0 < faster < 0.5
    observer = Observer()
    assert observer.expected_vote(crash) < -0.8 and 0 < observer.expected_vote(faster) < 0.4
    contrasts = [[crash, crash]] * 20 + [[faster, faster]] * 20 + [[0.0, 0.0]] * 20
    found = Rollouts(
        state=np.repeat(np.arange(60), 2), actions=[np.zeros((1, 1))] * 120, contrast=np.array(sum(contrasts, []))
    )
    result = vote(found, 60)
    record = result.record(found)
    assert (record["for_first"], record["for_second"], record["no_majority"]) == (20, 20, 20)
    assert result.direction == -1 and record["decided"] and record["p"] < 0.01
    assert sign_test(20, 20) == 1.0  # counting each state's lean alone says nothing


def test_a_decisive_vote_stops_drawing_once_decided_and_does_not_warn():
    _, record, _ = search([1] * 40)  # 40 states in batches of 2: 20 looks, each at 0.05 / 20
    assert record["states"] == 10 and record["stopped"] == "decided"  # 10 to 0: p = 1/512, the first below 0.0025
    assert record["decided"] and record["p"] == 1 / 512 and record["looks"] == 20 and record["drawn"] == 40
    assert weak_vote(record, ["a", "b"]) is None


def test_the_solver_keeps_drawing_until_the_vote_is_decided():
    leans = [1, -1, 0, 0, 1, -1, 0, 1] + [1] * 30
    _, record, _ = search(leans, batch_states=4)
    wins, losses = np.cumsum(np.array(leans) > 0), np.cumsum(np.array(leans) < 0)
    level = 0.05 / 10  # 38 states in batches of 4: 10 looks
    first = next(n for n in range(4, len(leans) + 1, 4) if sign_test(int(wins[n - 1]), int(losses[n - 1])) < level)
    assert record["states"] == first > 8 and record["stopped"] == "decided" and record["looks"] == 10
    assert (record["for_first"], record["for_second"]) == (wins[first - 1], losses[first - 1])


def test_agents_that_tie_on_most_states_give_a_weak_vote_that_warns():
    leans = [0, 0, 1, 0, -1, 0, 0, 1] * 4  # most states tie, the rest split 8 to 4: every drawn state votes
    chosen, record, _ = search(leans)
    assert record["stopped"] == "states" and record["states"] == 32 and not record["decided"]
    assert (record["for_first"], record["for_second"], record["no_majority"]) == (8, 4, 20)
    warning = weak_vote(record, ["lo", "hi"])
    assert warning.startswith(
        "weak vote: of 32 starting states, 8 showed lo as better, 4 hi and 20 neither (weighed by how plainly, p ="
    )
    assert "not below 0.05 / 16 looks" in warning
    assert "all 32 drawn states voted" in warning and chosen  # a weak vote still chooses its clip


def test_a_budget_that_surely_fits_few_states_plans_few_looks():
    """At most 40 steps a state, 200 surely fit 5: looks after 2 and 4 states and where it stops, each at 0.05 / 3
    (short rollouts then fit more states, in batches the budget still fits)."""
    _, record, tracker = search([1] * 40, budget=200)
    assert record["looks"] == 3 and record["stopped"] == "budget" and record["states"] > 5
    assert record["decided"] and record["p"] < 0.05 / 3 and tracker.steps <= 200


@pytest.mark.parametrize("lean", [1, 2])  # rollouts of 1 to HORIZON steps, or all of HORIZON (the most)
def test_the_budget_is_never_overspent(lean):
    leans = [lean] * 80
    per_state = 4 * HORIZON  # (pushes + 1) x horizon
    for budget in range(per_state, 20 * per_state, 37):
        _, record, tracker = search(leans, budget=budget, alpha=1e-30)  # so strict only the budget stops it
        assert tracker.steps <= budget and record["stopped"] == "budget"
        assert tracker.remaining < per_state  # it stopped only when no further state could fit
    with pytest.raises(ValueError, match="fits no starting state"):
        search(leans, budget=per_state - 1)


def test_the_same_seed_gives_the_same_vote_and_clips():
    leans = [1, 0, -1, 1, 1, 0, 1, -1, 1, 1, 0, 1] * 3
    first, second = search(leans, budget=900, seed=4), search(leans, budget=900, seed=4)
    assert first[0] == second[0] and first[1] == second[1] and first[2].steps == second[2].steps
    assert search(leans, budget=900, seed=5)[2].steps != first[2].steps  # the seed matters


def test_a_clip_audit_records_its_vote_only_where_there_is_one():
    plain = ClipAudit(shows="better", why="...")
    assert plain.model_dump() == {"shows": "better", "why": "..."}  # manifests without votes read as before
    vote = {"states": 8, "won": [3, 4], "no_majority": 1, "p": 1.0, "decided": False, "weight": -0.4}
    assert ClipAudit(shows="worse", why="...", vote=vote).model_dump()["vote"] == vote
    before = {"states": 8, "won": [3, 4], "no_majority": 1, "sign_test_p": 1.0, "decided": False}
    assert ClipAudit(shows="worse", why="...", vote=before).model_dump()["vote"] == {
        "states": 8,
        "won": [3, 4],
        "no_majority": 1,
        "p": 1.0,
        "decided": False,
    }  # a manifest written before the weights reads


def test_a_weak_vote_and_a_vote_against_the_ground_truth_warn_in_the_bundle_naming_agents():
    weak = {"states": 8, "won": [3, 4], "no_majority": 1, "p": 1.0, "decided": False, "weight": -0.2}
    [line] = vote_warnings(["hi", "med"], "med", weak)
    assert line.startswith(
        "weak vote: of 8 starting states, 3 showed hi as better, 4 med and 1 neither (weighed by how plainly, p = 1)"
    )
    assert [line.split(":")[0] for line in vote_warnings(["hi", "med"], "hi", weak)] == [
        "weak vote",
        "vote against the ground truth",
    ]
    decided_wrong = {"states": 9, "won": [0, 8], "no_majority": 1, "p": 2 / 2**8, "decided": True, "weight": -6.0}
    [line] = vote_warnings(["hi", "med"], "hi", decided_wrong)
    assert line.startswith("vote against the ground truth: it favours med, but hi is better")
    assert "Robot" not in line
    assert vote_warnings(["hi", "med"], "med", decided_wrong) == []  # decided, and for the better agent
    assert vote_warnings(["hi", "med"], None, decided_wrong) == []  # no ground truth to hold it to
    assert vote_warnings(["hi", "med"], "hi", None) == []  # not a representative clip
    plainer = {"states": 9, "won": [5, 3], "no_majority": 1, "p": 0.004, "decided": True, "weight": -1.5}
    [line] = vote_warnings(["hi", "med"], "hi", plainer)  # more states lean to hi, but med's are plainer
    assert line.startswith("vote against the ground truth: it favours med")


def test_the_representativeness_line_reports_its_test_and_calls_a_weak_vote_weak():
    report = {
        "agents": ["lo", "hi"],
        "scenario": "paper-bl-tr",
        "distribution": "training",
        "rollouts": 9,
        "first_looks_better": 0.6,
        "second_looks_better": 0.2,
        "no_difference": 0.2,
        "majority": 1,
        "percentile": 40.0,
        "disagrees": False,
        "agreeing_p": 0.9,
        "decided": False,
        "distribution_vote": {
            "direction": 1,
            "states": 16,
            "for_first": 5,
            "for_second": 3,
            "p": 0.73,
            "alpha": 0.05,
            "decided": False,
        },
    }
    line = describe_representativeness(report)
    assert line.startswith("representativeness paper-bl-tr")
    assert "(5 for lo, 3 for hi, weighed by how plainly), p = 0.73" in line
    assert line.endswith(
        "a weak vote (p not below 0.05): too few or too evenly split states to say which agent most "
        "starting states show as better"
    )
    report["distribution_vote"] |= {"for_first": 12, "for_second": 2, "p": 0.013, "decided": True}
    line = describe_representativeness(report)
    assert "(12 for lo, 2 for hi, weighed by how plainly), p = 0.013;" in line and "weak" not in line


def tiny_search(out, budget: str) -> int:
    return representative_search(out, budget=budget, states="4", top_k="1", batch_states=None)


def test_a_search_of_four_states_warns_of_its_weak_vote_and_repeats_itself(tmp_path, capsys):
    """Four states never decide (p >= 1/8); (pushes + 1) x horizon = 360 steps a state at most, so 1,500 fit them
    all and 300 none."""
    assert tiny_search(tmp_path / "a", "1500") == 0
    printed = capsys.readouterr().out
    run = json.loads((tmp_path / "a" / "run.json").read_text())
    vote = run["vote"]
    assert vote["states"] == 4 and vote["stopped"] == "states" and not vote["decided"] and run["sim_steps"] <= 1440
    assert f"warning: {tmp_path / 'a'}: {vote['warning']}" in printed and vote["warning"].startswith(
        "weak vote: of 4 starting states"
    )
    summary = json.loads((tmp_path / "a" / "summary-001.json").read_text())
    assert summary["solver"]["vote"] == {
        key: vote[key] for key in ("states", "for_first", "for_second", "no_majority", "weight", "p", "decided")
    }
    assert tiny_search(tmp_path / "b", "1500") == 0
    again = json.loads((tmp_path / "b" / "run.json").read_text())
    assert again["vote"] == vote and again["sim_steps"] == run["sim_steps"]
    assert (tmp_path / "b" / "summary-001.json").read_text() == (tmp_path / "a" / "summary-001.json").read_text()
    assert tiny_search(tmp_path / "c", "300") != 0
    assert "fits no starting state" in capsys.readouterr().err


@pytest.mark.parametrize("faster_kmh", [2.0, 7.0, 30.0])
def test_a_states_weight_is_the_share_of_bots_that_pick_each_agent(faster_kmh):
    """`Observer.expected_vote` is the bots' own rule: over 20,000 viewings, the share of perceptions that see the
    first car as better minus the share that see the second lies within 0.02 of it."""

    world = World(domain="road", rule="survival", score=Score("speed", "km/h", "higher", "mean", digits=0, span=20.0))
    clip = VisibleClip(
        ("first", "second"),
        ({"event": None}, {"event": None}),
        (0.0, 0.0),
        20.0,
        world=world,
        summed=(80.0 + faster_kmh, 80.0),
    )
    observer, rng = Observer(), random.Random(0)
    picks = [(lambda seen: seen["first"] > seen["second"])(observer.perceive(clip, rng)) for _ in range(20_000)]
    shares = sum(picks) / len(picks)
    assert 2 * shares - 1 == pytest.approx(observer.expected_vote(visible_contrast(clip)), abs=0.02)


def test_clip_lengths_double_up_to_the_longest():
    assert clip_lengths(20, 0) == [20] and clip_lengths(20, 20) == [20]
    assert (
        clip_lengths(20, 40) == [20, 40] and clip_lengths(20, 50) == [20, 40, 50] and clip_lengths(20, 30) == [20, 30]
    )


def test_a_weak_vote_tries_a_longer_clip_and_says_so():
    """At the study's length the states split evenly; twice as long, every state shows the second agent as better
    (as a crash that comes later in the drive would): the vote at the longer length decides, its clip is replayed at
    that length, every look of both lengths holds the test, and the warnings say the clip is longer and why."""

    replayed_at = []

    def replay_at(n: int):
        replayed_at.append(n)
        return replay

    leans = [1, -1] * 20
    config = RepresentativeConfig(states=len(leans), pushes=3, batch_states=4)
    tracker = Tracker(10**6, 1)
    chosen, record = representative(
        lambda n: bound(config, flip=n > HORIZON),
        lambda n: leans,
        tracker,
        config,
        replay_at,
        clip_lengths(HORIZON, 2 * HORIZON),
    )
    assert record["horizon"] == 2 * HORIZON and replayed_at == [2 * HORIZON] and record["decided"]
    first, longer = record["lengths"]
    assert (first["horizon"], first["for_first"], first["for_second"], first["decided"]) == (HORIZON, 20, 20, False)
    assert longer["horizon"] == 2 * HORIZON and longer["for_second"] == longer["states"] and longer["decided"]
    assert record["looks"] == 20  # 10 planned looks at each length, every one at 0.05 / 20
    for entry in record["lengths"]:
        entry["seconds"] = entry["horizon"] * 2.0
    [line] = Representative().warnings({"agents": ["lo", "hi"], "vote": record})
    assert line.startswith("longer clip: 40.0 s, not 20.0 s: at 20.0 s the vote was weak (20 lo, 20 hi, p = 0.99")
    assert line.endswith(f"at 40.0 s 0 lo, {longer['states']} hi, p < 0.001, decided")


def test_a_weak_vote_at_every_length_keeps_the_studys_length_and_lists_each():
    config = RepresentativeConfig(states=8, pushes=1, batch_states=4)
    _, record = representative(
        lambda n: bound(config),
        lambda n: [1, -1] * 4,
        Tracker(10**6, 1),
        config,
        lambda n: replay,
        [HORIZON, 2 * HORIZON],
    )
    assert record["horizon"] == HORIZON and not record["decided"] and len(record["lengths"]) == 2
    for entry in record["lengths"]:
        entry["seconds"] = float(entry["horizon"])
    warning = weak_vote(record, ["lo", "hi"])
    assert warning.endswith(
        "; at 20.0 s: 4 lo, 4 hi, p = 1: its clips may show either agent as the one that usually looks better"
    )
    assert "longer clip" not in " ".join(Representative().warnings({"agents": ["lo", "hi"], "vote": record}))
