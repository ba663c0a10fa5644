"""Rollouts shared across pairs: every agent plays each drawn state once, and a pair's votes, clips and records read
the same whether its search plays the pair alone or shares a pool with other agents, pairs and parts."""

from __future__ import annotations

import numpy as np

from search.core.domain import domain_for
from search.solvers.pool import Pool
from search.solvers.representative import RepresentativeConfig
from search.solvers.runner import SearchJob, run_search
from tests.support.played import checked_rollouts

CROWD = ["goal", "orca", "social_force"]


def test_the_crowds_fast_rollouts_read_each_pair_as_its_summaries_and_as_the_pair_alone():
    domain = domain_for(CROWD, "training")
    states = domain.draw_states("training", {"human_num": 5}, np.random.default_rng(0), 2)
    played = checked_rollouts(domain, CROWD, states, 40, 2)
    assert (played.ends > 0).any() and played.ends.shape == (6, 3)


def search(
    agents: tuple[str, str], earlier: int = 0, scenario: str = "training", horizon: int = 40, **world: int
) -> SearchJob:
    """A small representative search of ``agents`` (by default in a crowd of 5), its clip the ``earlier``-th
    other state of the vote."""
    return SearchJob(
        agents=agents,
        scenario=scenario,
        solver="representative",
        budget=6_000,
        seed=3,
        top_k=1,
        solver_config=RepresentativeConfig(states=6, pushes=2, batch_states=2, earlier=earlier),
        reward_settings={"horizon": horizon},
        world_settings=world if world or scenario != "training" else {"human_num": 5},
    )


def test_a_search_that_shares_a_pool_writes_what_it_writes_alone_and_no_agent_plays_a_state_twice():
    """Three pairs of three agents, in one pool: each pair's files are its files searched alone, and the pool
    played each agent's rollouts once, where the pairs searched alone play each agent twice."""
    pairs = [("goal", "orca"), ("goal", "social_force"), ("orca", "social_force")]
    domain = domain_for(CROWD, "training")
    pool = Pool(domain, CROWD, "training", {"human_num": 5}, {"horizon": 40}, 6, 2, 2, np.random.default_rng(3))
    alone_played = 0
    for pair in pairs:
        shared, alone = run_search(search(pair), pool=pool), run_search(search(pair))
        assert {name: text for name, text in shared.items() if name != "run.json"} == {
            name: text for name, text in alone.items() if name != "run.json"
        }
        alone_played += _played(alone)
    # each agent is in two of the pairs, all of which read the same states here: played once, not twice
    assert 2 * pool.played_steps == alone_played


def _played(files: dict[str, str]) -> int:
    import json

    return int(json.loads(files["run.json"])["vote"]["played_steps"])


def test_a_later_clip_of_the_same_vote_comes_from_another_state():
    """The ranking part's clip of a pair reads the pairwise part's vote and chooses from the other states."""
    import json

    first, later = (run_search(search(("goal", "orca"), earlier)) for earlier in (0, 1))
    vote, later_vote = (json.loads(files["run.json"])["vote"] for files in (first, later))
    assert {key: vote[key] for key in ("states", "p", "weight")} == {
        key: later_vote[key] for key in ("states", "p", "weight")
    }
    assert later_vote["earlier_states"] == [vote["chosen"][0]["state"]]
    assert later_vote["chosen"][0]["state"] != vote["chosen"][0]["state"]
