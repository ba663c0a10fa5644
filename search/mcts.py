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
from search.rollout import Tracker


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
        self.rollouts = 0  # iterations finished (backed up)
        self.rollout_steps = 0  # simulator steps they took
        self.batch_rows = 0  # rows stepped, summed over batched steps (batch_rows / batch_steps: mean batch)
        self.batch_steps = 0

    def run(self) -> None:
        self.until = self._commit_point() if self.config.mode == "receding" else math.inf
        Rollouts(self).run()

    def _commit_point(self) -> float:
        """Receding mode: the step count after which the root commits (its share of the remaining budget)."""
        return self.tracker.steps + self.tracker.remaining / max(self._expected_steps_left(), 1)

    def _expected_steps_left(self) -> int:
        """Steps from the root to the end of the best trajectory so far (the horizon if none yet)."""
        ranked = self.tracker.queue.ranked()
        length = ranked[0].actions.shape[0] if ranked else self.problem.horizon
        return length - self.root.depth

    def maybe_commit(self) -> None:
        """Receding mode: once the root's share of the budget is spent and one of its actions has a value, move
        the root to the child of its best action and forget the other branches (iterations still running in
        them finish and count, but no longer steer the search)."""
        if self.tracker.steps < self.until or self.root.terminal:
            return
        done = [a for a in self.root.children if a.child is not None and a.completed]
        if not done:
            return
        best = max(done, key=lambda a: a.q(self.config.backup))
        self.root.children = [best]
        self.root = best.child
        self.until = self._commit_point()

    @property
    def open(self) -> bool:
        """Whether new iterations may start: budget left, and (receding) a root that does not end the search."""
        return not self.tracker.exhausted and not self.root.terminal

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
        log_n, c, backup = math.log(node.visits), self.config.exploration, self.config.backup
        best, best_score = actions[0], -math.inf
        for action in actions:  # the first of equal scores wins
            score = action.q(backup) + c * math.sqrt(log_n / action.visits)
            if score > best_score:
                best, best_score = action, score
        return best

    @staticmethod
    def backup(path: list[ActionNode], value: float) -> None:
        for action in path:
            action.completed += 1
            action.total += value
            action.best = max(action.best, value)

    def state_of(self, node: StateNode):
        """The node's simulator row: its snapshot, or (the toolbox's way) a replay of its actions from reset,
        which leaves the problem holding that one row."""
        if node.snapshot is not None:
            return node.snapshot
        self.problem.reset(1)
        for action in actions_to(node):
            self.problem.step(action[None])
            self.tracker.count(1)
            self.replayed += 1
        return self.problem.snapshot()


class Rollouts:
    """The iterations in flight: up to ``batch`` rows stepped together. Each row expands its new edge (the edge's
    action held ``repeat`` steps, then a tree node with its snapshot) and rolls out with prior actions renewed
    every ``repeat`` steps. When rows end, their values are backed up at once and new iterations are selected
    into the freed rows, so the policies keep seeing a full batch until the budget runs out."""

    def __init__(self, search: MCTS):
        self.search = search
        problem, width = search.problem, search.config.batch
        self.actions = np.zeros((width, problem.horizon, *problem.action_shape))  # from the initial state
        self.lengths = np.zeros(width, dtype=np.int64)
        self.returns = np.zeros(width)
        self.start = np.zeros(width, dtype=np.int64)  # depth of the node each iteration expands
        self.held = np.zeros((width, *problem.action_shape))  # the new edge's action, then the rollout's
        self.paths: list[list[ActionNode]] = [[] for _ in range(width)]
        self.rows = np.zeros(0, dtype=np.int64)  # the slot of each simulator row, in row order
        self.free = list(range(width))  # slots without an iteration, lowest first

    def run(self) -> None:
        search = self.search
        self._fill(np.zeros(0, dtype=np.int64))
        while self.rows.size:
            terminal, ended = self._step()
            if not ended.any():
                continue
            ended = np.flatnonzero(ended)
            for i in ended.tolist():
                slot = int(self.rows[i])
                if terminal[i]:
                    search.tracker.finish(self.returns[slot], self.actions[slot, : self.lengths[slot]])
                search.backup(self.paths[slot], float(self.returns[slot]))
                search.rollouts += 1
                search.rollout_steps += int(self.lengths[slot] - self.start[slot])
                self.free.append(slot)
            self.free.sort()
            search.maybe_commit()
            self._fill(ended)

    def _step(self) -> tuple[np.ndarray, np.ndarray]:
        """One batched step of every row; new tree nodes at the end of their edge. Returns (terminal, ended)."""
        search = self.search
        config, problem, rows = search.config, search.problem, self.rows
        depth = self.lengths[rows]
        taken = depth - self.start[rows]
        renew = (taken >= config.repeat) & (taken % config.repeat == 0)
        if renew.any():
            self.held[rows[renew]] = problem.prior.sample(search.rng, int(renew.sum()))
        step_actions = self.held[rows]
        reward, terminal = problem.step(step_actions)
        search.tracker.count(rows.size)
        search.batch_rows += rows.size
        search.batch_steps += 1
        self.actions[rows, depth] = step_actions
        self.lengths[rows] = depth + 1
        self.returns[rows] += reward
        taken += 1
        for i in np.flatnonzero((taken <= config.repeat) & (terminal | (taken == config.repeat))).tolist():
            slot = int(rows[i])
            action = self.paths[slot][-1]
            if action.child is None:  # another row may have expanded the same edge first
                keep = config.branch == "snapshot" and not terminal[i]
                action.child = StateNode(action, int(self.lengths[slot]), float(self.returns[slot]),
                                         bool(terminal[i]), problem.snapshot([i]) if keep else None)
        ended = terminal | (taken >= config.repeat + config.rollout_depth) if config.rollout_depth else terminal
        return terminal, ended

    def _fill(self, ended: np.ndarray) -> None:
        """Start new iterations in the simulator rows ``ended`` (their iterations are over) while the budget is
        expected to allow them (at the mean iteration length so far; a full batch at the start); drop the rest."""
        search, problem = self.search, self.search.problem
        running = np.ones(self.rows.size, dtype=bool)
        running[ended] = False
        if search.rollouts:
            mean = search.rollout_steps / search.rollouts
            rows = self.rows[running]
            spare = search.tracker.remaining - np.maximum(mean - (self.lengths[rows] - self.start[rows]), 1).sum()
        else:
            mean, spare = 1.0, math.inf
        saved = problem.snapshot() if self.rows.size and search.config.branch == "replay" else None
        new, snapshots = [], []
        while self.free and spare > 0 and search.open:
            path = search.select()
            node = path[-1].parent
            snapshots.append(search.state_of(node))  # a replay from reset replaces the batch (saved above)
            slot = self.free.pop(0)
            self.paths[slot] = path
            if node.depth:
                self.actions[slot, : node.depth] = actions_to(node)
            self.lengths[slot] = self.start[slot] = node.depth
            self.returns[slot] = node.value
            self.held[slot] = path[-1].action
            new.append(slot)
            spare -= max(mean, 1.0)
        if saved is not None:
            problem.restore(saved)
        if not self.rows.size:  # the first batch
            self.rows = np.array(new, dtype=np.int64)
            problem.restore(problem.concat(snapshots))
            return
        reuse = ended[: len(new)]  # new iterations take the ended rows' places, in order
        if new:
            problem.assign(reuse, problem.concat(snapshots))
            self.rows[reuse] = new
        if len(new) < ended.size:  # near the end of the budget: the batch shrinks
            running[reuse] = True
            keep = np.flatnonzero(running)
            self.rows = self.rows[keep]
            if keep.size:
                problem.restore(problem.snapshot(keep))

def mcts(problem: Problem, tracker: Tracker, rng: np.random.Generator, config: MCTSConfig | None = None) -> MCTS:
    """Search until the tracker's budget is spent; returns the search (its tree, for inspection)."""
    search = MCTS(problem, tracker, rng, config or MCTSConfig())
    search.run()
    return search
