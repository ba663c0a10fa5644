import numpy as np
import pytest

from search.core.topk import TopK


def seq(value: float, length: int = 3) -> np.ndarray:
    return np.full((length, 2), value)


def test_keeps_the_k_best_ranked_best_first():
    queue = TopK(3)
    for reward in [5.0, 1.0, 9.0, 7.0, 3.0]:
        queue.push(reward, seq(reward))
    assert [f.reward for f in queue.ranked()] == [9.0, 7.0, 5.0]
    assert queue.best == 9.0
    assert not queue.push(4.0, seq(4.0))  # worse than everything kept


def test_duplicate_action_sequences_are_rejected():
    queue = TopK(5)
    assert queue.push(2.0, seq(1.0))
    assert not queue.push(2.0, seq(1.0))
    assert not queue.push(8.0, seq(1.0))  # same actions, whatever the reward
    assert queue.push(2.0, seq(1.0, length=4))  # a longer sequence is another trajectory
    assert len(queue) == 2


def test_ties_go_to_the_earlier_trajectory():
    queue = TopK(2)
    queue.push(1.0, seq(0.1))
    queue.push(1.0, seq(0.2))
    queue.push(1.0, seq(0.3))  # tied with both kept ones, but later: rejected
    assert [f.actions[0, 0] for f in queue.ranked()] == [0.1, 0.2]


def test_an_evicted_sequence_may_come_back():
    queue = TopK(1)
    queue.push(1.0, seq(0.1))
    queue.push(2.0, seq(0.2))
    assert queue.push(3.0, seq(0.1))
    assert [f.reward for f in queue.ranked()] == [3.0]


def test_k_must_be_positive():
    with pytest.raises(ValueError, match="top-k"):
        TopK(0)
