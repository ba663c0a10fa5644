import math

import numpy as np
import pytest

from search.core.outcomes import COLLISION, RUNNING, SUCCESS
from search.core.prior import ActionPrior
from search.solvers.reward import DivergenceReward, RewardConfig, pairwise_divergence

PRIOR = ActionPrior((1, 2), 0.25)


def reward(**settings) -> DivergenceReward:
    return DivergenceReward(RewardConfig(**settings), PRIOR)


def test_pairwise_divergence_plain_squared_mean_min():
    # three agents at (0,0), (3,4), (6,8): pair distances 5, 10, 5
    points = np.array([[[0.0, 0.0], [3.0, 4.0], [6.0, 8.0]]])
    assert pairwise_divergence(points, "plain", "mean")[0] == pytest.approx(20 / 3)
    assert pairwise_divergence(points, "plain", "min")[0] == 5.0
    assert pairwise_divergence(points, "squared", "mean")[0] == pytest.approx((25 + 100 + 25) / 3)
    assert pairwise_divergence(points[:, :2], "squared", "min")[0] == 25.0


def test_events_goal_collision_flag_horizon_and_all_done():
    r = reward(horizon=10)
    newly = np.array([[True, False], [True, False], [False, False], [False, False]])
    outcome = np.array([[SUCCESS, RUNNING], [COLLISION, RUNNING], [RUNNING, RUNNING], [COLLISION, COLLISION]])
    all_done = np.array([False, False, False, True])
    t = np.array([3, 3, 10, 4])
    goal, end = r.events(newly, outcome, all_done, t)
    assert goal.tolist() == [True, False, False, False]
    assert end.tolist() == [False, False, True, True]
    goal, end = reward(horizon=10, collision_is_goal=True).events(newly, outcome, all_done, t)
    assert goal.tolist() == [True, True, False, False]


def test_first_finish_ends_on_any_robots_end_and_a_collision_is_no_goal():
    """finish="first": the row where one robot collides while the other runs ends there (with the end term,
    not the goal's), as does a goal; "all" lets that row run on."""
    newly = np.array([[True, False], [False, True], [False, False]])
    outcome = np.array([[COLLISION, RUNNING], [RUNNING, SUCCESS], [RUNNING, RUNNING]])
    all_done = np.array([False, False, False])
    t = np.array([3, 3, 3])
    goal, end = reward(horizon=10, finish="first").events(newly, outcome, all_done, t)
    assert goal.tolist() == [False, True, False]
    assert end.tolist() == [True, False, False]
    goal, end = reward(horizon=10, finish="all").events(newly, outcome, all_done, t)
    assert goal.tolist() == [False, True, False] and end.tolist() == [False, False, False]
    goal, end = reward(horizon=10, finish="first", collision_is_goal=True).events(newly, outcome, all_done, t)
    assert goal.tolist() == [True, True, False] and end.tolist() == [False, False, False]


def test_last_finish_ends_only_when_every_robot_has_and_gives_a_goal_there():
    """finish="last": one robot's goal while the other runs is no end; the last robot's goal ends it with the goal
    term, the last collision with the end term, and the horizon ends it as ever."""
    newly = np.array([[True, False], [False, True], [True, False], [False, False]])
    outcome = np.array([[SUCCESS, RUNNING], [SUCCESS, SUCCESS], [COLLISION, SUCCESS], [RUNNING, RUNNING]])
    all_done = np.array([False, True, True, False])
    t = np.array([3, 5, 5, 10])
    goal, end = reward(horizon=10, finish="last").events(newly, outcome, all_done, t)
    assert goal.tolist() == [False, True, False, False]
    assert end.tolist() == [False, False, True, True]


def test_a_goal_needs_contrast_when_asked():
    """Robots that reach their goals on the same step show no difference: with goal_needs_contrast that step ends
    the trajectory without the goal term; one robot arriving alone is still a goal."""
    newly = np.array([[True, True], [True, False]])
    outcome = np.array([[SUCCESS, SUCCESS], [SUCCESS, RUNNING]])
    all_done, t = np.array([True, False]), np.array([40, 40])
    goal, end = reward(finish="first").events(newly, outcome, all_done, t)
    assert goal.tolist() == [True, True] and end.tolist() == [False, False]
    goal, end = reward(finish="first", goal_needs_contrast=True).events(newly, outcome, all_done, t)
    assert goal.tolist() == [False, True] and end.tolist() == [True, False]


def test_step_terms_by_hand():
    r = reward(alpha=2.0, goal_bonus=100.0, beta=3.0, horizon_offset=-50.0)
    actions = np.array([[[1.0, 0.0], [0.0, 0.0]]] * 3)  # action divergence 1 (plain)
    positions = np.array([[[0.0, 0.0], [0.0, 2.0]]] * 3)  # state divergence 2 (plain)
    humans = np.zeros((3, 1, 2))
    env = np.zeros((3, 1, 2))
    goal = np.array([False, True, False])
    end = np.array([False, False, True])
    terms = r.step_terms(actions, positions, humans, env, goal, end)
    assert terms["action_divergence"].tolist() == [1.0, 0.0, 0.0]
    assert terms["goal"].tolist() == [0.0, 100.0 + 2.0 * 2.0, 0.0]
    assert terms["horizon"].tolist() == [0.0, 0.0, -50.0 + 3.0 * 2.0]
    assert terms["plausibility"].tolist() == [0.0, 0.0, 0.0]
    assert r.step(actions, positions, humans, env, goal, end).tolist() == [1.0, 104.0, -44.0]
    squared = reward(norm="squared").step(actions * 3, positions, humans, env, goal, end)
    assert squared.tolist() == [9.0, 4.0, 4.0]


def test_plausibility_is_the_prior_log_likelihood():
    action = np.array([[[0.1, -0.2]]])
    uniform = reward(plausibility=0.5).step_terms(
        np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), np.zeros((1, 1, 2)), action, np.array([False]), np.array([False])
    )
    assert uniform["plausibility"][0] == pytest.approx(0.5 * -2 * math.log(0.5))
    sigma, bound = 0.1, 0.25
    gaussian = DivergenceReward(
        RewardConfig(plausibility=1.0, prior="gaussian", prior_sigma=sigma),
        ActionPrior((1, 2), bound, "gaussian", sigma),
    )
    terms = gaussian.step_terms(
        np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), np.zeros((1, 1, 2)), action, np.array([False]), np.array([False])
    )
    mass = math.erf(bound / (sigma * math.sqrt(2)))
    expected = sum(-0.5 * (x / sigma) ** 2 - math.log(sigma * math.sqrt(2 * math.pi) * mass) for x in (0.1, -0.2))
    assert terms["plausibility"][0] == pytest.approx(expected)


def test_gaussian_prior_samples_stay_in_bound():
    prior = ActionPrior((10, 2), 0.25, "gaussian", sigma=0.3)
    samples = prior.sample(np.random.default_rng(0), 500)
    assert samples.shape == (500, 10, 2)
    assert np.abs(samples).max() <= 0.25


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"norm": "cubed"}, "norm"),
        ({"combine": "max"}, "combine"),
        ({"horizon": 0}, "horizon"),
        ({"finish": "final"}, "finish must be 'all'"),
        ({"heuristic": "nope"}, "unknown heuristic"),
        ({"prior": "beta"}, "prior"),
    ],
)
def test_bad_reward_settings_say_what_is_wrong(settings, message):
    with pytest.raises(ValueError, match=message):
        RewardConfig(**settings)
    with pytest.raises(ValueError, match="unknown reward setting"):
        RewardConfig.from_dict({"alpah": 1.0})


def far_humans(agent_pos, other_pos, config):
    """A heuristic other than the default one: mean distance of the humans from the first robot."""
    return np.linalg.norm(other_pos - agent_pos[..., :1, :], axis=-1).mean(axis=-1)


def numpy_divergence(values, norm, combine):
    """The divergence as the paper writes it, with numpy arrays: the norm of each agent pair's difference, then
    their mean or minimum."""
    i, j = np.triu_indices(values.shape[-2], k=1)
    diff = values[..., i, :] - values[..., j, :]
    squared = np.sum(diff * diff, axis=-1)
    pairs = squared if norm == "squared" else np.sqrt(squared)
    if combine == "min":
        return pairs.min(axis=-1)
    # the pairs summed in order (numpy's own sum would add the pairs of one row pairwise from 8 on)
    return sum(pairs[..., k] for k in range(pairs.shape[-1])) / pairs.shape[-1]


def numpy_step_terms(config, heuristic, prior, agent_actions, agent_pos, other_pos, env_action, goal, end):
    """The reward terms of a step with numpy arrays: the reference the compiled reward must match bit for bit."""
    c = config
    d_a = numpy_divergence(agent_actions, c.norm, c.combine)
    d_s = numpy_divergence(agent_pos, c.norm, c.combine)
    h = d_s if heuristic is None else heuristic(agent_pos, other_pos, c)
    return {
        "action_divergence": np.where(~goal & ~end, d_a, 0.0),
        "goal": np.where(goal, c.goal_bonus + c.alpha * d_s, 0.0),
        "horizon": np.where(end, c.horizon_offset + c.beta * h, 0.0),
        "plausibility": c.plausibility * prior.log_prob(env_action) if c.plausibility else np.zeros_like(d_a),
    }


@pytest.mark.parametrize("agents", [2, 3, 5])
@pytest.mark.parametrize(
    "settings",
    [
        {},
        {"norm": "squared", "combine": "min", "goal_bonus": 100.0, "beta": 1e4, "horizon_offset": -1e5},
        {"plausibility": 0.3, "prior": "gaussian", "heuristic": "tests.solvers.test_reward:far_humans"},
    ],
)
def test_the_compiled_reward_equals_the_numpy_formulas_bit_for_bit(agents, settings):
    """Searches and replays score steps with one compiled kernel; it must give the numpy formulas' numbers to the
    last bit (a summary is checked exactly), and a step's reward must be the sum of its terms."""
    config = RewardConfig(**settings)
    prior = ActionPrior((4, 2), 0.25, config.prior, config.prior_sigma)
    r = DivergenceReward(config, prior)
    heuristic = far_humans if "heuristic" in settings else None
    rng = np.random.default_rng(agents)
    rows = 200
    actions = rng.normal(size=(rows, agents, 2)) * np.exp(rng.normal(size=(rows, agents, 1)) * 3)
    positions = rng.normal(size=(rows, agents, 2)) * 5
    humans, env = rng.normal(size=(rows, 4, 2)), rng.uniform(-0.25, 0.25, (rows, 4, 2))
    goal = rng.random(rows) < 0.1
    end = ~goal & (rng.random(rows) < 0.1)
    for g, e in [(goal, end), (goal & False, end & False), (goal, end & False), (goal & False, end)]:
        expected = numpy_step_terms(config, heuristic, prior, actions, positions, humans, env, g, e)
        terms = r.step_terms(actions, positions, humans, env, g, e)
        assert terms.keys() == expected.keys()
        for name in terms:
            assert np.array_equal(terms[name], expected[name]), name
        total = terms["action_divergence"] + terms["goal"] + terms["horizon"] + terms["plausibility"]
        assert np.array_equal(r.step(actions, positions, humans, env, g, e), total)
    for combine in ("mean", "min"):
        assert np.array_equal(
            pairwise_divergence(positions, config.norm, combine), numpy_divergence(positions, config.norm, combine)
        )


@pytest.mark.parametrize("shape", [(5, 1, 2), (5, 2, 3), (2,)])
def test_a_divergence_of_other_than_planar_vectors_of_two_or_more_agents_is_refused(shape):
    with pytest.raises(ValueError, match=r"two or more agents \(\.\.\., N >= 2, 2\), not an array of shape"):
        pairwise_divergence(np.zeros(shape), "plain", "mean")
