"""A study's representative searches of one distribution and seed run in one job that plays each agent once: three
runners on the tiny track of tests/gym/test_gym_clips.py, every pair in both parts, each search's files the same as
it writes alone, over one worker process or two."""

from __future__ import annotations

import json

from search.bundle.searches import group_work, search_group_files, search_groups
from search.solvers.runner import SearchJob, run_search
from tests.bundle.test_distinct_reels import MIDDLING
from tests.gym.test_any_world import FAST, SLOW, world  # noqa: F401  (the researcher's folder)
from tests.solvers.test_pool import search


def searches() -> list[SearchJob]:
    """Each pair's search for the pairwise part and for the ranking (another state of the same vote)."""
    return [
        search(pair, earlier, "track-starts.toml", horizon=6)
        for pair in ((FAST, MIDDLING), (FAST, SLOW), (MIDDLING, SLOW))
        for earlier in (0, 1)
    ]


def test_one_job_plays_each_runner_once_and_writes_what_each_search_writes_alone(world):  # noqa: F811
    jobs = searches()
    [(_, keys)] = search_groups(dict(enumerate(jobs))).items()  # one pool: one job
    assert keys == list(range(6))
    alone = [run_search(job) for job in jobs]
    for workers in (1, 2):
        shared, _ = search_group_files(jobs, workers)
        for own, files in zip(alone, shared, strict=True):
            assert {name: text for name, text in own.items() if name != "run.json"} == {
                name: text for name, text in files.items() if name != "run.json"
            }
    votes = [json.loads(files["run.json"])["vote"] for files in shared]
    played = sum(vote["played_steps"] for vote in votes)
    assert played and all(vote["played_steps"] == 0 for vote in votes[1::2])  # the ranking's: already played
    assert played < sum(json.loads(files["run.json"])["vote"]["played_steps"] for files in alone) / 3
    assert {tuple(vote["earlier_states"]) for vote in votes[1::2]} and all(
        "earlier_states" not in v for v in votes[::2]
    )


def test_a_pooled_job_is_sized_by_the_agents_it_plays():
    from search.bundle.searches import ClipJob
    from search.bundle.spec import Scheme
    from search.solvers.reward import RewardConfig

    jobs = searches()
    scheme = Scheme(
        "representative", "representative", 2_000, 0, 1, "reward", jobs[0].solver_config, RewardConfig(), {}
    )
    clips = [(ClipJob("clip", scheme, job.scenario, job.agents, (1, 2), ("pairwise",)), job) for job in jobs]
    assert group_work(clips).units == 6_000 * 3 // 2  # 3 runners played, where one search plays 2
    assert group_work(clips[:1]).units == 6_000


def test_each_pairs_check_reads_the_same_whichever_pairs_are_checked_beside_it():
    """The representativeness check plays every agent once for all its pairs: each pair's reports are those of
    the pair checked alone."""
    from search.bundle.representativeness import representativeness_job
    from search.bundle.spec import Representativeness
    from search.core.domain import domain_named

    domain, crowd = domain_named("crowd"), {"human_num": 5}
    fixed = [("paper-bl-tr", domain.state("paper-bl-tr", crowd))]
    pairs = [("goal", "orca"), ("goal", "social_force"), ("orca", "social_force")]
    settings, reward = Representativeness(states=4, pushes=2), {"horizon": 40}
    together, _ = representativeness_job("crowd", dict.fromkeys(pairs, fixed), "training", crowd, settings, reward)
    for pair in pairs:
        alone, _ = representativeness_job("crowd", {pair: fixed}, "training", crowd, settings, reward)
        assert alone[pair] == together[pair]
    assert together[pairs[0]] != together[pairs[1]]
