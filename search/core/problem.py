"""What a solver searches: a batched, branchable, deterministic environment with a reward.

Solvers see only this protocol, so the same MCTS runs on the coupled crowd simulator
(`search.crowd.problem`) and on small synthetic problems with a known optimum (the tests use one). The summary
methods of the literature need more of a problem: each capability they use is a small protocol below, which a
solver declares (`search.solvers.solver.Solver.needs`) and `require` checks once, when the solver starts.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from search.core.prior import ActionPrior


class Problem(Protocol):
    """B rows stepped together; each row is one trajectory from the problem's fixed initial state."""

    action_shape: tuple[int, ...]
    horizon: int  # no trajectory is longer
    prior: ActionPrior

    @property
    def batch(self) -> int: ...

    def reset(self, batch: int) -> None: ...

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance every row by one action (B, *action_shape); return (reward (B,), terminal (B,))."""

    def snapshot(self, index: npt.ArrayLike | None = None) -> Any:
        """A copy of rows ``index`` (all by default; indices may repeat)."""

    def restore(self, snapshot: Any) -> None:
        """Continue from a snapshot; the batch becomes its rows."""

    def concat(self, snapshots: list[Any]) -> Any:
        """One snapshot holding the rows of several, in order."""


class Assign(Protocol):
    """Rows overwritten in place. Optional: MCTS rebuilds the batch with snapshot/concat/restore where a problem
    lacks it (more slowly)."""

    def assign(self, index: npt.ArrayLike, snapshot: Any) -> None:
        """Overwrite rows ``index`` with a snapshot's rows (as many); the other rows go on untouched."""


# What a coupled problem applies to the agents' proposed actions, given each row's steps taken so far.
Override = Callable[[list[np.ndarray], np.ndarray], list[np.ndarray]]


class Follows(Protocol):
    """Agents that follow a leader (`search.solvers.follow`): ``override(proposed, taken)`` turns each agent's own
    choice into the actions executed (None: each its own), and ``proposed`` is each agent's own choice on the last
    step, (B, ...) per agent."""

    override: Override | None

    @property
    def proposed(self) -> list[np.ndarray]: ...


class ActionGap(Protocol):
    """How far apart two agents' actions are: what makes a disagreement."""

    def action_gap(self, a: np.ndarray, b: np.ndarray) -> np.ndarray: ...


class StateValues(Protocol):
    """Each agent's value of a state, where it has one: what scores a disagreement by its last state."""

    def values(self, agent: int, of: int | None = None) -> np.ndarray | None: ...


class ActionValues(Protocol):
    """Each agent's value of each action, where it has them: what scores a HIGHLIGHTS moment. Optional: without
    them HIGHLIGHTS measures importance by rollouts of the `Alternatives`."""

    def action_values(self, agent: int) -> np.ndarray | None: ...


class Alternatives(Protocol):
    """The actions an agent might have taken instead of its own: what HIGHLIGHTS' rollouts try."""

    def alternatives(self, action: np.ndarray) -> list[np.ndarray]: ...


def box_alternatives(action: np.ndarray, low: np.ndarray, high: np.ndarray) -> list[np.ndarray]:
    """``action`` (B, d) itself, then, for each coordinate, the action with that coordinate at ``low`` and at
    ``high``: the alternatives the stand-in importance tries for Box actions."""
    out = [np.array(action, dtype=np.float64)]
    for i in range(action.shape[-1]):
        for end in (low[i], high[i]):
            changed = np.array(action, dtype=np.float64)
            changed[..., i] = end
            out.append(changed)
    return out


class AgentRewards(Protocol):
    """(B, agents) each agent's own reward on the last step: what HIGHLIGHTS' rollouts sum over the alternatives.
    A problem has it from when it is built (zeros before the first step), so it is checked before any work."""

    agent_rewards: np.ndarray


class Features(Protocol):
    """(B, F) what a clip shows of each row: what HIGHLIGHTS-DIV tells states apart by."""

    def features(self) -> np.ndarray: ...


def members(capability: type) -> list[str]:
    """The names a capability declares: its attributes, properties and methods."""
    declared = {*getattr(capability, "__annotations__", {}), *vars(capability)}
    return sorted(name for name in declared if not name.startswith("_"))


def provides(problem: object, capability: type) -> bool:
    """Whether the problem has every member of the capability (as it stands now: a member may be an instance's)."""
    return all(hasattr(problem, name) for name in members(capability))


CAPABILITIES_DOC = 'docs/worlds.md, "What the summary methods need of a world"'


def require(problem: object, capabilities: tuple[type, ...], solver: str) -> None:
    """Refuse a problem that lacks a capability the solver needs, naming both and where the capability is
    documented."""
    for capability in capabilities:
        missing = [name for name in members(capability) if not hasattr(problem, name)]
        if missing:
            raise ValueError(
                f"the {solver} solver needs a problem with {capability.__name__} "
                f"(search.api.{capability.__name__}; {CAPABILITIES_DOC}); {type(problem).__name__} has no "
                f"{' and no '.join(missing)}: give it {' and '.join(missing)}, or use another solver"
            )
