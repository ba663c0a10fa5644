"""A coupled problem's environments: where each instance steps, in the problem's process or in worker processes.

A Python environment steps on one core, so a search that steps many rows together (MCTS's batch, the
representative solver's rollouts of a state) moves its rows to worker processes once their steps show that it pays
(`pays`: a slow environment, not one whose steps take microseconds): row b's environments stay in worker
b % workers (`search.core.workers.Keepers`), each step sends a row its environment action and the agents' actions
and brings back what the step did (observations, rewards, events, positions). The agents act in the
problem's process, on the batch of every row as before, and the problem scores the step from what came back, so
the numbers are the same whatever the number of workers. Snapshots travel only where the problem saves or
restores rows (MCTS: once per tree node and once per iteration started), never at each step.
"""

from __future__ import annotations

import itertools
import pickle
import weakref
from typing import Any, NamedTuple

import numpy as np

from search.core.workers import keepers
from search.gym.adapter import Adapter, Ending, ending


class Stepped(NamedTuple):
    """What one instance's step did, as its environment tells it (``observation`` None: it had ended before)."""

    observation: np.ndarray | None
    reward: float
    event: str | None  # how its episode ended on this step; None while it goes on
    moved: float  # how far its position moved
    position: np.ndarray
    measured: float | None  # the visible score after the step, where the adapter declares one


def advance(
    adapter: Adapter, end: Ending, env: Any, env_action: np.ndarray, agent_action: Any, running: bool
) -> Stepped:
    """Step one instance: the environment action on its world, then the agent's action (where its episode goes on);
    a finished instance stands still and is only read."""
    observation, reward, event, moved = None, 0.0, None, 0.0
    if running:
        # copies: an environment may move its position array in place
        before = np.array(adapter.position(env), dtype=np.float64)
        adapter.apply(env, env_action)
        observation, reward, terminated, truncated, info = env.step(agent_action)
        observation, reward = np.asarray(observation), float(reward)
        after = np.array(adapter.position(env), dtype=np.float64)
        moved = float(np.linalg.norm(after - before))
        if terminated or truncated:
            event = end(bool(terminated), bool(truncated), info, reward, env)
    position = np.array(adapter.position(env), dtype=np.float64)
    measured = float(adapter.measure(env)) if adapter.score is not None else None
    return Stepped(observation, reward, event, moved, position, measured)


# When a problem's rows move to workers: once its environments have stepped here for about what starting the
# workers costs, and only where an instance's step takes long enough for the trips to the workers to pay (MCTS in
# CartPole, whose steps take microseconds, ran at half its speed with its rows moved: BENCHMARKS.md, "MCTS's rows
# over workers")
SPREAD_AFTER_S = 2.0
SPREAD_STEP_S = 0.5e-3


def pays(seconds: float, steps: int) -> bool:
    """Whether rows whose instances took ``seconds`` for ``steps`` steps here should move to workers."""
    return steps > 0 and seconds >= SPREAD_AFTER_S and seconds >= SPREAD_STEP_S * steps


_keys = itertools.count()


class Spread:
    """The environments of a problem's rows in ``count`` worker processes, row b in worker b % count."""

    def __init__(self, adapter: Adapter, count: int):
        self.key, self.count = next(_keys), count
        self.keepers = keepers(count)
        weakref.finalize(self, self.keepers.forget, self.key)
        self.keepers.call({w: (_open, (self.key, type(adapter), adapter.settings)) for w in range(count)})

    @staticmethod
    def refusal(adapter: Adapter, saved: Any) -> str | None:
        """Why a problem's rows cannot leave its process (its adapter or its snapshots do not pickle), or None."""
        try:
            pickle.dumps((type(adapter), adapter.settings, saved))
        except Exception as error:  # noqa: BLE001 - any failure to pickle
            return f"{type(error).__name__}: {error}"
        return None

    def place(self, rows: list[int], saved: list[list[Any]], only: bool = False) -> None:
        """Rows ``rows`` from saved environments (one list per row); ``only``: they are all the rows there are."""
        parts: dict[int, list] = {w: [] for w in range(self.count)} if only else {}
        for row, envs in zip(rows, saved, strict=True):
            parts.setdefault(row % self.count, []).append((row, envs))
        self.keepers.call({w: (_place, (self.key, part, only)) for w, part in parts.items()})

    def save(self, rows: list[int]) -> list[list[Any]]:
        """The saved environments of rows ``rows``, in that order (indices may repeat)."""
        asked: dict[int, list[int]] = {}
        for row in rows:
            asked.setdefault(row % self.count, []).append(row)
        found = self.keepers.call({w: (_save, (self.key, part)) for w, part in asked.items()})
        by_row = {row: envs for w, part in asked.items() for row, envs in zip(part, found[w], strict=True)}
        return [by_row[row] for row in rows]

    def step(
        self, env_actions: np.ndarray, agent_actions: list[np.ndarray], running: np.ndarray
    ) -> list[list[Stepped]]:
        """Step every row (``running``: (B, agents), which instances go on); each row's instances' results."""
        parts: dict[int, list] = {}
        for row in range(len(env_actions)):
            mine = (row, env_actions[row], [actions[row] for actions in agent_actions], running[row].tolist())
            parts.setdefault(row % self.count, []).append(mine)
        found = self.keepers.call({w: (_step, (self.key, part)) for w, part in parts.items()})
        return [found[row % self.count][row // self.count] for row in range(len(env_actions))]


# what the workers run, on the dict each keeps: under the problem's key, its adapter, ending and rows' environments
def _open(kept: dict, key: int, cls: type[Adapter], settings: dict) -> None:
    adapter = cls(settings)
    kept[key] = (adapter, ending(adapter), {})


def _place(kept: dict, key: int, rows: list, only: bool) -> None:
    adapter, _, envs = kept[key]
    if only:
        envs.clear()
    for row, saved in rows:
        envs[row] = [adapter.restore_env(s) for s in saved]


def _save(kept: dict, key: int, rows: list[int]) -> list[list[Any]]:
    adapter, _, envs = kept[key]
    return [[adapter.snapshot_env(env) for env in envs[row]] for row in rows]


def _step(kept: dict, key: int, rows: list) -> list[list[Stepped]]:
    adapter, end, envs = kept[key]
    return [
        [advance(adapter, end, env, action, mine[k], running[k]) for k, env in enumerate(envs[row])]
        for row, action, mine, running in rows
    ]
