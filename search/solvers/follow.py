"""Agents that follow a leader: the coupled problem's way to play one agent's episode with every agent watching.

While a row follows, every agent's instance executes the leader's action, so all instances stay in the leader's
state, and each agent's own choice (``problem.proposed``) says what it would have done there. The summary methods
of the literature need exactly this: Agent Disagreements plays agent A and asks agent B at every step (a fork
ends the following), and HIGHLIGHTS plays each agent's own episodes (every agent follows it throughout).

A coupled problem applies ``problem.override(proposed, taken)`` to the agents' proposed actions (a list over agents
of (B, ...) arrays) before it steps, given each row's steps taken so far; a summary records the following as
``follow = {"leader": i, "steps": n}`` (every agent executed agent i's action on steps 1..n).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

ALWAYS = np.iinfo(np.int64).max  # as Follow's steps: the leader on every step


@dataclass(frozen=True)
class Follow:
    """Every agent takes agent ``leader``'s action on a row's steps 1..``steps`` (its own from then on)."""

    leader: int
    steps: int | np.ndarray  # one for every row, or one per row

    def __call__(self, proposed: list[np.ndarray], taken: np.ndarray) -> list[np.ndarray]:
        following = np.asarray(taken) < self.steps
        if not following.any():
            return proposed
        lead = proposed[self.leader]
        executed = []
        for action in proposed:
            action = np.array(action, copy=True)
            action[following] = lead[following]
            executed.append(action)
        return executed

    def to_dict(self) -> dict[str, int]:
        return {"leader": int(self.leader), "steps": int(self.steps)}

    @classmethod
    def of_summary(cls, summary: Mapping[str, Any]) -> Follow | None:
        """The following a summary records, or None for a summary whose agents all acted on their own."""
        data = summary.get("follow")
        if data is None:
            return None
        try:
            leader, steps = int(data["leader"]), int(data["steps"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"a summary's follow must be {{leader, steps}}, got {data!r}") from None
        agents = len(summary.get("agents", []))
        if not 0 <= leader < agents or steps < 0:
            raise ValueError(f"follow {data!r}: leader must index one of the {agents} agents and steps be >= 0")
        return cls(leader, steps)


def recorded(summary: dict[str, Any], follow: Follow | None, window: tuple[int, int] | None) -> dict[str, Any]:
    """``summary`` with its following and clip window written in (keys absent when there are none)."""
    if follow is not None:
        summary["follow"] = follow.to_dict()
    if window is not None:
        summary["window"] = [int(window[0]), int(window[1])]
    return summary
