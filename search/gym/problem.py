"""The coupled problem for any Gymnasium environment: one instance of the environment per agent, all reset from
the scenario's seed and stepped in lockstep under one shared environment action, scored by the divergence reward.

Each row of the batch holds N instances (one per agent). A step applies the row's environment action to every
instance still running (through the adapter, on the world only), lets each agent act on its own instance's
observation, and steps it. An instance whose episode ended stands still until the row ends, as a finished robot
does in the crowd world.

The divergence (``RewardConfig``: norm, combine, alpha, beta, goal_bonus, ...) is the crowd world's formula with
the agents' actions and positions in place of the robots':

- **Box actions** are first scaled to [-1, 1] per coordinate by the action space's bounds, so acceleration and
  steering weigh alike; the action divergence is the (plain or squared) Euclidean norm of the pair's difference.
  A finished agent's action counts as the centre of the box (zero).
- **Discrete actions**: the divergence of a pair is 1 where they chose different actions and 0 where the same
  (its plain and squared forms agree). A finished agent's action differs from every action.
- The state divergence (goal and horizon terms) is the norm of the difference of the adapter's ``position``.

Pairs are combined by their mean or minimum, as in the crowd world.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from search.core.outcomes import OUTCOME_NAMES, RUNNING
from search.core.prior import ActionPrior
from search.gym.adapter import Adapter, ending, load_adapter
from search.gym.agents import GymAgent
from search.gym.rows import Spread, advance, pays
from search.solvers.reward import DivergenceReward, RewardConfig

FINISHED = -1  # a finished agent's discrete action: differs from every action


@dataclass(frozen=True)
class GymScenario:
    """A study scenario in a Gymnasium domain: the adapter, its settings and the seed of the initial state."""

    name: str
    adapter: str  # module:Class
    seed: int
    settings: dict = field(default_factory=dict)
    description: str = ""

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "domain": "gym",
            "adapter": self.adapter,
            "seed": self.seed,
            "settings": dict(self.settings),
            "description": self.description,
        }

    @classmethod
    def from_dict(cls, data: dict) -> GymScenario:
        try:
            return cls(
                name=str(data["name"]),
                adapter=str(data["adapter"]),
                seed=int(data["seed"]),
                settings=dict(data.get("settings", {})),
                description=str(data.get("description", "")),
            )
        except KeyError as error:
            raise ValueError(f"a Gymnasium scenario needs name, adapter and seed; {error} is missing") from None

    def load_adapter(self) -> Adapter:
        return load_adapter(self.adapter, self.settings)


@dataclass
class Instance:
    """One agent's environment in one row, with what the agent sees and how its episode went."""

    env: object
    observation: np.ndarray
    outcome: int = RUNNING
    event_step: int = 0  # the step its episode ended on (0 while running)
    path_length: float = 0.0
    measured: list[float] = field(default_factory=list)  # the visible score after each step, where one is declared


@dataclass
class GymSnapshot:
    rows: list[list[Instance]]  # saved instances: ``env`` holds the adapter's snapshot of the environment
    steps: np.ndarray  # (B,) steps taken from the initial state

    @property
    def batch(self) -> int:
        return len(self.rows)


class Divergence:
    """Pairwise divergences of agents' actions for one action space, and of their positions."""

    def __init__(self, action_space, config: RewardConfig):
        import gymnasium

        self.squared, self.minimum = config.norm == "squared", config.combine == "min"
        self.discrete = isinstance(action_space, gymnasium.spaces.Discrete)
        if not self.discrete:
            if (
                not isinstance(action_space, gymnasium.spaces.Box)
                or not np.all(np.isfinite(action_space.low))
                or not np.all(np.isfinite(action_space.high))
            ):
                raise ValueError(f"agents' actions must be Discrete or a bounded Box, not {action_space}")
            self.low = np.asarray(action_space.low, dtype=np.float64).reshape(-1)
            self.high = np.asarray(action_space.high, dtype=np.float64).reshape(-1)

    def scaled(self, action) -> np.ndarray:
        """An agent's action as divergence coordinates: [-1, 1] per Box coordinate, the index for Discrete."""
        if self.discrete:
            return np.array([float(np.asarray(action).reshape(-1)[0])])
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(-1), self.low, self.high)
        return 2 * (a - self.low) / (self.high - self.low) - 1

    def finished(self) -> np.ndarray:
        return np.array([float(FINISHED)]) if self.discrete else np.zeros(self.low.shape)

    def actions(self, values: list[np.ndarray]) -> float:
        if self.discrete:
            return self._combine([float(a[0] != b[0] or a[0] == FINISHED) for a, b in _pairs(values)])
        return self.vectors(values)

    def vectors(self, values: list[np.ndarray]) -> float:
        distances = []
        for a, b in _pairs(values):
            d = float(np.sum((np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) ** 2))
            distances.append(d if self.squared else float(np.sqrt(d)))
        return self._combine(distances)

    def _combine(self, values: list[float]) -> float:
        if self.minimum:
            return min(values)
        total = 0.0
        for value in values:
            total += value
        return total / len(values)


def _pairs(values: list):
    return [(values[i], values[j]) for i in range(len(values)) for j in range(i + 1, len(values))]


class GymCoupledProblem:
    """The agents under comparison, one environment instance each, under one environment action (a `Problem`)."""

    def __init__(
        self,
        agents: list[GymAgent],
        scenario: GymScenario,
        reward: RewardConfig | None = None,
        adapter: Adapter | None = None,
        render: bool = False,
        workers: int = 1,
    ):
        if len(agents) < 2:
            raise ValueError("a comparison needs at least two agents")
        self.agents, self.scenario = agents, scenario
        self.adapter = adapter or scenario.load_adapter()
        self.ending = ending(self.adapter)
        self.reward_config = reward or RewardConfig()
        if self.reward_config.heuristic != "state_divergence":
            raise ValueError(
                "in a Gymnasium domain the horizon heuristic is the state divergence: leave heuristic unset"
            )
        self.action_shape = tuple(self.adapter.env_action_shape)
        self.horizon = self.reward_config.horizon
        self.prior = ActionPrior(self.action_shape, 1.0, self.reward_config.prior, self.reward_config.prior_sigma)
        self.reward = DivergenceReward(self.reward_config, self.prior)
        env = self.adapter.make(render=render)
        observation, _ = env.reset(seed=scenario.seed)
        self.action_space = env.action_space
        self.divergence = Divergence(env.action_space, self.reward_config)
        saved = self.adapter.snapshot_env(env)
        self._initial = [Instance(saved, np.asarray(observation)) for _ in agents]  # every agent from one state
        self.rows: list[list[Instance]] = []  # each instance's environment is here, or in a worker (``spread``)
        self.workers = workers  # processes the rows' environments step in (search.gym.rows)
        self.spread: Spread | None = None
        self.stepped_here = 0.0, 0  # seconds the environments took to step in this process, and their steps
        self.t = np.zeros(0, dtype=np.int64)
        self.last_agent_actions: list[list[np.ndarray]] = []  # the last step's, per row and agent (for replays)
        self.last_events = np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)  # the last step's (goal, end)
        self.override: Callable | None = (
            None  # a search.solvers.follow.Follow or alike: the actions executed given those proposed
        )
        self.proposed: list[np.ndarray] = []  # each agent's own choice on the last step, (B, ...) per agent
        self.agent_rewards = np.zeros((0, len(agents)))  # each agent's own reward on the last step

    @property
    def batch(self) -> int:
        return len(self.rows)

    def reset(self, batch: int) -> None:
        self._set_rows([self._initial] * batch, np.zeros(batch, dtype=np.int64))

    def _spread_if_it_pays(self) -> None:
        """Move the rows' environments to worker processes once their steps here show that it pays
        (`search.gym.rows.pays`), where the adapter and its snapshots pickle (else, with a one-line notice, they
        stay here)."""
        if self.spread is not None or self.workers <= 1 or not pays(*self.stepped_here):
            return
        refusal = Spread.refusal(self.adapter, self._initial[0].env)
        if refusal is not None:
            self.workers = 1
            print(
                f"note: {type(self.adapter).__name__}'s rows step in one process: its adapter or its snapshots do "
                f"not pickle ({refusal})",
                file=sys.stderr,
            )
            return
        saved = self.snapshot()
        self.spread = Spread(self.adapter, self.workers)
        self._set_rows(saved.rows, saved.steps)

    def _set_rows(self, saved: list[list[Instance]], steps: np.ndarray, index: list[int] | None = None) -> None:
        """Rows from saved ones: all the rows (``index`` None) or rows ``index`` in place."""
        spread = self.spread
        if spread is None:
            rows = [[_copy(i, self.adapter.restore_env(i.env)) for i in row] for row in saved]
        else:
            places = list(range(len(saved))) if index is None else index
            spread.place(places, [[i.env for i in row] for row in saved], only=index is None)
            rows = [[_copy(i, None) for i in row] for row in saved]
        if index is None:
            self.rows, self.t = rows, steps.copy()
            return
        for i, row, t in zip(index, rows, steps, strict=True):
            self.rows[i], self.t[i] = row, t

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        actions = np.asarray(actions, dtype=np.float64)
        batch, n = self.batch, len(self.agents)
        agent_actions = self._chosen()
        running = np.array([[i.outcome == RUNNING for i in row] for row in self.rows], dtype=bool).reshape(batch, n)
        env_actions = np.clip(actions, -1.0, 1.0)
        self._spread_if_it_pays()
        if self.spread is None:
            started = time.perf_counter()
            stepped = [
                [
                    advance(self.adapter, self.ending, i.env, env_actions[b], agent_actions[k][b], running[b, k])
                    for k, i in enumerate(row)
                ]
                for b, row in enumerate(self.rows)
            ]
            seconds, steps = self.stepped_here
            self.stepped_here = seconds + time.perf_counter() - started, steps + int(running.sum())
        else:
            stepped = self.spread.step(env_actions, agent_actions, running)
        self.agent_rewards = np.zeros((batch, n))
        newly_done = np.zeros((batch, n), dtype=bool)
        outcome = np.zeros((batch, n), dtype=np.int64)
        scaled, positions = [], []
        self.t = self.t + 1
        for b, row in enumerate(self.rows):
            row_scaled = []
            for k, instance in enumerate(row):
                found = stepped[b][k]
                if found.observation is not None:  # it was running: it stepped
                    self.agent_rewards[b, k] = found.reward
                    instance.observation = found.observation
                    instance.path_length += found.moved
                    if found.event is not None:
                        instance.outcome, instance.event_step = OUTCOME_NAMES.index(found.event), int(self.t[b])
                        newly_done[b, k] = True
                    row_scaled.append(self.divergence.scaled(agent_actions[k][b]))
                else:
                    row_scaled.append(self.divergence.finished())
                if found.measured is not None:  # a finished instance stands still: its score is read as shown
                    instance.measured.append(found.measured)
                outcome[b, k] = instance.outcome
            scaled.append(row_scaled)
            positions.append([found.position for found in stepped[b]])
        return self._score(actions, agent_actions, newly_done, outcome, scaled, positions)

    def _score(self, actions, agent_actions, newly_done, outcome, scaled, positions) -> tuple[np.ndarray, np.ndarray]:
        """The step's reward and terminal flags from its events, the agents' actions and their positions."""
        n = len(self.agents)
        all_done = (outcome != RUNNING).all(axis=1)
        goal, end = self.reward.events(newly_done, outcome, all_done, self.t)
        self.last_events = goal, end
        self.last_agent_actions = [[agent_actions[k][b] for k in range(n)] for b in range(self.batch)]
        reward = np.array([self._divergence(goal[b], end[b], scaled[b], positions[b]) for b in range(self.batch)])
        if self.reward_config.plausibility:
            reward = reward + self.reward_config.plausibility * self.prior.log_prob(actions)
        return reward, goal | end

    def endings(self, row: int) -> list[tuple[int, int]]:
        """Each agent's outcome (an index into OUTCOME_NAMES) and the step its episode ended on (0: running)."""
        return [(i.outcome, i.event_step) for i in self.rows[row]]

    def measured(self, row: int) -> list[list[float]]:
        """Each agent's visible score after each step so far (empty where the world declares none)."""
        return [i.measured for i in self.rows[row]]

    def _divergence(self, goal: bool, end: bool, scaled: list, positions: list) -> float:
        c = self.reward_config
        if goal:
            return c.goal_bonus + c.alpha * self.divergence.vectors(positions)
        if end:
            return c.horizon_offset + c.beta * self.divergence.vectors(positions)
        return self.divergence.actions(scaled)

    def _act(self) -> list[np.ndarray]:
        """Each agent's actions for every row, in one batched call per agent (finished instances included: their
        action is never used)."""
        return [agent.act(self.observations(k)) for k, agent in enumerate(self.agents)]

    def _chosen(self) -> list[np.ndarray]:
        """The actions executed this step: each agent's own (``proposed``), or what ``override`` makes of them."""
        self.proposed = self._act()
        return self.proposed if self.override is None else self.override(self.proposed, self.t)

    # what the summary methods of the literature need (search.solvers.follow, disagreements, highlights)
    def action_gap(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(B,) how far apart two agents' actions are: 1 or 0 for discrete actions; for Box actions the distance
        with each coordinate scaled to [-1, 1]."""
        if self.divergence.discrete:
            return (np.asarray(a).reshape(len(a), -1)[:, 0] != np.asarray(b).reshape(len(b), -1)[:, 0]).astype(float)
        scale = 2 / (self.divergence.high - self.divergence.low)
        gap = (np.asarray(a, np.float64).reshape(len(a), -1) - np.asarray(b, np.float64).reshape(len(b), -1)) * scale
        return np.linalg.norm(gap, axis=1)

    def alternatives(self, action: np.ndarray) -> list[np.ndarray]:
        """Actions an agent might have taken instead of ``action`` (B, ...): every discrete action, or the action
        itself and each Box coordinate at either end of its range."""
        if self.divergence.discrete:
            return [np.full_like(np.asarray(action), a) for a in range(int(self.action_space.n))]
        from search.core.problem import box_alternatives

        flat = np.asarray(action, np.float64).reshape(len(action), -1)
        shape = np.asarray(action).shape
        return [a.reshape(shape) for a in box_alternatives(flat, self.divergence.low, self.divergence.high)]

    def observations(self, agent: int) -> np.ndarray:
        return np.stack([row[agent].observation for row in self.rows])

    def features(self) -> np.ndarray:
        """(B, F) what each row's first agent observes, flattened: the state HIGHLIGHTS-DIV tells apart."""
        observations = np.asarray(self.observations(0), dtype=np.float64)
        return observations.reshape(len(observations), -1)

    def values(self, agent: int, of: int | None = None) -> np.ndarray | None:
        """(B,) agent ``agent``'s value of the state of agent ``of``'s instance (its own by default), where it has
        one."""
        return self.agents[agent].value(self.observations(agent if of is None else of))

    def action_values(self, agent: int) -> np.ndarray | None:
        """(B, A) agent ``agent``'s value of each action in its instance's state, where it has them."""
        return self.agents[agent].action_values(self.observations(agent))

    def snapshot(self, index=None) -> GymSnapshot:
        chosen = list(range(self.batch)) if index is None else np.asarray(index).reshape(-1).tolist()
        if self.spread is None:
            envs = [[self.adapter.snapshot_env(i.env) for i in self.rows[b]] for b in chosen]
        else:
            envs = self.spread.save(chosen)
        rows = [
            [_copy(i, env) for i, env in zip(self.rows[b], saved, strict=True)]
            for b, saved in zip(chosen, envs, strict=True)
        ]
        return GymSnapshot(rows, self.t[chosen])

    def restore(self, snapshot: GymSnapshot) -> None:
        self._set_rows(snapshot.rows, snapshot.steps)

    def assign(self, index, snapshot: GymSnapshot) -> None:
        self._set_rows(snapshot.rows, snapshot.steps, np.asarray(index).reshape(-1).tolist())

    def concat(self, snapshots: list[GymSnapshot]) -> GymSnapshot:
        return GymSnapshot([row for s in snapshots for row in s.rows], np.concatenate([s.steps for s in snapshots]))


def _copy(instance: Instance, env: Any) -> Instance:
    """The instance with ``env`` in place of its environment, and lists of its own."""
    return Instance(
        env, instance.observation, instance.outcome, instance.event_step, instance.path_length, [*instance.measured]
    )
