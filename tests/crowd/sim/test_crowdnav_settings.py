"""The world settings CrowdNav_DSRNN's configs use: randomised humans, goal changes, fields of view, the arc
unicycle; each as defined, each deterministic and carried by snapshots."""

import math

import numpy as np
import pytest
from scipy import stats

from search.crowd.agents.policies import load_policy
from search.crowd.sim import world
from search.crowd.sim.coupled import CoupledSimulator, replay
from search.crowd.sim.observation import observe
from search.crowd.sim.orca import orca_velocities
from search.crowd.sim.scenarios import Scenario, sample_training_states
from search.crowd.sim.world import WorldConfig, new_state

CROWDNAV = WorldConfig(
    human_num=5,
    human_v_pref=1.0,
    randomize_attributes=True,
    goal_change_chance=0.25,
    end_goal_change_chance=1.0,
    robot_fov=180.0,
    human_fov=270.0,
    time_limit=49.0,
)


def test_randomised_humans_are_uniform_over_crowdnavs_ranges():
    config = WorldConfig(human_num=5, human_v_pref=1.0, randomize_attributes=True)
    state = sample_training_states(config, np.random.default_rng(0), 400)
    v_pref, radius = state.human_v_pref.ravel(), state.human_radius.ravel()
    assert stats.kstest(v_pref, stats.uniform(0.5, 1.0).cdf).pvalue > 0.01
    assert stats.kstest(radius, stats.uniform(0.3, 0.2).cdf).pvalue > 0.01
    # each human keeps clear of the robot's start and goal by its own radius
    for w in range(50):
        for h in range(5):
            for point in (state.robot_pos[w, 0], state.robot_goal[w, 0]):
                assert np.linalg.norm(state.human_pos[w, h] - point) >= radius[w * 5 + h] + 0.25 + 0.3 - 1e-12
    fixed = sample_training_states(config.with_(randomize_attributes=False), np.random.default_rng(0), 3)
    assert (fixed.human_v_pref == 1.0).all() and (fixed.human_radius == 0.3).all()


def test_the_circle_start_puts_the_robot_on_the_circle_facing_anywhere_with_humans_kept_away():
    config = WorldConfig(human_num=5, human_v_pref=1.0, kinematics="unicycle", robot_start="circle")
    state = sample_training_states(config, np.random.default_rng(0), 300)
    np.testing.assert_allclose(np.linalg.norm(state.robot_pos[:, 0], axis=-1), 6.0)
    assert np.linalg.norm(state.robot_goal[:, 0] - state.robot_pos[:, 0], axis=-1).min() >= 6.0
    assert stats.kstest(state.robot_theta[:, 0], stats.uniform(0, 2 * np.pi).cdf).pvalue > 0.01
    for end in (state.robot_pos, state.robot_goal):  # CrowdNav keeps humans half the circle radius away
        assert np.linalg.norm(state.human_pos - end, axis=-1).min() >= 3.0


def test_a_fixed_scenario_draws_its_humans_from_the_crowd_seed():
    scenario = Scenario("s", (-5.0, 0.0), (5.0, 0.0), ((0.0, 3.0), (0.0, -3.0)), ((0.0, -3.0), (0.0, 3.0)))
    config = scenario.config(WorldConfig(randomize_attributes=True))
    a, b = scenario.initial_state(config, 2), scenario.initial_state(config, 1)
    np.testing.assert_array_equal(a.human_radius[0], b.human_radius[0])
    np.testing.assert_array_equal(a.human_radius[0], a.human_radius[1])
    other = scenario.initial_state(config.with_(crowd_seed=1))
    assert not np.array_equal(other.human_radius, b.human_radius)
    assert ((0.3 <= b.human_radius) & (b.human_radius <= 0.5)).all()
    assert ((0.5 <= b.human_v_pref) & (b.human_v_pref <= 1.5)).all()


def _changed_goals(config, steps, worlds=300, seed=0):
    state = sample_training_states(config, np.random.default_rng(seed), worlds)
    changes = []
    for _ in range(steps):
        goals = state.human_goal.copy()
        world.step(state, config, np.zeros((worlds, 1, 2)))
        arrived = np.linalg.norm(goals - state.human_pos, axis=-1) < state.human_radius
        changes.append((~np.all(goals == state.human_goal, axis=-1), arrived))
    return changes, state


def test_goals_change_with_their_chance_every_interval_only():
    config = WorldConfig(human_num=5, human_v_pref=1.0, goal_change_chance=0.25)
    changes, state = _changed_goals(config, 20)
    for step, (changed, _) in enumerate(changes[:19], start=1):
        assert not changed.any(), f"a goal changed at {step * 0.25} s, between the 5 s marks"
    share = changes[19][0].mean()  # at 5 s: each of 1,500 humans with chance 0.25
    assert abs(share - 0.25) < 3 * math.sqrt(0.25 * 0.75 / 1500)
    new = state.human_goal[changes[19][0]]
    distance = np.linalg.norm(new, axis=-1)  # on the circle, plus noise of at most v_pref / 2 per axis
    assert (np.abs(distance - 6.0) <= 0.5 * math.sqrt(2) + 1e-9).all()
    never, _ = _changed_goals(config.with_(goal_change_chance=0.0), 20, worlds=20)
    assert not any(changed.any() for changed, _ in never)


@pytest.mark.parametrize("chance", [0.0, 0.5, 1.0])
def test_humans_at_their_goal_take_a_new_one_with_the_end_chance(chance):
    config = WorldConfig(human_num=1, human_v_pref=1.0, end_goal_change_chance=chance)
    worlds = 400
    state = new_state(
        np.zeros((worlds, 1, 2)),
        np.full((worlds, 1, 2), 0.1),
        np.full((worlds, 1, 2), -20.0),
        np.full((worlds, 1, 2), -25.0),
        0.0,
        config,
        rng=np.arange(worlds, dtype=np.uint64),
    )
    world.step(state, config, np.zeros((worlds, 1, 2)))  # every human arrives within its radius of (0.1, 0.1)
    changed = np.linalg.norm(state.human_goal[:, 0] - 0.1, axis=-1) > 1e-12
    assert abs(changed.mean() - chance) < 3 * math.sqrt(0.25 / worlds)
    assert (np.abs(np.linalg.norm(state.human_goal[changed, 0], axis=-1) - 6.0) <= 0.5 * math.sqrt(2) + 1e-9).all()


def _robot_among(humans, config, velocity=(1.0, 0.0), theta=0.0):
    state = new_state(
        np.array([humans], float),
        np.array([humans], float),
        np.zeros((1, 1, 2)),
        np.array([[[9.0, 0.0]]]),
        theta,
        config,
    )
    state.robot_vel[0, 0] = velocity
    return state


def test_humans_outside_the_robots_field_of_view_are_not_observed():
    humans = [[2.0, 0.1], [-2.0, 0.0], [0.5, 1.5], [0.1, -3.0]]  # ahead, behind, 72 deg left, 88 deg right
    config = WorldConfig(human_num=4, robot_fov=180.0)
    assert observe(_robot_among(humans, config), config, 0).human_mask.tolist() == [[True, False, True, True]]
    narrow = config.with_(robot_fov=120.0)
    assert observe(_robot_among(humans, narrow), narrow, 0).human_mask.tolist() == [[True, False, False, False]]
    # a holonomic robot faces its velocity; a unicycle its heading
    facing_back = observe(_robot_among(humans, narrow, velocity=(-1.0, 0.0)), narrow, 0)
    assert facing_back.human_mask.tolist() == [[False, True, False, False]]
    unicycle = narrow.with_(kinematics="unicycle")
    turned = observe(_robot_among(humans, unicycle, velocity=(1.0, 0.0), theta=-math.pi / 2), unicycle, 0)
    assert turned.human_mask.tolist() == [[False, False, False, True]]
    full = WorldConfig(human_num=4)
    assert observe(_robot_among(humans, full, velocity=(0.0, 0.0)), full, 0).human_mask.all()


def test_humans_avoid_only_the_humans_in_their_view():
    # human 0 walks east; human 1 comes up behind it, fast; human 2 stands ahead-left of it
    pos = np.array([[[0.0, 0.0], [-1.2, 0.0], [1.0, 0.8]]])
    vel = np.array([[[0.5, 0.0], [1.5, 0.0], [0.0, 0.0]]])
    goal = np.array([[[-6.0, 0.0], [6.0, 0.0], [1.0, 0.8]]])
    goal[0, 0] = [6.0, 0.0]
    config = WorldConfig(human_num=3, human_v_pref=1.0, human_fov=180.0)
    state = new_state(pos, goal, np.full((1, 1, 2), -20.0), np.full((1, 1, 2), -25.0), 0.0, config)
    state.human_vel[...] = vel
    velocity = world.human_velocities(state, config, None)
    # by hand: human 0 sees human 2 (ahead), and human 1 in its place stands still at (7, 7)
    pad = 0.01 + config.safety_space
    expected = orca_velocities(
        np.array([[[0.0, 0.0], [7.0, 7.0], [1.0, 0.8]]]),
        np.array([[[0.5, 0.0], [0.0, 0.0], [0.0, 0.0]]]),
        np.array([[[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]]]),
        np.full((1, 3), 0.3 + pad),
        np.ones((1, 3)),
        n_ego=1,
    )
    np.testing.assert_array_equal(velocity[0, 0], expected[0, 0])
    everyone = world.human_velocities(state, config.with_(human_fov=360.0), None)
    assert not np.allclose(everyone[0, 0], velocity[0, 0])  # with full view, human 1 behind it matters


def test_the_arc_unicycle_turns_while_it_moves():
    config = WorldConfig(human_num=0, kinematics="unicycle", unicycle_motion="arc")
    state = new_state(
        np.zeros((1, 0, 2)), np.zeros((1, 0, 2)), np.zeros((1, 1, 2)), np.array([[[9.0, 9.0]]]), 0.3, config
    )
    state.robot_speed[:] = 0.8
    world.step(state, config, np.array([[[0.05, 0.1]]]))
    v, theta, turn, dt = 0.85, 0.3, 0.1, config.dt
    radius = v * dt / turn  # CrowdNav's differential drive: w = dtheta / dt, R = v / w
    expected = [
        radius * (math.sin(theta + turn) - math.sin(theta)),
        radius * (math.cos(theta) - math.cos(theta + turn)),
    ]
    np.testing.assert_allclose(state.robot_pos[0, 0], expected, rtol=1e-12)
    assert state.robot_theta[0, 0] == pytest.approx(0.4)
    np.testing.assert_allclose(state.robot_vel[0, 0], [v * math.cos(0.4), v * math.sin(0.4)])
    straight = config.with_(unicycle_motion="straight")
    other = new_state(
        np.zeros((1, 0, 2)), np.zeros((1, 0, 2)), np.zeros((1, 1, 2)), np.array([[[9.0, 9.0]]]), 0.3, straight
    )
    other.robot_speed[:] = 0.8
    world.step(other, straight, np.array([[[0.05, 0.1]]]))
    np.testing.assert_allclose(other.robot_pos[0, 0], [dt * v * math.cos(0.4), dt * v * math.sin(0.4)])


def _scenario():
    rng = np.random.default_rng(4)
    angles = rng.uniform(0, 2 * np.pi, 5)
    humans = tuple((6 * math.cos(a), 6 * math.sin(a)) for a in angles)
    return Scenario("crowdnav", (-4.0, -4.0), (4.0, 4.0), humans, tuple((-x, -y) for x, y in humans))


def test_replays_with_every_setting_on_are_bit_identical_and_snapshots_carry_the_randomness():
    scenario = _scenario()
    actions = np.random.default_rng(1).uniform(-0.25, 0.25, (60, 1, 5, 2))
    policies = [load_policy("goal"), load_policy("orca")]
    first = replay(policies, scenario, actions[:, 0], config=CROWDNAV, stop_when_done=False)
    second = replay(policies, scenario, actions[:, 0], config=CROWDNAV, stop_when_done=False)
    np.testing.assert_array_equal(first.crowds, second.crowds)
    np.testing.assert_array_equal(first.agent_pos, second.agent_pos)
    sim = CoupledSimulator(policies, scenario, CROWDNAV)
    for action in actions[:20]:
        sim.step(action)
    snapshot = sim.snapshot()
    for action in actions[20:]:
        sim.step(-action)  # other random goal changes happen on this branch
    sim.restore(snapshot)
    for k, action in enumerate(actions[20:], start=20):
        step = sim.step(action)
        np.testing.assert_array_equal(step.other_pos[0], first.other_pos[k])
        np.testing.assert_array_equal(step.agent_pos[0], first.agent_pos[k])
    goals_changed = not np.array_equal(sim.state.human_goal[0], -np.array(scenario.human_positions))
    assert goals_changed
    # one node branched into a batch gives each branch its own run's numbers
    sim.restore(sim.snapshot([0, 0]))
    assert (sim.state.rng == sim.state.rng[0]).all()


def test_invalid_settings_are_explained():
    for changes, message in [
        ({"goal_change_chance": 1.5}, "between 0 and 1"),
        ({"robot_fov": 0.0}, "degrees"),
        ({"human_fov": 90.0, "robot_visible": True}, "invisible robot"),
        ({"unicycle_motion": "skid"}, "unicycle_motion"),
    ]:
        with pytest.raises(ValueError, match=message):
            WorldConfig(**changes)
