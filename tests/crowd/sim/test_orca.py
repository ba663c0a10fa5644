"""ORCA against the RVO2 library itself, against hand-computed cases, and over long dense runs."""

import numpy as np
import pyrvo
import pytest

from search.crowd.sim.orca import orca_step, orca_velocities


def rvo2_velocities(pos, vel, pref, radii, speeds, neighbor_dist=10.0, max_neighbors=10, horizon=5.0, dt=0.25):
    """One RVO2 doStep over one world, as CrowdNav drives the library."""
    sim = pyrvo.RVOSimulator(dt, neighbor_dist, max_neighbors, horizon, horizon, 0.3, 1.0)
    for i in range(len(pos)):
        sim.add_agent(
            tuple(pos[i]),
            neighbor_dist,
            max_neighbors,
            horizon,
            horizon,
            float(radii[i]),
            float(speeds[i]),
            tuple(vel[i]),
        )
        sim.set_agent_pref_velocity(i, tuple(pref[i]))
    sim.do_step()
    return np.array([[sim.get_agent_velocity(i).x, sim.get_agent_velocity(i).y] for i in range(len(pos))])


@pytest.mark.parametrize("spread, n, max_neighbors", [(4.0, 10, 10), (2.0, 10, 10), (6.0, 12, 5), (1.5, 6, 3)])
def test_agrees_with_rvo2_on_random_scenes(spread, n, max_neighbors):
    rng = np.random.default_rng(int(spread * 100) + n)
    b = 600
    pos = rng.uniform(-spread, spread, (b, n, 2))
    vel = rng.uniform(-0.5, 0.5, (b, n, 2))
    pref = rng.uniform(-1.2, 1.2, (b, n, 2))
    radii = rng.uniform(0.2, 0.5, (b, n))
    speeds = rng.uniform(0.1, 1.5, (b, n))
    ours = orca_step(pos, vel, pref, radii, speeds, max_neighbors=max_neighbors)
    reference = np.stack(
        [rvo2_velocities(pos[w], vel[w], pref[w], radii[w], speeds[w], max_neighbors=max_neighbors) for w in range(b)]
    )
    assert np.abs(ours - reference).max() < 1e-4


def test_single_agent_takes_its_preferred_velocity_capped_at_max_speed():
    out = orca_step(np.zeros((1, 1, 2)), np.zeros((1, 1, 2)), [[[3.0, 4.0]]], [[0.3]], [[1.0]])
    np.testing.assert_allclose(out[0, 0], [0.6, 0.8], atol=1e-6)


def test_head_on_pair_by_hand():
    # Agents 2 m apart, radii 0.5, at rest, heading for each other at 1 m/s, tau = 5 s.
    # w = -(2, 0)/5 = (-0.4, 0) lies in the cut-off circle's region, so u = (0.2, 0) and each agent takes half:
    # the half-plane x <= 0.1 for the left agent, and the closest point to (1, 0) is (0.1, 0).
    pos = np.array([[[-1.0, 0.0], [1.0, 0.0]]])
    pref = np.array([[[1.0, 0.0], [-1.0, 0.0]]])
    out = orca_step(pos, np.zeros((1, 2, 2)), pref, [[0.5, 0.5]], [[1.0, 1.0]])
    np.testing.assert_allclose(out[0], [[0.1, 0.0], [-0.1, 0.0]], atol=1e-6)


def test_reciprocal_pair_shares_the_avoidance_equally():
    # Two agents slightly offset head-on: the scene is symmetric under a half turn about the origin, so
    # reciprocity gives exactly opposite new velocities, each side-stepping by the same amount.
    pos = np.array([[[-2.0, 0.1], [2.0, -0.1]]])
    pref = np.array([[[1.0, 0.0], [-1.0, 0.0]]])
    out = orca_step(pos, pref * 0.8, pref, [[0.3, 0.3]], [[1.0, 1.0]])[0]
    np.testing.assert_allclose(out[1], -out[0], atol=1e-6)
    assert out[0, 1] > 0.01 and out[1, 1] < -0.01  # each turns away from the other


def test_neighbours_outside_range_are_ignored():
    pos = np.array([[[0.0, 0.0], [20.0, 0.0]]])
    pref = np.array([[[1.0, 0.0], [-1.0, 0.0]]])
    out = orca_step(pos, np.zeros((1, 2, 2)), pref, [[0.3, 0.3]], [[1.0, 1.0]])
    np.testing.assert_allclose(out[0], pref[0], atol=1e-6)


def test_dense_crossing_never_overlaps_and_respects_speed_limits():
    # 24 agents swap places across a 4 m circle; ORCA with padded radii keeps the real discs apart.
    n, steps, dt = 24, 400, 0.25
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pos = np.stack([4 * np.cos(angles), 4 * np.sin(angles)], axis=1)[None]
    goals = -pos
    pos = pos + np.random.default_rng(0).uniform(-0.05, 0.05, pos.shape)  # a perfect ring deadlocks
    vel = np.zeros_like(pos)
    radius, padded = 0.3, 0.3 + 0.01 + 0.15
    speeds = np.full((1, n), 1.0)
    for _ in range(steps):
        to_goal = goals - pos
        length = np.linalg.norm(to_goal, axis=-1, keepdims=True)
        pref = np.where(length > 1, to_goal / length, to_goal)
        vel = orca_step(pos, vel, pref, np.full((1, n), padded), speeds, max_neighbors=n)
        assert np.linalg.norm(vel, axis=-1).max() <= 1.0 + 1e-5
        pos = pos + vel * dt
        gaps = np.linalg.norm(pos[0, :, None] - pos[0, None], axis=-1) + np.eye(n) * 10
        assert gaps.min() >= 2 * radius
    assert np.linalg.norm(goals - pos, axis=-1).max() < 1.0  # and they get there


def test_n_ego_computes_only_the_leading_agents():
    rng = np.random.default_rng(1)
    pos, vel, pref = rng.normal(size=(3, 4, 5, 2))[:3]
    radii, speeds = np.full((4, 5), 0.3), np.full((4, 5), 1.0)
    full = orca_velocities(pos, vel, pref, radii, speeds)
    first = orca_velocities(pos, vel, pref, radii, speeds, n_ego=1)
    np.testing.assert_array_equal(first[:, 0], full[:, 0])


@pytest.mark.parametrize(
    "bad, message",
    [
        (dict(positions=np.zeros((2, 3))), "positions must have shape"),
        (dict(radii=np.zeros((1, 4))), "radii has shape"),
        (dict(velocities=np.full((1, 3, 2), np.nan)), "velocities contains NaN"),
        (dict(max_speeds=-np.ones((1, 3))), "non-negative"),
    ],
)
def test_bad_inputs_are_named(bad, message):
    args = dict(
        positions=np.zeros((1, 3, 2)),
        velocities=np.zeros((1, 3, 2)),
        preferred_velocities=np.zeros((1, 3, 2)),
        radii=np.ones((1, 3)),
        max_speeds=np.ones((1, 3)),
    )
    args.update(bad)
    with pytest.raises(ValueError, match=message):
        orca_step(**args)
