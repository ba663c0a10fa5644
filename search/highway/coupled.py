"""The coupled highway problem on the kernel: GymCoupledProblem's rows and divergence reward, with every agent's
environment a row of one HighwayKernel instead of a highway-env instance, and snapshots plain arrays instead of
deep copies.

It steps the same trajectories as GymCoupledProblem over highway-env (tests/highway/test_kernel_problem.py
checks rewards, events, positions and path lengths step by step, snapshots included), so a search finds the same
scenarios, and its summaries replay in highway-env (``foil verify``, clips). ``coupled_problem`` picks it where
the kernel covers the scenario's settings, and highway-env itself, with a one-line notice, where it does not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from search.core.outcomes import OUTCOME_NAMES, RUNNING
from search.gym.adapter import EVENTS
from search.gym.agents import GymAgent
from search.gym.problem import GymCoupledProblem, GymScenario
from search.highway.adapter import HighwayAdapter, kmh
from search.highway.kernel import HighwayKernel, HighwayState, adapter_spec, notice
from search.solvers.reward import RewardConfig


@dataclass
class KernelSnapshot:
    """B rows of N agents: the kernel's rows (row b's agent k at b * N + k) and each instance's bookkeeping."""

    state: HighwayState
    observations: np.ndarray  # (B, N, ...) what each agent sees
    outcome: np.ndarray  # (B, N)
    event_step: np.ndarray  # (B, N)
    path_length: np.ndarray  # (B, N)
    steps: np.ndarray  # (B,)
    measured: np.ndarray  # (B, N, steps the episode can last): the visible score (km/h) after each step

    @property
    def batch(self) -> int:
        return len(self.steps)


class KernelCoupledProblem(GymCoupledProblem):
    """GymCoupledProblem for highway driving, stepped by the kernel."""

    def __init__(
        self,
        agents: list[GymAgent],
        scenario: GymScenario,
        reward: RewardConfig | None = None,
        adapter: HighwayAdapter | None = None,
    ):
        super().__init__(agents, scenario, reward, adapter)
        assert isinstance(self.adapter, HighwayAdapter)
        spec = adapter_spec(self.adapter)
        if isinstance(spec, str):
            raise ValueError(f"the highway kernel does not cover {spec}")
        self.kernel = HighwayKernel(spec, 1)
        self.kernel.reset([scenario.seed])
        n = len(agents)
        self._start = KernelSnapshot(
            self.kernel.state.take(np.zeros(n, np.int64)),  # every agent from one state
            np.stack([self._initial[0].observation] * n)[None],
            np.full((1, n), RUNNING),
            np.zeros((1, n), np.int64),
            np.zeros((1, n)),
            np.zeros(1, np.int64),
            np.zeros((1, n, int(np.ceil(spec.duration / self.adapter.dt)))),
        )
        self._rows = self._start

    @property
    def batch(self) -> int:
        return self._rows.batch

    def reset(self, batch: int) -> None:
        self.restore(self.snapshot_of(self._start, np.zeros(batch, np.int64)))

    def observations(self, agent: int) -> np.ndarray:
        return np.ascontiguousarray(self._rows.observations[:, agent])

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        actions = np.asarray(actions, dtype=np.float64)
        rows, n, state = self._rows, len(self.agents), self.kernel.state
        agent_actions = self._chosen()
        self.agent_rewards = np.zeros((self.batch, n))
        running = rows.outcome == RUNNING
        self.t = rows.steps = self.t + 1
        live = np.flatnonzero(running.reshape(-1))  # kernel rows, b * n + k
        before = np.stack([state.x[live, 0], state.y[live, 0]], axis=1)
        if len(live):
            self.kernel.apply(np.clip(actions[live // n], -1.0, 1.0), live)
            ego_actions = np.stack([agent_actions[i % n][i // n] for i in live])
            observations, rewards, terminated, truncated = self.kernel.step(ego_actions, live)
        newly_done = np.zeros(running.shape, bool)
        for j, i in enumerate(live):
            b, k = divmod(int(i), n)
            rows.observations[b, k] = observations[j]
            self.agent_rewards[b, k] = rewards[j]
            after = np.array([state.x[i, 0], state.y[i, 0]])
            rows.path_length[b, k] += float(np.linalg.norm(after - before[j]))
            if terminated[j] or truncated[j]:
                event = self.adapter.outcome(bool(terminated[j]), bool(truncated[j]), {})
                if event not in EVENTS:
                    raise ValueError(f"adapter outcome {event!r}: use one of {EVENTS}")
                rows.outcome[b, k], rows.event_step[b, k] = OUTCOME_NAMES.index(event), int(self.t[b])
                newly_done[b, k] = True
        # every instance's visible score after the step, as the adapter's measure reads it (a finished one stands)
        # (a row stepped on past its episodes' end stands still: its last column holds what every later step reads)
        at = np.minimum(self.t, rows.measured.shape[2]) - 1
        rows.measured[np.arange(self.batch), :, at] = kmh(state.speed[:, 0]).reshape(self.batch, n)
        positions = np.stack([state.x[:, 0], state.y[:, 0]], axis=1).reshape(self.batch, n, 2)
        scaled = [
            [
                self.divergence.scaled(agent_actions[k][b]) if running[b, k] else self.divergence.finished()
                for k in range(n)
            ]
            for b in range(self.batch)
        ]
        return self._score(actions, agent_actions, newly_done, rows.outcome, scaled, list(positions))

    def endings(self, row: int) -> list[tuple[int, int]]:
        return list(zip(self._rows.outcome[row].tolist(), self._rows.event_step[row].tolist(), strict=True))

    def measured(self, row: int) -> list[list[float]]:
        steps, kept = int(self._rows.steps[row]), self._rows.measured.shape[2]
        values = self._rows.measured[row, :, :steps]
        return [[*agent, *[agent[-1]] * (steps - kept)] for agent in values.tolist()]

    def snapshot_of(self, snapshot: KernelSnapshot, index) -> KernelSnapshot:
        """Rows ``index`` of a snapshot (indices may repeat)."""
        index = np.asarray(index, dtype=np.int64).reshape(-1)
        n = len(self.agents)
        kernel_rows = (index[:, None] * n + np.arange(n)).reshape(-1)
        return KernelSnapshot(
            snapshot.state.take(kernel_rows),
            snapshot.observations[index].copy(),
            snapshot.outcome[index].copy(),
            snapshot.event_step[index].copy(),
            snapshot.path_length[index].copy(),
            snapshot.steps[index].copy(),
            snapshot.measured[index].copy(),
        )

    def snapshot(self, index=None) -> KernelSnapshot:  # type: ignore[override]
        return self.snapshot_of(self._rows, np.arange(self.batch) if index is None else index)

    def restore(self, snapshot: KernelSnapshot) -> None:  # type: ignore[override]
        self._rows = self.snapshot_of(snapshot, np.arange(snapshot.batch))
        self.kernel.state = self._rows.state  # one state: the kernel steps the rows' arrays in place
        self.t = self._rows.steps

    def assign(self, index, snapshot: KernelSnapshot) -> None:  # type: ignore[override]
        index = np.asarray(index, dtype=np.int64).reshape(-1)
        n, rows = len(self.agents), self._rows
        self.kernel.state.assign((index[:, None] * n + np.arange(n)).reshape(-1), snapshot.state)
        for name in ("observations", "outcome", "event_step", "path_length", "steps", "measured"):
            getattr(rows, name)[index] = getattr(snapshot, name)
        self.t = rows.steps

    def concat(self, snapshots: list[KernelSnapshot]) -> KernelSnapshot:  # type: ignore[override]
        states = [s.state for s in snapshots]
        merged = HighwayState(
            {name: np.concatenate([s.arrays[name] for s in states]) for name in states[0].arrays},
            np.concatenate([s.time for s in states]),
        )
        fields = ("observations", "outcome", "event_step", "path_length", "steps", "measured")
        return KernelSnapshot(merged, *(np.concatenate([getattr(s, name) for s in snapshots]) for name in fields))


def coupled_problem(
    agents: list[GymAgent], scenario: GymScenario, reward: RewardConfig | None = None, adapter=None, workers: int = 1
) -> GymCoupledProblem:
    """The coupled problem for a scenario: on the kernel for highway scenarios it covers, otherwise
    GymCoupledProblem over the environment itself, its rows over ``workers`` processes (for a highway scenario,
    with a one-line notice)."""
    adapter = adapter or scenario.load_adapter()
    if not isinstance(adapter, HighwayAdapter):
        return GymCoupledProblem(agents, scenario, reward, adapter, workers=workers)
    spec = adapter_spec(adapter)
    if isinstance(spec, str):
        notice(spec)
        return GymCoupledProblem(agents, scenario, reward, adapter, workers=workers)
    return KernelCoupledProblem(agents, scenario, reward, adapter)
