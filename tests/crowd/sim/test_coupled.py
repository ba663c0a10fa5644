"""The coupled simulator: shared crowd, snapshot/restore, branching, replay."""

import os

import numpy as np
import pytest

from search.crowd.agents.policies import load_policy
from search.crowd.sim.coupled import CoupledSimulator, replay
from search.crowd.sim.scenarios import load_scenario
from search.crowd.sim.world import WorldConfig


def make(names=("goal", "orca"), scenario="paper-bl-tr", batch=1, config=None):
    return CoupledSimulator([load_policy(n) for n in names], load_scenario(scenario), config, batch=batch)


def env_actions(steps, batch=1, seed=0, n=10):
    return np.random.default_rng(seed).uniform(-0.25, 0.25, (steps, batch, n, 2))


def test_every_agent_sees_the_same_crowd():
    sim = make(("goal", "orca", "social_force"))
    for action in env_actions(20):
        sim.step(action)
        observations = sim.observations()
        humans = [o.robot_node[:, None, 0:2] + o.spatial_edges for o in observations]
        for other in humans[1:]:
            np.testing.assert_allclose(other, humans[0], atol=1e-12)


def test_invisible_robots_do_not_change_the_crowd():
    actions = env_actions(30)
    runs = []
    for names in (("goal", "orca"), ("social_force", "goal")):
        sim = make(names)
        runs.append(np.stack([sim.step(a).other_pos for a in actions]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_visible_robots_each_get_their_own_crowd():
    sim = make(config=WorldConfig(robot_visible=True, human_v_pref=1.0))
    for action in env_actions(25):
        sim.step(action)
    crowds = [sim.state.human_pos[sim._where(k)[0]] for k in range(2)]
    assert not np.allclose(crowds[0], crowds[1])


def test_snapshot_and_restore_equal_a_straight_run():
    actions = env_actions(40)
    straight = make()
    record = [straight.step(a) for a in actions]
    branched = make()
    for a in actions[:15]:
        branched.step(a)
    snap = branched.snapshot()
    for a in actions[15:25]:
        branched.step(-a)  # wander off
    branched.restore(snap)
    for a, expected in zip(actions[15:], record[15:], strict=True):
        got = branched.step(a)
        np.testing.assert_array_equal(got.agent_pos, expected.agent_pos)
        np.testing.assert_array_equal(got.other_pos, expected.other_pos)
        np.testing.assert_array_equal(got.rewards, expected.rewards)
    assert branched.state.equals(straight.state)


def test_one_node_branched_into_a_batch_matches_single_runs():
    actions = env_actions(30, batch=1)
    sim = make()
    for a in actions[:10]:
        sim.step(a)
    node = sim.snapshot([0, 0, 0])
    futures = env_actions(20, batch=3, seed=5)
    sim.restore(node)
    batched = [sim.step(a) for a in futures]
    for b in range(3):
        single = make()
        for a in actions[:10]:
            single.step(a)
        for t, a in enumerate(futures):
            step = single.step(a[[b]])
            np.testing.assert_array_equal(step.agent_pos[0], batched[t].agent_pos[b])


def test_replay_reproduces_a_trajectory_bit_for_bit():
    actions = env_actions(60)[:, 0]
    policies = [load_policy("goal"), load_policy("social_force")]
    scenario = load_scenario("paper-tl-br")
    sim = CoupledSimulator(policies, scenario)
    recorded = []
    for a in actions:
        recorded.append(sim.step(a[None]))
        if sim.all_done[0]:
            break
    again = replay(policies, scenario, actions)
    assert len(again.time) == len(recorded)
    np.testing.assert_array_equal(again.agent_pos, np.stack([s.agent_pos[0] for s in recorded]))
    np.testing.assert_array_equal(again.other_pos, np.stack([s.other_pos[0] for s in recorded]))
    np.testing.assert_array_equal(again.agent_actions, np.stack([s.agent_actions[0] for s in recorded]))
    third = replay(policies, scenario, actions.reshape(len(actions), -1))
    np.testing.assert_array_equal(third.agent_pos, again.agent_pos)


def test_finished_robots_stop_and_report_outcomes():
    sim = make(("goal", "orca"), scenario="paper-code")
    finished_earlier = np.zeros((1, 2), dtype=bool)
    for a in env_actions(200):
        step = sim.step(a)
        assert np.all(step.agent_actions[finished_earlier] == 0)  # finished robots get no action
        finished_earlier = step.done
        if sim.all_done[0]:
            break
    assert sim.all_done[0]
    assert set(step.outcome[0]) <= {1, 2, 3}


def test_needs_two_agents_and_valid_actions():
    with pytest.raises(ValueError, match="at least two"):
        CoupledSimulator([load_policy("goal")], load_scenario("paper-bl-tr"))
    with pytest.raises(ValueError, match="unknown agent"):
        load_policy("nobody")
    sim = make()
    with pytest.raises(ValueError, match="outside the bound"):
        sim.step(np.ones((1, 10, 2)))


def test_crowds_are_shared_or_one_per_agent():
    shared = make()
    step = shared.step(env_actions(1)[0])
    assert step.crowds.shape == (1, 1, 10, 2)
    np.testing.assert_array_equal(step.crowds[:, 0], step.other_pos)
    visible = make(config=WorldConfig(robot_visible=True, human_v_pref=1.0))
    for action in env_actions(20):
        step = visible.step(action)
    assert step.crowds.shape == (1, 2, 10, 2)
    np.testing.assert_array_equal(step.crowds[:, 0], step.other_pos)
    assert not np.allclose(step.crowds[:, 0], step.crowds[:, 1])


@pytest.mark.parametrize("visible", [False, True])
@pytest.mark.parametrize("rows", [[2], [4, 1], [0, 1, 3, 4, 5]])
def test_assign_overwrites_some_rows_with_a_snapshot_and_leaves_the_others(visible, rows):
    config = WorldConfig(robot_visible=visible)
    names = ("goal", "med")  # a recurrent agent: its hidden state must travel with the rows too
    source, target = make(names, batch=len(rows), config=config), make(names, batch=6, config=config)
    for a in env_actions(12, batch=len(rows), seed=1):
        source.step(a)
    for a in env_actions(7, batch=6, seed=2):
        target.step(a)
    others = [b for b in range(6) if b not in rows]
    untouched = target.snapshot(others)
    target.assign(rows, source.snapshot())
    for j, row in enumerate(rows):
        mine, theirs = target.snapshot([row]), source.snapshot([j])
        assert mine.state.equals(theirs.state)
        for a, b in zip(mine.policy_states, theirs.policy_states, strict=True):
            assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    after = target.snapshot(others)
    assert after.state.equals(untouched.state)
    for a, b in zip(after.policy_states, untouched.policy_states, strict=True):
        assert all(np.array_equal(a[k], b[k]) for k in a)
    for a in env_actions(10, batch=6, seed=3):  # the assigned rows go on as the source's (torch's numbers may
        got, expected = target.step(a), source.step(a[rows])  # differ in the last bits between batch sizes)
        np.testing.assert_allclose(got.agent_pos[rows], expected.agent_pos, rtol=0, atol=1e-5)
        np.testing.assert_allclose(got.crowds[rows], expected.crowds, rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="rows to overwrite"):
        target.assign([0, 1], source.snapshot([0]))


@pytest.mark.parametrize(
    "config",
    [None, WorldConfig(robot_visible=True), WorldConfig(env_action_mode="preferred")],
    ids=["shared crowd", "visible robots", "preferred mode"],
)
def test_the_crowd_helper_thread_changes_nothing(monkeypatch, config):
    """Crowds computed on the helper thread while the policies act equal crowds computed in line, bit for bit."""
    from search.crowd.sim import coupled

    assert coupled._crowd_worker() is not None or len(os.sched_getaffinity(0)) == 1
    runs = []
    for helper in (True, False):
        if not helper:
            monkeypatch.setattr(coupled, "_crowd_worker", lambda: None)
        sim = make(batch=6, config=config)
        steps = [sim.step(a) for a in env_actions(30, batch=6, seed=3)]
        runs.append((np.stack([s.crowds for s in steps]), np.stack([s.agent_pos for s in steps]), sim.state.done))
    for with_helper, in_line in zip(*runs, strict=True):
        assert np.array_equal(with_helper, in_line)


def _steps_in_child(queue) -> None:
    sim = make(batch=2)
    queue.put(np.stack([sim.step(a).crowds for a in env_actions(5, batch=2, seed=1)]))


def test_a_forked_child_gets_its_own_crowd_helper():
    """A child forked after the parent used the helper thread has no such thread: it must make its own, not
    wait for ever on the parent's."""
    import multiprocessing

    parent = make(batch=2)
    expected = np.stack([parent.step(a).crowds for a in env_actions(5, batch=2, seed=1)])
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_steps_in_child, args=(queue,))
    child.start()
    try:
        assert np.array_equal(queue.get(timeout=60), expected)
    finally:
        child.join(10)
        if child.is_alive():
            child.kill()


@pytest.mark.parametrize("visible", [False, True])
def test_observations_are_each_agents_view_of_the_state_bit_for_bit(visible):
    from search.crowd.sim.observation import observe

    sim = CoupledSimulator(
        [load_policy("goal"), load_policy("orca")],
        load_scenario("paper-bl-tr"),
        WorldConfig(robot_visible=visible),
        batch=3,
    )
    rng = np.random.default_rng(4)
    for _ in range(6):
        sim.step(rng.uniform(-0.25, 0.25, (3, 10, 2)))
    state, noise = sim.state, rng.uniform(-0.25, 0.25, (3, 10, 2))
    for k in range(2):
        worlds = slice(k * 3, (k + 1) * 3) if visible else slice(None)
        robot = 0 if visible else k
        for shift in (None, noise):
            seen = observe(state, sim.config, robot, worlds, shift)
            pos = state.robot_pos[worlds, robot]
            humans = state.human_pos[worlds] if shift is None else state.human_pos[worlds] + shift
            np.testing.assert_array_equal(seen.spatial_edges, humans - pos[:, None, :])
            offset = state.robot_goal[worlds, robot] - pos
            distance = np.sqrt(offset[:, 0] * offset[:, 0] + offset[:, 1] * offset[:, 1])
            np.testing.assert_array_equal(
                seen.robot_node,
                np.column_stack(
                    [
                        pos,
                        np.full(3, sim.config.robot_radius),
                        state.robot_goal[worlds, robot],
                        np.full(3, sim.config.robot_v_pref),
                        state.robot_theta[worlds, robot],
                        offset,
                        distance,
                        offset / distance[:, None],
                    ]
                ),
            )
            np.testing.assert_array_equal(seen.temporal_edges, state.robot_vel[worlds, robot])
            np.testing.assert_array_equal(seen.human_velocities, state.human_vel[worlds])
            np.testing.assert_array_equal(seen.human_radii, state.human_radius[worlds])
            np.testing.assert_array_equal(seen.done, state.done[worlds, robot])
            assert seen.human_mask.all() and seen.human_mask.shape == (3, 10)


def test_the_robot_node_carries_the_goal_relative_to_the_robot():
    """Field by field, by name; a robot on its goal has distance 0 and no direction (not NaN)."""
    from search.crowd.sim.observation import ROBOT_NODE_FIELDS, observe

    scenario = load_scenario("paper-bl-tr")
    config = scenario.config()
    state = scenario.initial_state(config, 2, 1)
    state.robot_pos[1, 0] = state.robot_goal[1, 0]
    node = dict(zip(ROBOT_NODE_FIELDS, observe(state, config, 0).robot_node.T, strict=True))
    gx, gy = state.robot_goal[0, 0]
    px, py = state.robot_pos[0, 0]
    assert (node["goal_dx"][0], node["goal_dy"][0]) == (gx - px, gy - py)
    assert node["goal_distance"][0] == pytest.approx(np.hypot(gx - px, gy - py))
    assert np.hypot(node["goal_ux"][0], node["goal_uy"][0]) == pytest.approx(1.0)
    assert node["goal_ux"][0] * (gx - px) > 0 and node["goal_uy"][0] * (gy - py) > 0
    assert (node["goal_distance"][1], node["goal_ux"][1], node["goal_uy"][1]) == (0.0, 0.0, 0.0)
    assert (node["px"][0], node["gx"][0], node["v_pref"][0]) == (px, gx, config.robot_v_pref)
