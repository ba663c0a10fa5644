"""What a robot perceives, and the policy interface shared by the coupled simulator, evaluation and search.

A policy maps a batch of observations to a batch of actions. Its recurrent state is a dict of arrays with the
batch axis first, returned rather than kept, so the simulator can snapshot and restore it as plain copies.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numba
import numpy as np

from search.crowd.sim.world import WorldConfig, WorldState, in_view

PolicyState = dict[str, np.ndarray]

# The robot node's fields, in order. The first seven are CrowdNav_DSRNN's (absolute position and goal); the goal
# relative to the robot follows, as a deliberate departure: through the absolute coordinates alone a goal offset
# that is small next to the world's +-12 m reads like a low-gain controller, and trained robots circled their goal.
ROBOT_NODE_FIELDS = (
    "px",
    "py",
    "radius",
    "gx",
    "gy",
    "v_pref",
    "theta",
    "goal_dx",
    "goal_dy",
    "goal_distance",
    "goal_ux",
    "goal_uy",
)
ROBOT_NODE_SIZE = len(ROBOT_NODE_FIELDS)


@dataclass
class Observation:
    """What one robot per world perceives, batch axis first (DS-RNN's observation plus what scripts need)."""

    robot_node: np.ndarray  # (B, ROBOT_NODE_SIZE): the fields ROBOT_NODE_FIELDS
    temporal_edges: np.ndarray  # (B, 2): robot velocity
    spatial_edges: np.ndarray  # (B, n, 2): human position minus robot position
    human_velocities: np.ndarray  # (B, n, 2)
    human_radii: np.ndarray  # (B, n)
    human_mask: np.ndarray  # (B, n) bool: the human is observed (it exists, within the robot's field of view)
    done: np.ndarray  # (B,) bool: this robot has finished (its action is ignored)

    @property
    def batch(self) -> int:
        return int(self.robot_node.shape[0])


def observe(
    state: WorldState,
    config: WorldConfig,
    robot: int,
    worlds: slice = slice(None),
    position_noise: np.ndarray | None = None,
) -> Observation:
    """Robot ``robot``'s observation in the worlds ``worlds`` (a slice); ``position_noise`` (B, n, 2) shifts the
    humans it sees (the observation mode of the environment action)."""
    start, stop, step = worlds.indices(state.n_worlds)
    if step != 1:
        raise ValueError("observe takes a contiguous slice of worlds")
    return observe_agents(state, config, [(start, robot)], stop - start, position_noise)[0]


def observe_agents(
    state: WorldState,
    config: WorldConfig,
    agents: list[tuple[int, int]],
    batch: int,
    position_noise: np.ndarray | None = None,
) -> list[Observation]:
    """Several robots' observations in one pass (a coupled step observes every agent): agent ``(first, robot)``
    is robot ``robot`` in worlds ``first`` to ``first + batch``."""
    k, n = len(agents), state.human_pos.shape[1]
    robot_node, temporal_edges = np.empty((k, batch, ROBOT_NODE_SIZE)), np.empty((k, batch, 2))
    spatial_edges, human_velocities = np.empty((k, batch, n, 2)), np.empty((k, batch, n, 2))
    human_radii, done = np.empty((k, batch, n)), np.empty((k, batch), dtype=bool)
    human_mask = np.ones((k, batch, n), dtype=bool)
    where = np.array(agents, dtype=np.int64).reshape(k, 2)
    _observe(
        state.robot_pos,
        state.robot_goal,
        state.robot_theta,
        state.robot_vel,
        state.done,
        state.human_pos,
        state.human_vel,
        state.human_radius,
        where,
        position_noise,
        float(config.robot_radius),
        float(config.robot_v_pref),
        robot_node,
        temporal_edges,
        spatial_edges,
        human_velocities,
        human_radii,
        done,
    )
    if config.robot_fov < 360:  # CrowdNav's robot faces its velocity (holonomic) or its heading (unicycle)
        heading = (
            robot_node[..., 6]
            if config.kinematics == "unicycle"
            else np.arctan2(temporal_edges[..., 1], temporal_edges[..., 0])
        )
        human_mask = in_view(heading, spatial_edges, config.robot_fov)
    return [
        Observation(
            robot_node[i],
            temporal_edges[i],
            spatial_edges[i],
            human_velocities[i],
            human_radii[i],
            human_mask[i],
            done[i],
        )
        for i in range(k)
    ]


@numba.njit(cache=True)
def _observe(
    robot_pos: np.ndarray,
    robot_goal: np.ndarray,
    robot_theta: np.ndarray,
    robot_vel: np.ndarray,
    robot_done: np.ndarray,
    human_pos: np.ndarray,
    human_vel: np.ndarray,
    human_radius: np.ndarray,
    where: np.ndarray,
    noise: np.ndarray | None,
    radius: float,
    v_pref: float,
    robot_node: np.ndarray,
    temporal_edges: np.ndarray,
    spatial_edges: np.ndarray,
    human_velocities: np.ndarray,
    human_radii: np.ndarray,
    done: np.ndarray,
) -> None:
    """Fill every agent's observation arrays in one pass (numpy took a dozen calls per agent)."""
    for k in range(where.shape[0]):
        first, robot = where[k, 0], where[k, 1]
        for b in range(robot_node.shape[1]):
            w = first + b
            x, y = robot_pos[w, robot, 0], robot_pos[w, robot, 1]
            robot_node[k, b, 0], robot_node[k, b, 1], robot_node[k, b, 2] = x, y, radius
            robot_node[k, b, 3], robot_node[k, b, 4] = robot_goal[w, robot, 0], robot_goal[w, robot, 1]
            robot_node[k, b, 5], robot_node[k, b, 6] = v_pref, robot_theta[w, robot]
            dx, dy = robot_goal[w, robot, 0] - x, robot_goal[w, robot, 1] - y
            distance = np.sqrt(dx * dx + dy * dy)
            robot_node[k, b, 7], robot_node[k, b, 8], robot_node[k, b, 9] = dx, dy, distance
            if distance > 0.0:
                robot_node[k, b, 10], robot_node[k, b, 11] = dx / distance, dy / distance
            else:
                robot_node[k, b, 10], robot_node[k, b, 11] = 0.0, 0.0
            temporal_edges[k, b, 0], temporal_edges[k, b, 1] = robot_vel[w, robot, 0], robot_vel[w, robot, 1]
            done[k, b] = robot_done[w, robot]
            for h in range(human_pos.shape[1]):
                hx, hy = human_pos[w, h, 0], human_pos[w, h, 1]
                if noise is not None:
                    hx, hy = hx + noise[b, h, 0], hy + noise[b, h, 1]
                spatial_edges[k, b, h, 0], spatial_edges[k, b, h, 1] = hx - x, hy - y
                human_velocities[k, b, h, 0], human_velocities[k, b, h, 1] = human_vel[w, h, 0], human_vel[w, h, 1]
                human_radii[k, b, h] = human_radius[w, h]


class Policy(Protocol):
    """Batched observations in, batched actions (B, 2) out; recurrent state passed explicitly."""

    name: str

    def initial_state(self, batch: int) -> PolicyState: ...

    def act(self, observation: Observation, state: PolicyState) -> tuple[np.ndarray, PolicyState]: ...
