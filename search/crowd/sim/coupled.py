"""The coupled simulator: N >= 2 robot policies in the same scenario, driven by one shared environment action.

With the robot invisible to humans (the default) every agent's robot lives in the same world and the crowd is
computed once per step, so every agent sees identical humans. With a visible robot each agent gets its own copy
of the world (worlds ``k * B + b`` belong to agent ``k``) and the same environment action drives every copy.

The simulator runs ``B`` independent coupled scenarios at once, so a search can roll out many branches in one
batched call. ``snapshot()`` / ``restore()`` copy arrays (the world state's rows and every policy's recurrent state),
so a search branches from any node without replaying from reset.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import cache
from typing import cast

import numpy as np
from numpy.typing import ArrayLike

from search.crowd.sim import world
from search.crowd.sim.observation import Observation, Policy, PolicyState, observe_agents
from search.crowd.sim.scenarios import Scenario
from search.crowd.sim.world import WorldConfig, WorldState

# what turns the agents' proposed actions (one (B, 2) array per agent) into those executed, given each row's steps
# taken so far: `search.solvers.follow.Follow`
Override = Callable[[list[np.ndarray], np.ndarray], list[np.ndarray]]


@dataclass
class Snapshot:
    """A frozen copy of B coupled scenarios: world state plus each policy's recurrent state."""

    state: WorldState
    policy_states: list[PolicyState]
    batch: int


@dataclass
class CoupledStep:
    """What one coupled step exposes to rewards and recorders; agent axis second: (B, N, ...)."""

    agent_actions: np.ndarray  # (B, N, 2) the actions the policies chose (zero once finished)
    agent_pos: np.ndarray  # (B, N, 2) the robots after the move
    agent_vel: np.ndarray  # (B, N, 2)
    other_pos: np.ndarray  # (B, n, 2) the crowd after the move (agent 0's world when robots are visible)
    crowds: np.ndarray  # (B, C, n, 2) every crowd: C = 1 when shared, one per agent (C = N) when robots are visible
    rewards: np.ndarray  # (B, N) each robot's navigation reward
    done: np.ndarray  # (B, N) bool
    newly_done: np.ndarray  # (B, N) bool: finished on this step
    outcome: np.ndarray  # (B, N) int8, see search.core.outcomes
    time: np.ndarray  # (B,)


class CoupledSimulator:
    def __init__(self, policies: list[Policy], scenario: Scenario, config: WorldConfig | None = None, batch: int = 1):
        if len(policies) < 2:
            raise ValueError("a coupled simulator compares at least two policies")
        if batch < 1:
            raise ValueError("batch must be at least 1")
        self.policies = list(policies)
        self.scenario = scenario
        self.config = scenario.config(config)
        self.batch = batch
        self.override: Override | None = (
            None  # a search.solvers.follow.Follow or alike: the actions executed given those proposed
        )
        self.proposed = np.zeros((batch, len(policies), 2))  # each agent's own choice on the last step
        self.reset()

    @property
    def n_agents(self) -> int:
        return len(self.policies)

    @property
    def shared_crowd(self) -> bool:
        return not self.config.robot_visible

    def reset(self, batch: int | None = None) -> None:
        """Every one of the B coupled scenarios back to the scenario's initial state."""
        self.batch = batch or self.batch
        if self.shared_crowd:
            self.state = self.scenario.initial_state(self.config, self.batch, self.n_agents)
        else:
            self.state = self.scenario.initial_state(self.config, self.batch * self.n_agents, 1)
        self.policy_states = [p.initial_state(self.batch) for p in self.policies]

    def _where(self, agent: int) -> tuple[slice, int]:
        """(worlds, robot index) of one agent's robot."""
        if self.shared_crowd:
            return slice(None), agent
        return slice(agent * self.batch, (agent + 1) * self.batch), 0

    def gather(self, array: np.ndarray) -> np.ndarray:
        """A per-robot world array (W, R, ...) as (B, N, ...)."""
        if self.shared_crowd:
            return array
        return np.stack([array[self._where(k)] for k in range(self.n_agents)], axis=1)

    def observations(self, env_action: np.ndarray | None = None) -> list[Observation]:
        noise = env_action if self.config.env_action_mode == "observation" else None
        agents = [(worlds.start or 0, robot) for worlds, robot in map(self._where, range(self.n_agents))]
        return observe_agents(self.state, self.config, agents, self.batch, noise)

    def step(self, env_action: ArrayLike) -> CoupledStep:
        """One step of every coupled scenario under the shared environment action (B, n, 2) or (B, 2n)."""
        actions, reward, newly_done = self.advance(env_action)
        done = self.gather(self.state.done)
        return CoupledStep(
            agent_actions=actions,
            agent_pos=self.gather(self.state.robot_pos).copy(),
            agent_vel=self.gather(self.state.robot_vel).copy(),
            other_pos=self.state.human_pos[: self.batch].copy(),
            crowds=self.crowds(),
            rewards=self.gather(reward),
            done=done.copy(),
            newly_done=newly_done,
            outcome=self.gather(self.state.outcome).copy(),
            time=self.state.time[: self.batch].copy(),
        )

    def advance(self, env_action: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``step`` without its record: the robots' actions (B, N, 2), navigation rewards (W, R) and which robots
        finished on this step (B, N); the new state is ``self.state`` (read robots through ``gather``).

        The humans' next velocities depend on the state and the environment action only (a visible robot is
        seen at its last velocity), so on a machine with a second core they are computed there, by compiled
        code that leaves the interpreter free, while the policies act."""
        env_action = world.check_env_action(env_action, self.batch, self.config)
        world_action = env_action if self.shared_crowd else np.tile(env_action, (self.n_agents, 1, 1))
        crowd_action = None if self.config.env_action_mode == "observation" else world_action
        worker = _crowd_worker()
        humans = worker.submit(world.human_velocities, self.state, self.config, crowd_action) if worker else None
        observations = self.observations(env_action)
        actions = np.zeros((self.batch, self.n_agents, 2))
        for k, (policy, observation) in enumerate(zip(self.policies, observations, strict=True)):
            action, self.policy_states[k] = policy.act(observation, self.policy_states[k])
            actions[:, k] = action
            if observation.done.any():
                actions[observation.done, k] = 0.0
        self.proposed = actions
        if self.override is not None:
            taken = np.rint(self.state.time[: self.batch] / self.config.dt).astype(np.int64)
            actions = np.stack(self.override(list(actions.transpose(1, 0, 2)), taken), axis=1)
        robot_action = actions if self.shared_crowd else actions.transpose(1, 0, 2).reshape(-1, 1, 2)
        human_vel = humans.result() if humans else world.human_velocities(self.state, self.config, crowd_action)
        was_done = self.gather(self.state.done).copy()
        reward = world.advance(self.state, self.config, robot_action, human_vel)  # checked above
        return actions, reward, self.gather(self.state.done) & ~was_done

    def crowds(self) -> np.ndarray:
        """(B, C, n, 2) the humans of every crowd: one shared crowd, or each agent's own."""
        if self.shared_crowd:
            return self.state.human_pos[:, None].copy()
        return np.stack([self.state.human_pos[self._where(k)[0]] for k in range(self.n_agents)], axis=1)

    @property
    def all_done(self) -> np.ndarray:
        """(B,) every agent has finished."""
        return cast(np.ndarray, self.gather(self.state.done).all(axis=1))  # an array: the axis is given

    def snapshot(self, index: ArrayLike | None = None) -> Snapshot:
        """A copy of the coupled scenarios ``index`` (all by default; indices may repeat to branch one node
        into several)."""
        index = np.arange(self.batch) if index is None else np.asarray(index, dtype=np.int64).reshape(-1)
        if self.shared_crowd:
            worlds = index
        else:
            worlds = np.concatenate([k * self.batch + index for k in range(self.n_agents)])
        policy_states = [{key: value.take(index, axis=0) for key, value in s.items()} for s in self.policy_states]
        return Snapshot(self.state.take(worlds), policy_states, len(index))

    def restore(self, snapshot: Snapshot) -> None:
        """Continue from a snapshot; the batch becomes the snapshot's."""
        self.batch = snapshot.batch
        self.state = snapshot.state.copy()
        self.policy_states = [{key: value.copy() for key, value in s.items()} for s in snapshot.policy_states]

    def assign(self, index: ArrayLike | list[int], snapshot: Snapshot) -> None:
        """Overwrite the coupled scenarios ``index`` with a snapshot's (as many rows; the batch keeps its size)."""
        rows = index if isinstance(index, list) else np.asarray(index, dtype=np.int64).reshape(-1).tolist()
        if len(rows) != snapshot.batch:
            raise ValueError(f"{len(rows)} rows to overwrite, but the snapshot holds {snapshot.batch}")
        pairs = [
            (state[key], value)
            for state, new in zip(self.policy_states, snapshot.policy_states, strict=True)
            for key, value in new.items()
        ]
        if self.shared_crowd:  # rows are worlds: one pass over every array
            world.assign_rows(self.state.row_pairs(snapshot.state) + pairs, rows)
        else:
            self.state.assign([k * self.batch + row for k in range(self.n_agents) for row in rows], snapshot.state)
            world.assign_rows(pairs, rows)


@dataclass
class Trajectory:
    """One coupled scenario, step by step: what a summary records and a replay must reproduce."""

    env_actions: np.ndarray  # (T, n, 2)
    agent_actions: np.ndarray  # (T, N, 2)
    agent_pos: np.ndarray  # (T, N, 2) the robots
    other_pos: np.ndarray  # (T, n, 2) the shared crowd (agent 0's when robots are visible)
    crowds: np.ndarray  # (T, C, n, 2) every crowd, see CoupledStep
    rewards: np.ndarray  # (T, N)
    outcome: np.ndarray  # (N,) int8
    event_time: np.ndarray  # (N,)
    path_length: np.ndarray  # (N,)
    min_clearance: np.ndarray  # (N,)
    time: np.ndarray  # (T,)

    def head(self, steps: int) -> Trajectory:
        """The first ``steps`` steps (the per-robot totals stay those of the whole run; events carry their time)."""
        per_step = ("env_actions", "agent_actions", "agent_pos", "other_pos", "crowds", "rewards", "time")
        return replace(self, **{name: getattr(self, name)[:steps] for name in per_step})


@cache
def _crowd_worker() -> ThreadPoolExecutor | None:
    """The thread that computes crowds while policies act; None on a single core."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return ThreadPoolExecutor(1, thread_name_prefix="foil-crowd") if cores > 1 else None


os.register_at_fork(after_in_child=_crowd_worker.cache_clear)  # a forked child does not inherit the thread


def replay(
    policies: list[Policy],
    scenario: Scenario,
    env_actions: ArrayLike,
    config: WorldConfig | None = None,
    stop_when_done: bool = True,
    coda_to: int = 0,
    override: Override | None = None,
) -> Trajectory:
    """Run one coupled scenario from its initial state under a sequence of environment actions.

    With ``coda_to`` the run goes on after the last action without pushes (zero environment actions) until every
    robot's episode has ended or ``coda_to`` steps have been taken in all: a clip's coda, which shows how the
    robots still on their way fare after the search's trajectory ended. ``override`` turns the robots' proposed
    actions into those executed (`search.solvers.follow`)."""
    sim = CoupledSimulator(policies, scenario, config, batch=1)
    sim.override = override
    env_actions = np.asarray(env_actions, dtype=np.float64)
    n = sim.config.human_num
    if env_actions.ndim < 1 or env_actions.size % max(2 * n, 1):
        raise ValueError(f"environment actions must be a sequence of {2 * n} numbers per step")
    env_actions = env_actions.reshape(-1, n, 2)
    steps = []
    for action in env_actions:
        steps.append(sim.step(action[None]))
        if stop_when_done and sim.all_done[0]:
            break
    used = env_actions[: len(steps)]
    no_push = np.zeros((1, n, 2))
    while len(steps) < coda_to and not sim.all_done[0]:
        steps.append(sim.step(no_push))
    used = np.concatenate([used, np.zeros((len(steps) - len(used), n, 2))])
    state = sim.state
    return Trajectory(
        env_actions=used,
        agent_actions=np.stack([s.agent_actions[0] for s in steps]),
        agent_pos=np.stack([s.agent_pos[0] for s in steps]),
        other_pos=np.stack([s.other_pos[0] for s in steps]),
        crowds=np.stack([s.crowds[0] for s in steps]),
        rewards=np.stack([s.rewards[0] for s in steps]),
        outcome=sim.gather(state.outcome)[0].copy(),
        event_time=sim.gather(state.event_time)[0].copy(),
        path_length=sim.gather(state.path_length)[0].copy(),
        min_clearance=sim.gather(state.min_clearance)[0].copy(),
        time=np.array([s.time[0] for s in steps]),
    )
