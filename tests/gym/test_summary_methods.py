"""Agent Disagreements, HIGHLIGHTS and HIGHLIGHTS-DIV on the tiny corridor environment (tests/gym/corridor.py),
with discrete and continuous agents, and their published formulas on hand-computed values."""

from __future__ import annotations

import json

import numpy as np
import pytest

from search.core.domain import domain_for
from search.core.rollout import Tracker
from search.solvers.disagreements import Disagreement, DisagreementsConfig, find, last_state, top_k
from search.solvers.episodes import draw_episodes
from search.solvers.follow import Follow
from search.solvers.highlights import HighlightsConfig, Moment, q_importance, select
from search.solvers.runner import SearchJob, run_search, write_outputs
from search.solvers.solver import solver_named
from search.solvers.summary import verify
from tests.gym.corridor import dodging, straight
from tests.gym.test_gym_problem import BOX, DISCRETE, scenario_file

VALUED = ("tests.gym.test_summary_methods:valued_straight", "tests.gym.test_summary_methods:valued_dodging")
Q_AGENT = ("tests.gym.test_summary_methods:q_straight", "tests.gym.corridor:dodging_moves")


class Valued:
    """A corridor agent with a value of its own: how close the walker is to the goal."""

    def __init__(self, act):
        self.act = act

    @staticmethod
    def value(observations):
        return -np.abs(5.0 - observations[:, 0])


class QMoves:
    """Walks straight (action 1) with hand-made action values: the spread grows as the obstacle comes near."""

    @staticmethod
    def act(observations):
        return np.ones(len(observations), dtype=np.int64)

    @staticmethod
    def action_values(observations):
        near = 1.0 / (0.1 + np.abs(observations[:, 2] - observations[:, 0]))
        return np.stack([np.zeros(len(observations)), near, -near, 0.5 * near, -0.5 * near], axis=1)


valued_straight = Valued(straight)
valued_dodging = Valued(dodging)
q_straight = QMoves()


def test_published_importance_formulas_on_hand_computed_values():
    values = np.array([[1.0, 5.0, 3.0], [2.0, 2.5, -1.0]])
    assert q_importance(values, "max_min").tolist() == [4.0, 3.5]  # HIGHLIGHTS: max Q - min Q
    assert q_importance(values, "second_best").tolist() == [2.0, 0.5]  # max Q - second best
    # last_state: values[x, y] = agent x's value of the state agent y's branch ended in
    v = np.array([[[1.0], [4.0]], [[2.0], [0.5]]])
    # A's end: 1 * ratio + 2, B's end: 4 * ratio + 0.5
    assert last_state(v, 1.0).tolist() == [abs(3.0 - 4.5)]
    assert last_state(v, 2.0).tolist() == [abs(4.0 - 8.5)]


def test_overlap_limit_skips_then_fills():
    found = [
        Disagreement(episode=0, step=10, branch=5, importance=3.0),
        Disagreement(episode=0, step=12, branch=5, importance=2.0),  # shares 8 of A's steps with the first
        Disagreement(episode=1, step=12, branch=5, importance=1.5),  # another episode: no overlap
        Disagreement(episode=0, step=30, branch=5, importance=1.0),
    ]
    chosen = top_k(found, 3, overlap=3, half=5)
    assert [(d.episode, d.step) for d in chosen] == [(0, 10), (1, 12), (0, 30)]
    filled = top_k(found, 4, overlap=3, half=5)
    assert [(d.episode, d.step) for d in filled][-1] == (0, 12)  # skipped, then filled in when too few pass
    assert [(d.episode, d.step) for d in top_k(found, 2, overlap=20, half=5)] == [(0, 10), (0, 12)]


def moment(episode, step, importance, features):
    return Moment(episode, step, 40, importance, np.asarray(features, dtype=float))


def test_highlights_gap_and_the_div_filter():
    moments = [
        moment(0, 10, 5.0, [0.0, 0.0]),
        moment(0, 14, 4.0, [3.0, 3.0]),  # too close in time to the first (gap 10)
        moment(1, 10, 3.0, [0.01, 0.0]),  # another episode, but the same situation as the first
        moment(1, 30, 2.0, [-3.0, 3.0]),
    ]
    plain = select(moments, HighlightsConfig(highlights=3, gap=10))
    assert [(m.episode, m.step) for m in plain] == [(0, 10), (1, 10), (1, 30)]  # in episode order
    div = select(moments, HighlightsConfig(highlights=3, gap=10, diversity=0.5))
    assert [(m.episode, m.step) for m in div] == [(0, 10), (1, 30)]  # the look-alike is left out


def test_a_later_reel_shows_the_next_moments_the_selection_keeps():
    moments = [
        moment(0, 10, 5.0, [0.0, 0.0]),
        moment(0, 14, 4.0, [3.0, 3.0]),  # too close in time to the first (gap 10), in any reel
        moment(1, 10, 3.0, [0.01, 0.0]),
        moment(1, 30, 2.0, [-3.0, 3.0]),
    ]
    second = select(moments, HighlightsConfig(highlights=2, gap=10), earlier=1)
    assert [(m.episode, m.step) for m in second] == [(1, 30)]  # the first reel's are (0, 10) and (1, 10)
    with pytest.raises(ValueError, match="hold 2 moments far enough apart, too few for 3 reels of 1: give more"):
        select(moments, HighlightsConfig(highlights=1, gap=10, diversity=0.5), earlier=2)


def corridor_groups(agents, discrete, tmp_path, count=2):
    where = scenario_file(tmp_path, discrete)
    domain = domain_for(agents, where)
    state = domain.state(where, {})
    return draw_episodes(
        lambda s: domain.coupled(agents, s, {"horizon": 40}), [state], count, np.random.default_rng(0)
    )[0]


@pytest.mark.parametrize("agents", [BOX, DISCRETE])
def test_disagreements_are_the_steps_where_the_agents_would_act_differently(agents, tmp_path):
    group = corridor_groups(agents, agents == DISCRETE, tmp_path)
    config = DisagreementsConfig(threshold=0.25)
    found = find(group, Tracker(10**6, 5), config, 10**6)
    flagged = {(t, row) for t, _, rows in found for row in rows}
    assert flagged  # the dodging agent steps aside where the straight one walks on
    # replay A's episodes with B asked, step by step: the flags are exactly the steps where they differ
    problem = group.coupled.problem
    problem.reset(len(group.env))
    problem.override = Follow(0, 10**9)
    running = np.ones(len(group.env), dtype=bool)
    for t in range(group.env.shape[1] - config.horizon // 2 + 1):
        _, terminal = problem.step(group.env[:, t])
        a, b = problem.proposed
        differ = (a != b) if agents == DISCRETE else (np.linalg.norm(np.asarray(a) - b, axis=1) > 0.25)
        for row in range(len(group.env)):
            assert ((t, row) in flagged) == bool(running[row] and differ[row])
        # following: every instance is where the leader is
        positions = [[problem.adapter.position(i.env).tolist() for i in r] for r in problem.rows]
        assert all(p[0] == p[1] for p in positions)
        running &= ~terminal


@pytest.mark.parametrize("agents", [BOX, DISCRETE, VALUED])
def test_disagreement_clips_fork_where_they_disagree_and_verify(agents, tmp_path):
    where = scenario_file(tmp_path, agents == DISCRETE)
    job = SearchJob(
        agents=agents,
        scenario=where,
        solver="disagreements",
        budget=2_000,
        top_k=3,
        reward_settings={"horizon": 40},
        solver_config=DisagreementsConfig(horizon=6),
    )
    files = run_search(job)
    assert _same_but_times(files, run_search(job))
    record = json.loads(files["run.json"])["method"]
    assert record["importance"] == ("last_state" if agents == VALUED else "outcome")
    out = write_outputs(tmp_path / "out", files)
    summaries = sorted(out.glob("summary-*.json"))
    assert summaries
    for path in summaries:
        assert verify(path) == []
        data = json.loads(path.read_text())
        fork_at, (first, last) = data["follow"]["steps"], data["window"]
        assert data["follow"]["leader"] == 0 and first == max(0, fork_at - 3) and last == len(data["steps"])
        robots = [step["agent_positions"] for step in data["steps"]]
        assert all(r[0] == r[1] for r in robots[:fork_at])  # one shared history up to the fork
    importances = [c["importance"] for c in record["chosen"]]
    assert importances == sorted(importances, reverse=True)
    tampered = json.loads(summaries[0].read_text())
    tampered["follow"]["steps"] += 1
    summaries[0].write_text(json.dumps(tampered))
    assert verify(summaries[0])


def _same_but_times(first: dict, second: dict) -> bool:
    """Equal outputs apart from run.json's wall times."""
    drop = ("wall_s", "search_wall_s", "steps_per_s")
    a, b = json.loads(first["run.json"]), json.loads(second["run.json"])
    return {k: v for k, v in first.items() if k != "run.json"} == {
        k: v for k, v in second.items() if k != "run.json"
    } and {k: v for k, v in a.items() if k not in drop} == {k: v for k, v in b.items() if k not in drop}


@pytest.mark.parametrize(
    ("agents", "solver", "importance"),
    [
        (BOX, "highlights", "rollouts"),
        (DISCRETE, "highlights-div", "rollouts"),
        (Q_AGENT, "highlights", "max_min"),
    ],
)
def test_highlights_reels_show_each_agent_alone_and_verify(agents, solver, importance, tmp_path):
    where = scenario_file(tmp_path, agents != BOX)
    job = SearchJob(
        agents=agents,
        scenario=where,
        solver=solver,
        budget=4_000,
        reward_settings={"horizon": 40},
        solver_config=solver_named(solver).config_class(highlights=2, context=6, gap=6, lookahead=3),
    )
    files = run_search(job)
    assert _same_but_times(files, run_search(job))
    record = json.loads(files["run.json"])["method"]
    assert record["agent_0"]["importance"] == importance
    out = write_outputs(tmp_path / "out", files)
    reels = {}
    for path in sorted(out.glob("summary-*.json")):
        assert verify(path) == []
        data = json.loads(path.read_text())
        leader = data["follow"]["leader"]
        assert data["follow"]["steps"] == len(data["steps"]) and data["solver"]["reel"] == agents[leader]
        # the reel's agent alone
        assert all(step["agent_positions"][0] == step["agent_positions"][1] for step in data["steps"])
        first, last = data["window"]
        assert last - first <= 6
        reels.setdefault(leader, []).append(data["solver"]["state_step"])
    assert set(reels) == {0, 1} and all(len(steps) <= 2 for steps in reels.values())
    if importance == "max_min":  # the chosen states are those of the largest hand-made spread: nearest the obstacle
        chosen = record["agent_0"]["chosen"]
        assert chosen and all(c["importance"] >= 1.0 for c in chosen)


also_straight = Valued(straight)


def test_agents_that_never_disagree_get_the_first_episode_each_on_its_own(tmp_path):
    agents = ("tests.gym.corridor:straight", "tests.gym.test_summary_methods:also_straight")
    job = SearchJob(
        agents=agents,
        scenario=scenario_file(tmp_path),
        solver="disagreements",
        budget=500,
        reward_settings={"horizon": 40},
        solver_config=DisagreementsConfig(horizon=6),
    )
    files = run_search(job)
    record = json.loads(files["run.json"])["method"]
    assert record["disagreements"] == 0 and record["chosen"] == []
    out = write_outputs(tmp_path / "out", files)
    [path] = sorted(out.glob("summary-*.json"))
    data = json.loads(path.read_text())
    assert "follow" not in data and "window" not in data and len(data["steps"]) <= 6
    assert data["solver"]["disagreement_step"] is None and verify(path) == []


def test_a_domain_without_a_fast_path_scores_forks_by_their_summaries_alike(tmp_path):
    """`Domain.shown`'s default replays each fork as its summary; the Gymnasium domain reads the same contrast
    from its problem. A world that brings no fast path of its own gets the same disagreements, only slower."""
    import numpy as np

    from search.core.domain import Domain
    from search.core.rollout import Tracker
    from search.gym.domain import GymDomain
    from search.solvers.solver import Comparison, OwnSummaries

    class Replaying(GymDomain):
        shown = Domain.shown

    scenario = scenario_file(tmp_path)
    method = solver_named("disagreements")
    assert isinstance(method, OwnSummaries)
    records = []
    for domain in (GymDomain(), Replaying()):
        comparison = Comparison(BOX, scenario, domain, {}, {"horizon": 40}, {"name": "disagreements"})
        _, record = method.choose(
            comparison, Tracker(1_000, 3), np.random.default_rng(0), DisagreementsConfig(horizon=6)
        )
        records.append(record)
    assert records[0]["importance"] == "outcome" and records[0]["chosen"]
    assert records[0] == records[1]
