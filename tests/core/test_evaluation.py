"""The evaluation Foil computes from a world's played episodes: the same keys and intervals for every world, outcome
rates only where the episodes have outcomes, the visible score only where the world declares one."""

import pytest

from app.visible import Score
from search.core.evaluation import Episode, describe, evaluation
from search.gym.evaluate import episodes_result


def test_outcomes_give_rates_with_wilson_intervals_as_the_gym_evaluation_does():
    played = [Episode(1.0, 4.0, "success"), Episode(-1.0, 2.0, "collision"), Episode(0.5, 6.0, "timeout")] * 2
    result = evaluation("a", 3, played, None, per_episode=True)
    assert result["success_rate"] == pytest.approx(1 / 3) and result["collision_rate"] == pytest.approx(1 / 3)
    assert result["success_ci95"][0] < 1 / 3 < result["success_ci95"][1]
    assert result["episode_rewards"] == [1.0, -1.0, 0.5] * 2 and result["length_mean"] == pytest.approx(4.0)
    assert result["nav_time_mean"] == pytest.approx(4.0)
    same = episodes_result("a", 3, [e.event for e in played], [e.reward for e in played], [4, 2, 6] * 2, 1.0, None)
    assert {k: v for k, v in result.items() if k != "episode_rewards"} == same
    assert describe(result).startswith("a: 6 episodes (seed 3), success rate 0.333 (")


def test_a_world_of_reward_alone_has_no_rates_and_its_visible_score_has_an_interval():
    wait = Score("mean wait", unit="s", better="lower", summed="mean", span=5.0)
    played = [Episode(-float(w), 60.0, None, float(w)) for w in (12, 15, 9, 20)]
    result = evaluation("nearest-car", 0, played, wait)
    assert not any(key.endswith("_rate") for key in result) and "episode_rewards" not in result
    assert result["score"]["mean"] == pytest.approx(14.0) and result["score"]["name"] == "mean wait"
    low, high = result["score"]["ci95"]
    assert low < 14.0 < high
    text = describe(result)
    assert "rate" not in text and "visible score: mean wait mean over the episode 14.0 s" in text


def test_what_a_world_gets_wrong_is_named():
    with pytest.raises(ValueError, match="give every episode an outcome, or none"):
        evaluation("a", 0, [Episode(1.0, 1.0, "success"), Episode(0.0, 1.0)], None)
    with pytest.raises(ValueError, match="episode outcome 'won'"):
        evaluation("a", 0, [Episode(1.0, 1.0, "won"), Episode(0.0, 1.0, "won")], None)
    with pytest.raises(ValueError, match="episode 1 has none: give each Episode its score"):
        evaluation("a", 0, [Episode(1.0, 1.0, None, 2.0), Episode(0.0, 1.0)], Score("height", span=1.0))
    with pytest.raises(ValueError, match="at least 2 episodes"):
        evaluation("a", 0, [Episode(1.0, 1.0)], None)
