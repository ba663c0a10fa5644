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

from dataclasses import dataclass, field

import numpy as np

from search.gym.adapter import EVENTS, Adapter, load_adapter
from search.gym.agents import GymAgent
from search.sim.world import OUTCOME_NAMES, RUNNING
from search.solvers.prior import ActionPrior
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
    ):
        if len(agents) < 2:
            raise ValueError("a comparison needs at least two agents")
        self.agents, self.scenario = agents, scenario
        self.adapter = adapter or scenario.load_adapter()
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
        self.divergence = Divergence(env.action_space, self.reward_config)
        saved = self.adapter.snapshot_env(env)
        self._initial = [Instance(saved, np.asarray(observation)) for _ in agents]  # every agent from one state
        self.rows: list[list[Instance]] = []
        self.t = np.zeros(0, dtype=np.int64)
        self.last_agent_actions: list[list[np.ndarray]] = []  # the last step's, per row and agent (for replays)
        self.last_events = np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)  # the last step's (goal, end)

    @property
    def batch(self) -> int:
        return len(self.rows)

    def _save(self, row: list[Instance]) -> list[Instance]:
        """A row as saved instances (``env`` holds the adapter's snapshot of the environment)."""
        return [
            Instance(self.adapter.snapshot_env(i.env), i.observation, i.outcome, i.event_step, i.path_length)
            for i in row
        ]

    def _load(self, row: list[Instance]) -> list[Instance]:
        """Live instances from a saved row, which stays usable."""
        return [
            Instance(self.adapter.restore_env(i.env), i.observation, i.outcome, i.event_step, i.path_length)
            for i in row
        ]

    def reset(self, batch: int) -> None:
        self.rows = [self._load(self._initial) for _ in range(batch)]
        self.t = np.zeros(batch, dtype=np.int64)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        actions = np.asarray(actions, dtype=np.float64)
        batch, n = self.batch, len(self.agents)
        agent_actions = self._act()
        newly_done = np.zeros((batch, n), dtype=bool)
        outcome = np.zeros((batch, n), dtype=np.int64)
        scaled, positions = [], []
        self.t = self.t + 1
        for b, row in enumerate(self.rows):
            row_scaled, row_positions = [], []
            for k, instance in enumerate(row):
                if instance.outcome == RUNNING:
                    # copies: an environment may move its position array in place
                    before = np.array(self.adapter.position(instance.env), dtype=np.float64)
                    self.adapter.apply(instance.env, np.clip(actions[b], -1.0, 1.0))
                    observation, _, terminated, truncated, info = instance.env.step(agent_actions[k][b])
                    instance.observation = np.asarray(observation)
                    after = np.array(self.adapter.position(instance.env), dtype=np.float64)
                    instance.path_length += float(np.linalg.norm(after - before))
                    if terminated or truncated:
                        event = self.adapter.outcome(bool(terminated), bool(truncated), info)
                        if event not in EVENTS:
                            raise ValueError(f"adapter outcome {event!r}: use one of {EVENTS}")
                        instance.outcome, instance.event_step = OUTCOME_NAMES.index(event), int(self.t[b])
                        newly_done[b, k] = True
                    row_scaled.append(self.divergence.scaled(agent_actions[k][b]))
                else:
                    row_scaled.append(self.divergence.finished())
                row_positions.append(np.array(self.adapter.position(instance.env), dtype=np.float64))
                outcome[b, k] = instance.outcome
            scaled.append(row_scaled)
            positions.append(row_positions)
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
        out = []
        for k, agent in enumerate(self.agents):
            observations = np.stack([row[k].observation for row in self.rows])
            out.append(agent.act(observations))
        return out

    def snapshot(self, index=None) -> GymSnapshot:
        rows = self.rows if index is None else [self.rows[i] for i in np.asarray(index).reshape(-1)]
        steps = self.t.copy() if index is None else self.t[np.asarray(index).reshape(-1)]
        return GymSnapshot([self._save(row) for row in rows], steps)

    def restore(self, snapshot: GymSnapshot) -> None:
        self.rows = [self._load(row) for row in snapshot.rows]
        self.t = snapshot.steps.copy()

    def assign(self, index, snapshot: GymSnapshot) -> None:
        for i, row, t in zip(np.asarray(index).reshape(-1), snapshot.rows, snapshot.steps, strict=True):
            self.rows[i] = self._load(row)
            self.t[i] = t

    def concat(self, snapshots: list[GymSnapshot]) -> GymSnapshot:
        return GymSnapshot([row for s in snapshots for row in s.rows], np.concatenate([s.steps for s in snapshots]))
