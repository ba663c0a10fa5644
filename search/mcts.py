"""Monte Carlo tree search with double progressive widening over environment actions, as adaptive stress testing
runs it (the AST toolbox's ``MCTSdpw``), with two changes that make it fast:

- **branching by snapshot**: every tree node keeps a snapshot of its simulator rows, so an iteration restores its
  leaf's parent instead of replaying the action prefix from reset (``branch="replay"`` keeps the toolbox's way,
  as the reference the benchmarks compare against);
- **batched iterations**: ``batch`` selections are made one after another (each counts its visits at once, so
  the next one sees them and widening stays exact), then their leaves are expanded and rolled out together, so
  the agents' policies run on batches.

Widening: a state node visited n times gets a new action, sampled from the environment action prior, while it has
fewer than ``k * n**alpha`` actions; otherwise UCT picks ``argmax Q + c * sqrt(ln n / n_a)`` among the actions
that do not end the trajectory. The simulator is deterministic, so each action has one child state (no state
widening), and an action that ends the trajectory has an exact value: choosing it again would teach nothing and,
with snapshots, cost nothing, so a node whose every action ends the trajectory widens instead. An action chosen
again while its child is still being computed in the same batch gets another rollout from that child.

Modes: ``tree`` grows one tree from the initial state for the whole budget; ``receding`` (the toolbox's
``stress_test`` mode, the one the paper ran) searches from a root, commits the root's best action after the
root's share of the budget, drops the other branches, and goes on from the new root.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from search.problem import Problem
from search.rollout import Tracker, rollout


@dataclass(frozen=True)
class MCTSConfig:
    """Widening (k = alpha = 0.5) and rollouts to the end are the paper's. The paper ran exploration 100, mean
    backup, one step per action and receding mode; the defaults here won clearly in BENCHMARKS.md ("Search"):
    exploration 10 (in reward units), max backup (the simulator is deterministic: an action is as good as the
    best trajectory through it) and actions held for 8 steps (2 s), which moves humans coherently."""

    exploration: float = 10.0
    k: float = 0.5
    alpha: float = 0.5
    rollout_depth: int = 0  # steps a rollout may take after its new node; 0: to the end of the trajectory
    repeat: int = 8  # steps each tree action (and each rollout action) is held for
    mode: str = "tree"  # "tree" or "receding"
    backup: str = "max"  # Q of an action: "mean" return through it (the toolbox) or its "max"
    batch: int = 32  # iterations expanded and rolled out together
    branch: str = "snapshot"  # "snapshot", or "replay" from reset as the AST toolbox does

    def __post_init__(self):
        checks = [
            (self.exploration >= 0, "exploration must be >= 0"),
            (self.k > 0 and 0 < self.alpha <= 1, "k must be > 0 and alpha in (0, 1]"),
            (self.rollout_depth >= 0, "rollout_depth must be >= 0"),
            (self.repeat >= 1, "repeat must be >= 1"),
            (self.mode in ("tree", "receding"), "mode must be 'tree' or 'receding'"),
            (self.backup in ("mean", "max"), "backup must be 'mean' or 'max'"),
            (self.batch >= 1, "batch must be >= 1"),
            (self.branch in ("snapshot", "replay"), "branch must be 'snapshot' or 'replay'"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"invalid MCTS setting: {message}")


class StateNode:
    __slots__ = ("parent", "depth", "value", "terminal", "visits", "children", "snapshot")

    def __init__(self, parent: ActionNode | None, depth: int, value: float, terminal: bool, snapshot=None):
        self.parent = parent  # the action that led here
        self.depth = depth  # steps from the initial state
        self.value = value  # reward accumulated from the initial state
        self.terminal = terminal
        self.visits = 0
        self.children: list[ActionNode] = []
        self.snapshot = snapshot  # this state's simulator row; None when branching by replay or terminal


class ActionNode:
    __slots__ = ("parent", "action", "visits", "completed", "total", "best", "child")

    def __init__(self, parent: StateNode, action: np.ndarray):
        self.parent = parent
        self.action = action
        self.visits = 0  # selections, counted when selected
        self.completed = 0  # returns backed up so far
        self.total = 0.0
        self.best = -math.inf
        self.child: StateNode | None = None

    def q(self, backup: str) -> float:
        if not self.completed:
            return -math.inf  # still in flight: its siblings go first
        return self.best if backup == "max" else self.total / self.completed


def actions_to(node: StateNode) -> np.ndarray:
    """The environment actions from the initial state to ``node``, step by step, (depth, *shape)."""
    path = []
    while node.parent is not None:
        edge = node.parent
        path.extend([edge.action] * (node.depth - edge.parent.depth))
        node = edge.parent
    return np.array(path[::-1])


class MCTS:
    def __init__(self, problem: Problem, tracker: Tracker, rng: np.random.Generator, config: MCTSConfig):
        self.problem, self.tracker, self.rng, self.config = problem, tracker, rng, config
        problem.reset(1)
        snapshot = problem.snapshot() if config.branch == "snapshot" else None
        self.root = self.start = StateNode(None, 0, 0.0, False, snapshot)
        self.replayed = 0  # simulator steps spent replaying prefixes from reset (branch="replay")

    def run(self) -> None:
        if self.config.mode == "tree":
            while not self.tracker.exhausted:
                self.iterate()
            return
        while not self.root.terminal:
            until = self.tracker.steps + self.tracker.remaining / max(self._expected_steps_left(), 1)
            while self.tracker.steps < until and not self.tracker.exhausted:
                self.iterate()
            if self.tracker.exhausted:
                return
            self.commit()

    def _expected_steps_left(self) -> int:
        """Steps from the root to the end of the best trajectory so far (the horizon if none yet)."""
        ranked = self.tracker.queue.ranked()
        length = ranked[0].actions.shape[0] if ranked else self.problem.horizon
        return length - self.root.depth

    def commit(self) -> None:
        """Move the root to the child of its best action and forget the other branches."""
        done = [a for a in self.root.children if a.child is not None]
        best = max(done, key=lambda a: a.q(self.config.backup))
        self.root.children = [best]
        self.root = best.child

    def select(self) -> list[ActionNode]:
        """Descend from the root to an action whose child is new or in flight, counting visits."""
        c = self.config
        node, path = self.root, []
        while True:
            node.visits += 1
            open_actions = [a for a in node.children if a.child is None or not a.child.terminal]
            if len(node.children) < c.k * node.visits ** c.alpha or not open_actions:
                action = ActionNode(node, self.problem.prior.sample(self.rng, 1)[0])
                node.children.append(action)
            else:
                action = self._uct(node, open_actions)
            action.visits += 1
            path.append(action)
            if action.child is None:
                return path
            node = action.child

    def _uct(self, node: StateNode, actions: list[ActionNode]) -> ActionNode:
        log_n = math.log(node.visits)
        scores = [a.q(self.config.backup) + self.config.exploration * math.sqrt(log_n / a.visits) for a in actions]
        return actions[int(np.argmax(scores))]

    @staticmethod
    def backup(path: list[ActionNode], value: float) -> None:
        for action in path:
            action.completed += 1
            action.total += value
            action.best = max(action.best, value)

    def iterate(self) -> None:
        """One batch of iterations: select leaves, expand them with one batched step, roll them out together."""
        paths = [self.select() for _ in range(self.tracker.affordable(self.config.batch))]
        parents = [path[-1].parent for path in paths]
        self.problem.restore(self.problem.concat([self._state_of(node) for node in parents]))

        count, repeat = len(paths), self.config.repeat
        actions = np.zeros((count, self.problem.horizon, *self.problem.action_shape))
        for i, node in enumerate(parents):
            if node.depth:
                actions[i, : node.depth] = actions_to(node)
        lengths = np.array([node.depth for node in parents], dtype=np.int64)
        returns = np.array([node.value for node in parents])
        start = lengths.copy()
        held = np.array([path[-1].action for path in paths])  # the new edges' actions, then the rollouts'

        def choose(rows: np.ndarray, depth: np.ndarray) -> np.ndarray:
            renew = rows[(depth - start[rows] >= repeat) & ((depth - start[rows]) % repeat == 0)]
            held[renew] = self.problem.prior.sample(self.rng, renew.size)
            return held[rows]

        def add_children(taken: int, rows: np.ndarray, terminal: np.ndarray) -> None:
            if taken > repeat:
                return
            for i, row in enumerate(rows.tolist()):
                action = paths[row][-1]
                if action.child is None and (terminal[i] or taken == repeat):
                    keep = self.config.branch == "snapshot" and not terminal[i]
                    snapshot = self.problem.snapshot([i]) if keep else None
                    action.child = StateNode(action, int(lengths[row]), float(returns[row]), bool(terminal[i]),
                                             snapshot)

        rollout(self.problem, self.tracker, actions, lengths, returns, choose,
                max_steps=repeat + self.config.rollout_depth if self.config.rollout_depth else None,
                on_step=add_children)
        for path, value in zip(paths, returns.tolist(), strict=True):
            self.backup(path, value)

    def _state_of(self, node: StateNode):
        """The node's simulator row: its snapshot, or (the toolbox's way) a replay of its actions from reset."""
        if node.snapshot is not None:
            return node.snapshot
        self.problem.reset(1)
        for action in actions_to(node):
            self.problem.step(action[None])
            self.tracker.count(1)
            self.replayed += 1
        return self.problem.snapshot()


def mcts(problem: Problem, tracker: Tracker, rng: np.random.Generator, config: MCTSConfig | None = None) -> MCTS:
    """Search until the tracker's budget is spent; returns the search (its tree, for inspection)."""
    search = MCTS(problem, tracker, rng, config or MCTSConfig())
    search.run()
    return search
