"""The batched world: vectorisation, environment action modes, kinematics, reward and episode ends."""

import pickle

import numpy as np
import pytest

from search.core.outcomes import COLLISION, RUNNING, SUCCESS, TIMEOUT
from search.crowd.sim import world
from search.crowd.sim.scenarios import load_scenario, sample_training_states
from search.crowd.sim.world import WorldConfig, WorldState, new_state


def one_robot_world(config, robot, goal, humans=(), human_goals=None):
    humans = np.array(humans, dtype=float).reshape(1, -1, 2)
    goals = humans if human_goals is None else np.array(human_goals, dtype=float).reshape(1, -1, 2)
    return new_state(humans, goals, np.array([[robot]], float), np.array([[goal]], float), 0.0, config)


def test_stepping_many_worlds_at_once_equals_stepping_each_alone():
    config = WorldConfig()
    rng = np.random.default_rng(3)
    batch = sample_training_states(config, rng, 6)
    singles = [batch.take([w]) for w in range(6)]
    for _ in range(40):
        action = rng.uniform(-1, 1, (6, 1, 2))
        env_action = rng.uniform(-0.25, 0.25, (6, 10, 2))
        rewards = world.step(batch, config, action, env_action)
        for w, single in enumerate(singles):
            assert world.step(single, config, action[[w]], env_action[[w]])[0, 0] == rewards[w, 0]
    for w, single in enumerate(singles):
        assert single.equals(batch.take([w]))


def test_worlds_are_taken_copied_and_overwritten_whole_and_fields_written_in_place():
    """Every field lives in the state's world rows: taking, pickling and overwriting worlds carry all of them."""
    config = WorldConfig()
    rng = np.random.default_rng(5)
    state = sample_training_states(config, rng, 4)
    for _ in range(5):
        world.step(state, config, rng.uniform(-1, 1, (4, 1, 2)), rng.uniform(-0.25, 0.25, (4, 10, 2)))
    fields = {name: value.copy() for name, value in state.fields().items()}
    taken = state.take([2, 2, 0])
    for name, value in fields.items():
        assert getattr(taken, name).dtype == value.dtype
        assert np.array_equal(getattr(taken, name), value[[2, 2, 0]], equal_nan=True), name
    unpickled = pickle.loads(pickle.dumps(state))
    unpickled.assign([1], taken.take([0]))  # world 2 into world 1
    for name, value in fields.items():
        expected = value.copy()
        expected[1] = value[2]
        assert np.array_equal(getattr(unpickled, name), expected, equal_nan=True), name
    assert state.equals(WorldState(**fields))  # untouched by the copies
    with pytest.raises(TypeError, match=r"missing \['time'\], unknown \['tme'\]"):
        WorldState(**{("tme" if name == "time" else name): value for name, value in fields.items()})
    assert state.take([]).human_pos.shape == (0, 10, 2)
    with pytest.raises(AttributeError, match="in place"):
        state.time = np.zeros(4)
    with pytest.raises(ValueError, match="by worlds of 3 humans"):
        state.assign([0], one_robot_world(config, (0, 0), (1, 1), humans=[(1, 1), (2, 2), (3, 3)]))


def test_same_actions_give_bit_identical_states():
    config = WorldConfig(human_policy="social_force")

    def run():
        rng = np.random.default_rng(11)
        state = sample_training_states(config, rng, 4)
        for _ in range(30):
            world.step(state, config, rng.uniform(-1, 1, (4, 1, 2)), rng.uniform(-0.25, 0.25, (4, 10, 2)))
        return state

    assert run().equals(run())


def test_preferred_mode_keeps_humans_within_their_speed():
    config = WorldConfig(env_action_mode="preferred")
    state = sample_training_states(config, np.random.default_rng(0), 3)
    for _ in range(20):
        world.step(state, config, np.zeros((3, 1, 2)), np.full((3, 10, 2), 0.25))
        assert np.linalg.norm(state.human_vel, axis=-1).max() <= config.human_v_pref + 1e-6


def test_velocity_mode_adds_the_action_after_orca():
    config = WorldConfig(env_action_mode="velocity")
    state = sample_training_states(config, np.random.default_rng(0), 2)
    plain = state.copy()
    action = np.random.default_rng(1).uniform(-0.25, 0.25, (2, 10, 2))
    world.step(plain, config, np.zeros((2, 1, 2)))
    world.step(state, config, np.zeros((2, 1, 2)), action)
    np.testing.assert_allclose(state.human_vel - plain.human_vel, action, atol=1e-12)


def test_observation_mode_leaves_the_crowd_alone():
    from search.crowd.agents.policies import load_policy
    from search.crowd.sim.coupled import CoupledSimulator

    scenario = load_scenario("paper-bl-tr")
    config = WorldConfig(env_action_mode="observation")
    sims = [CoupledSimulator([load_policy("goal"), load_policy("orca")], scenario, config) for _ in range(2)]
    noise = np.full((1, 10, 2), 0.2)
    seen = sims[0].observations(noise)[0].spatial_edges - sims[0].observations(None)[0].spatial_edges
    np.testing.assert_allclose(seen, noise)
    first = sims[0].step(noise)
    second = sims[1].step(np.zeros((1, 10, 2)))
    np.testing.assert_array_equal(first.other_pos, second.other_pos)


@pytest.mark.parametrize(
    "action, message",
    [
        (np.full((1, 10, 2), 0.3), "outside the bound"),
        (np.full((1, 10, 2), np.nan), "NaN or infinite"),
        (np.zeros((1, 9, 2)), "must have shape"),
    ],
)
def test_bad_environment_actions_are_refused_and_change_nothing(action, message):
    config = WorldConfig()
    state = sample_training_states(config, np.random.default_rng(0), 1)
    before = state.copy()
    with pytest.raises(ValueError, match=message):
        world.step(state, config, np.zeros((1, 1, 2)), action)
    assert state.equals(before)


def test_out_of_bound_actions_are_clipped_only_when_asked():
    config = WorldConfig(clip_env_actions=True, env_action_mode="velocity")
    state = sample_training_states(config, np.random.default_rng(0), 1)
    clipped = state.copy()
    world.step(state, config, np.zeros((1, 1, 2)), np.full((1, 10, 2), 5.0))
    world.step(clipped, config, np.zeros((1, 1, 2)), np.full((1, 10, 2), 0.25))
    assert state.equals(clipped)


def test_bad_robot_actions_are_refused():
    config = WorldConfig()
    state = sample_training_states(config, np.random.default_rng(0), 1)
    with pytest.raises(ValueError, match="NaN or infinite"):
        world.step(state, config, np.array([[[np.inf, 0.0]]]))
    with pytest.raises(ValueError, match="robot action must have shape"):
        world.step(state, config, np.zeros((1, 2)))


def test_collision_is_reported_on_the_step_it_happens():
    # The robot runs into a resting human within this very step (CrowdNav would report it one step later).
    config = WorldConfig(human_num=1, human_v_pref=0.0)
    state = one_robot_world(config, [0.0, 0.0], [5.0, 0.0], humans=[[0.8, 0.0]])  # 0.2 m clear
    reward = world.step(state, config, np.array([[[1.0, 0.0]]]))
    assert state.outcome[0, 0] == COLLISION and state.done[0, 0]
    assert reward[0, 0] == config.collision_penalty
    assert state.event_time[0, 0] == config.dt


def test_passing_through_a_human_within_one_step_is_a_collision():
    config = WorldConfig(human_num=1, human_v_pref=0.0, dt=1.0)
    state = one_robot_world(config, [0.0, 0.0], [5.0, 0.0], humans=[[0.5, 0.0]])
    world.step(state, config, np.array([[[1.0, 0.0]]]))  # ends at x = 1, beyond the human
    assert state.outcome[0, 0] == COLLISION


def test_success_reward_and_frozen_robot_after_the_goal():
    config = WorldConfig(human_num=0)
    state = one_robot_world(config, [0.0, 0.0], [0.3, 0.0])
    assert world.step(state, config, np.array([[[1.0, 0.0]]]))[0, 0] == config.success_reward
    assert state.outcome[0, 0] == SUCCESS
    pos = state.robot_pos.copy()
    assert world.step(state, config, np.array([[[1.0, 0.0]]]))[0, 0] == 0.0
    np.testing.assert_array_equal(state.robot_pos, pos)


def test_progress_and_discomfort_rewards():
    config = WorldConfig(human_num=1, human_v_pref=0.0)
    state = one_robot_world(config, [0.0, 0.0], [10.0, 0.0], humans=[[0.0, 5.0]])
    assert world.step(state, config, np.array([[[1.0, 0.0]]]))[0, 0] == pytest.approx(2 * 0.25)
    # A human 0.7 m away at the end of the move: 0.1 m surface clearance.
    state = one_robot_world(config, [0.0, 0.0], [0.0, -10.0], humans=[[0.7, 0.0]])
    reward = world.step(state, config, np.array([[[0.0, 0.0]]]))[0, 0]
    assert reward == pytest.approx((0.1 - 0.25) * 10 * 0.25)
    assert state.min_clearance[0, 0] == pytest.approx(0.1)


def test_timeout_at_the_time_limit():
    config = WorldConfig(human_num=0, time_limit=1.0)
    state = one_robot_world(config, [0.0, 0.0], [10.0, 0.0])
    for _ in range(3):
        world.step(state, config, np.zeros((1, 1, 2)))
        assert state.outcome[0, 0] == RUNNING
    assert world.step(state, config, np.zeros((1, 1, 2)))[0, 0] == 0.0
    assert state.outcome[0, 0] == TIMEOUT and state.event_time[0, 0] == 1.0


def test_holonomic_speed_is_limited():
    config = WorldConfig(human_num=0)
    state = one_robot_world(config, [0.0, 0.0], [10.0, 0.0])
    world.step(state, config, np.array([[[3.0, 4.0]]]))
    np.testing.assert_allclose(state.robot_vel[0, 0], [0.6, 0.8])


def test_holonomic_velocities_equal_the_numpy_formula_bit_for_bit():
    config = WorldConfig(human_num=0)
    rng = np.random.default_rng(5)
    state = sample_training_states(config, rng, 64)
    state.done[:8] = True
    action = rng.normal(0.0, 1.5, state.robot_pos.shape)
    action[8:12] = 0.0  # standing still keeps the heading
    before = state.copy()
    velocity = world.robot_velocities(state, config, action)
    speed = np.sqrt(action[..., 0:1] ** 2 + action[..., 1:2] ** 2)
    clipped = np.where(speed > config.robot_v_pref, action * (config.robot_v_pref / np.maximum(speed, 1e-300)), action)
    active = ~before.done
    theta = np.where(speed[..., 0] > 0, np.arctan2(clipped[..., 1], clipped[..., 0]), before.robot_theta)
    assert np.array_equal(velocity, np.where(active[..., None], clipped, 0.0))
    assert np.array_equal(state.robot_theta, np.where(active, theta, before.robot_theta))
    assert (speed > config.robot_v_pref).any()
    assert np.array_equal(state.robot_theta[8:12], before.robot_theta[8:12])


def test_unicycle_accumulates_clipped_speed_and_turns():
    config = WorldConfig(human_num=0, kinematics="unicycle")
    state = one_robot_world(config, [0.0, 0.0], [10.0, 0.0])
    state.robot_theta[:] = 0.0
    for k in range(1, 4):
        world.step(state, config, np.array([[[1.0, 0.0]]]))
        assert state.robot_speed[0, 0] == pytest.approx(0.1 * k)
    world.step(state, config, np.array([[[0.0, -5.0]]]))
    assert state.robot_theta[0, 0] == pytest.approx(2 * np.pi - 0.1)
    np.testing.assert_allclose(np.linalg.norm(state.robot_vel[0, 0]), 0.3)


def test_social_force_humans_head_for_their_goals_and_repel():
    config = WorldConfig(human_num=2, human_policy="social_force", human_v_pref=1.0)
    state = new_state(
        np.array([[[-3.0, 0.0], [3.0, 0.05]]]),
        np.array([[[3.0, 0.0], [-3.0, 0.05]]]),
        np.array([[[0.0, -20.0]]]),
        np.array([[[0.0, 20.0]]]),
        0.0,
        config,
    )
    for _ in range(60):
        world.step(state, config, np.zeros((1, 1, 2)))
        assert np.linalg.norm(state.human_vel, axis=-1).max() <= 1.0 + 1e-9
    assert state.human_pos[0, 0, 0] > 2.0 and state.human_pos[0, 1, 0] < -2.0


def test_visible_robot_is_avoided_by_humans():
    invisible, visible = (
        WorldConfig(human_num=1, human_v_pref=1.0),
        WorldConfig(human_num=1, human_v_pref=1.0, robot_visible=True),
    )
    runs = []
    for config in (invisible, visible):
        state = one_robot_world(config, [0.0, 0.0], [0.0, 0.0], humans=[[-3.0, 0.0]], human_goals=[[3.0, 0.0]])
        closest = np.inf
        for _ in range(30):
            world.step(state, config, np.zeros((1, 1, 2)))
            closest = min(closest, np.linalg.norm(state.human_pos[0, 0] - state.robot_pos[0, 0]))
        runs.append(closest)
    assert runs[0] < 0.1 and runs[1] > 0.6


def test_invalid_config_is_explained():
    with pytest.raises(ValueError, match="env_action_mode must be one of"):
        WorldConfig(env_action_mode="push")
    with pytest.raises(ValueError, match="unknown world setting"):
        WorldConfig.from_dict({"humans": 3})


def numpy_move_and_judge(state, config, robot_vel, human_vel):
    """The move and its judgement written with numpy arrays (the formulas world.step implements): the reference
    the compiled loop must match bit for bit."""
    rel_start = state.robot_pos[:, :, None, :] - state.human_pos[:, None, :, :]
    prev_goal_dist = np.linalg.norm(state.robot_goal - state.robot_pos, axis=-1)
    active = ~state.done
    move = robot_vel * config.dt
    robot_pos = state.robot_pos + move
    path_length = state.path_length + np.linalg.norm(move, axis=-1)
    human_pos = state.human_pos + human_vel * config.dt
    time = state.time + config.dt
    rel_end = robot_pos[:, :, None, :] - human_pos[:, None, :, :]
    seg = rel_end - rel_start
    seg_sq = np.sum(seg * seg, axis=-1)
    t = np.clip(
        np.divide(-np.sum(rel_start * seg, axis=-1), seg_sq, out=np.zeros_like(seg_sq), where=seg_sq > 0), 0.0, 1.0
    )
    surface = (
        np.linalg.norm(rel_start + t[..., None] * seg, axis=-1) - state.human_radius[:, None, :] - config.robot_radius
    )
    clearance = surface.min(axis=-1)
    goal_dist = np.linalg.norm(state.robot_goal - robot_pos, axis=-1)
    collision = active & (clearance < 0)
    success = active & ~collision & (goal_dist < config.robot_radius)
    timeout = active & ~collision & ~success & (time[:, None] >= config.time_limit - 1e-9)
    reward = np.where(
        clearance < config.discomfort_dist,
        (clearance - config.discomfort_dist) * config.discomfort_factor * config.dt,
        config.progress_factor * (prev_goal_dist - goal_dist),
    )
    reward = np.where(timeout, 0.0, reward)
    reward = np.where(success, config.success_reward, reward)
    reward = np.where(collision, config.collision_penalty, reward)
    reward = np.where(active, reward, 0.0)
    finished = collision | success | timeout
    return {
        "reward": reward,
        "robot_pos": robot_pos,
        "human_pos": human_pos,
        "time": time,
        "path_length": path_length,
        "min_clearance": np.where(active, np.minimum(state.min_clearance, clearance), state.min_clearance),
        "outcome": np.where(
            collision, COLLISION, np.where(success, SUCCESS, np.where(timeout, TIMEOUT, state.outcome))
        ),
        "event_time": np.where(finished, time[:, None], state.event_time),
        "done": state.done | finished,
    }


@pytest.mark.parametrize("kinematics, visible", [("holonomic", False), ("unicycle", False), ("holonomic", True)])
def test_the_compiled_step_equals_the_numpy_formulas_bit_for_bit(kinematics, visible):
    config = WorldConfig(kinematics=kinematics, robot_visible=visible, time_limit=8.0)
    rng = np.random.default_rng(11)
    state = sample_training_states(config, rng, 24)
    outcomes = set()
    for _ in range(40):
        toward_goal = (state.robot_goal - state.robot_pos) * rng.uniform(0.2, 2.0, state.robot_pos.shape[:2])[..., None]
        action = toward_goal + rng.normal(0.0, 0.3, state.robot_pos.shape)
        env_action = rng.uniform(-0.25, 0.25, (24, config.human_num, 2))
        before = state.copy()
        human_vel = world.human_velocities(before, config, env_action)
        robot_vel = world.robot_velocities(before, config, action)
        expected = numpy_move_and_judge(before, config, robot_vel, human_vel)
        reward = world.step(state, config, action, env_action)
        assert np.array_equal(reward, expected.pop("reward"))
        for name, value in expected.items():
            assert np.array_equal(getattr(state, name), value, equal_nan=True), name
        outcomes.update(state.outcome.ravel().tolist())
    assert {RUNNING, COLLISION, TIMEOUT} <= outcomes and (SUCCESS in outcomes or kinematics == "unicycle")
