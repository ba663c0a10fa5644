"""The agent registry (`load_policy`: scripted robots and the shipped or trained DS-RNN checkpoints) and the
scripted robots. The policy interface itself lives in `search.crowd.sim.observation`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from search.crowd.sim.observation import Observation, Policy, PolicyState
from search.crowd.sim.orca import orca_velocities
from search.crowd.sim.social_force import social_force_velocities


def _toward_goal(observation: Observation, v_pref: np.ndarray) -> np.ndarray:
    """Velocity straight at the goal at v_pref, slowing so the last step lands on it."""
    to_goal = observation.robot_node[:, 3:5] - observation.robot_node[:, 0:2]
    dist = np.linalg.norm(to_goal, axis=1, keepdims=True)
    return np.where(dist > v_pref, to_goal * (v_pref / np.maximum(dist, 1e-300)), to_goal)


class _Stateless:
    def initial_state(self, batch: int) -> PolicyState:
        return {}


class GoalPolicy(_Stateless):
    """Straight to the goal at full speed, ignoring the crowd."""

    name = "goal"

    def act(self, observation, state):
        return _toward_goal(observation, observation.robot_node[:, 5:6]), state


class OrcaRobotPolicy(_Stateless):
    """A robot that steers by ORCA through the humans it observes (as CrowdNav's ORCA robot baseline)."""

    name = "orca"

    def __init__(self, time_horizon: float = 5.0, safety_space: float = 0.15, dt: float = 0.25):
        self.time_horizon, self.safety_space, self.dt = time_horizon, safety_space, dt

    def act(self, observation, state):
        b, n = observation.human_mask.shape
        robot_pos = observation.robot_node[:, 0:2]
        v_pref = observation.robot_node[:, 5]
        pad = 0.01 + self.safety_space
        humans = robot_pos[:, None, :] + observation.spatial_edges
        far = np.where(observation.human_mask[..., None], humans, 1e6)  # padded humans out of range
        pos = np.concatenate([robot_pos[:, None, :], far], axis=1)
        vel = np.concatenate([observation.temporal_edges[:, None, :], observation.human_velocities], axis=1)
        pref = np.concatenate([_toward_goal(observation, v_pref[:, None])[:, None, :], np.zeros((b, n, 2))], axis=1)
        radii = np.concatenate([observation.robot_node[:, 2:3], observation.human_radii], axis=1) + pad
        speeds = np.concatenate([v_pref[:, None], np.ones((b, n))], axis=1)
        action = orca_velocities(
            pos, vel, pref, radii, speeds, max_neighbors=n, time_horizon=self.time_horizon, dt=self.dt, n_ego=1
        )
        return action[:, 0], state


class SocialForceRobotPolicy(_Stateless):
    """A robot pushed towards its goal and away from humans by social forces (CrowdNav's parameters)."""

    name = "social_force"

    def __init__(self, A: float = 2.0, B: float = 1.0, KI: float = 1.0, dt: float = 0.25):
        self.A, self.B, self.KI, self.dt = A, B, KI, dt

    def act(self, observation, state):
        robot_pos = observation.robot_node[:, None, 0:2]
        humans = robot_pos + observation.spatial_edges
        far = np.where(observation.human_mask[..., None], humans, 1e6)
        velocity = social_force_velocities(
            robot_pos,
            observation.temporal_edges[:, None, :],
            observation.robot_node[:, None, 3:5],
            observation.robot_node[:, None, 2],
            observation.robot_node[:, None, 5],
            A=self.A,
            B=self.B,
            KI=self.KI,
            dt=self.dt,
            others_pos=far,
            others_radius=observation.human_radii,
        )
        return velocity[:, 0], state


SCRIPTED = {"goal": GoalPolicy, "orca": OrcaRobotPolicy, "social_force": SocialForceRobotPolicy}


SHIPPED_AGENTS = ("lo", "med", "hi")
AGENTS_DIR = Path(__file__).parent


def load_policy(spec: str) -> Policy:
    """A policy by name: a scripted one (``goal``, ``orca``, ``social_force``), a shipped DS-RNN agent (``lo``,
    ``med``, ``hi``), a checkpoint or TorchScript file, or ``module:attribute`` (an object with the Policy
    interface, or a zero-argument callable that returns one)."""
    if spec in SCRIPTED:
        return SCRIPTED[spec]()
    if spec in SHIPPED_AGENTS or (Path(spec).suffix or "/" in spec) and (":" not in spec or Path(spec).is_file()):
        from search.crowd.agents.dsrnn import load_checkpoint_policy  # torch only when a network is asked for

        return load_checkpoint_policy(AGENTS_DIR / f"{spec}.pt" if spec in SHIPPED_AGENTS else spec, name=spec)
    if ":" in spec:
        from importlib import import_module

        module_name, _, attribute = spec.partition(":")
        try:
            target = getattr(import_module(module_name), attribute)
        except (ImportError, AttributeError) as error:
            raise ValueError(f"cannot load policy {spec!r}: {error}") from None
        policy = target() if callable(target) and not hasattr(target, "act") and _takes_nothing(target) else target
        if not (hasattr(policy, "act") and hasattr(policy, "initial_state")):
            raise ValueError(
                f"{spec!r} is not a crowd policy: it needs act() and initial_state() (an agent of a Gymnasium "
                "world acts in the world its scenario file names: give the scenario, e.g. --scenario FILE)"
            )
        return policy
    raise ValueError(
        f"unknown agent {spec!r}: use one of {sorted(SCRIPTED) + list(SHIPPED_AGENTS)}, a checkpoint "
        "file or module:attribute"
    )


def _takes_nothing(target) -> bool:
    """Whether ``target`` can be called with no arguments (a factory of policies, not a function of observations)."""
    import inspect

    try:
        inspect.signature(target).bind()
    except (TypeError, ValueError):
        return False
    return True


def trained_world(spec: str) -> dict:
    """The world settings an agent brings with it: a CrowdNav_DSRNN checkpoint's, read from its model folder's
    config; none for every other agent."""
    if spec in SCRIPTED or spec in SHIPPED_AGENTS or not Path(spec).suffix or not Path(spec).is_file():
        return {}
    from search.crowd.agents.crowdnav import is_crowdnav_file, read_crowdnav_config

    return dict(read_crowdnav_config(spec).world) if is_crowdnav_file(spec) else {}


def comparison_world(agents: list[str], explicit: dict, scenario_world: dict | None = None) -> dict:
    """The world settings agents are compared in: those their checkpoints were trained in, under the settings a
    scenario file's ``[world]`` gives (``scenario_world``), under the ``explicit`` ones (command line, study file).
    Agents trained in different worlds need the differing settings given explicitly."""
    world: dict = {}
    for agent in agents:
        for key, value in trained_world(agent).items():
            if key in world and world[key][1] != value and key not in explicit:
                raise ValueError(
                    f"agents {world[key][0]} and {agent} were trained in different worlds ({key} = "
                    f"{world[key][1]!r} and {value!r}): choose one, e.g. --world {key}={value}"
                )
            world.setdefault(key, (agent, value))
    scenario_world = scenario_world or {}
    return {key: value for key, (_, value) in world.items() if key not in scenario_world} | explicit
