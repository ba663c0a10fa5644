"""Monte Carlo tree search with double progressive widening over environment actions, as adaptive stress testing
runs it (the AST toolbox's ``MCTSdpw``), with two changes that make it fast:

- **branching by snapshot**: every tree node keeps a snapshot of its simulator rows, so an iteration restores its
  leaf's parent instead of replaying the action prefix from reset (``branch="replay"`` keeps the toolbox's way,
  as the reference the benchmarks compare against);
- **a full batch of iterations in flight**: up to ``batch`` iterations are expanded and rolled out together, one
  simulator row each, so the agents' policies run on batches. When an iteration ends (its trajectory ends, or
  ``rollout_depth`` cuts it), its value is backed up at once and the next iteration is selected into its row,
  so the batch stays full until the budget runs out. Each selection counts its visits at once, so the next one
  sees them and widening stays exact; actions still in flight have no value yet and their siblings go first.
  The budget is a bound: where it no longer pays for a step of every row in flight, the first rows step and the
  others' iterations stop unfinished.

Widening: a state node visited n times gets a new action, sampled from the environment action prior, while it has
fewer than ``k * n**alpha`` actions; otherwise UCT picks ``argmax Q + c * sqrt(ln n / n_a)`` among the actions
that do not end the trajectory. The simulator is deterministic, so each action has one child state (no state
widening), and an action that ends the trajectory has an exact value: choosing it again would teach nothing and,
with snapshots, cost nothing, so a node whose every action ends the trajectory widens instead. An action chosen
again while its child is still being computed gets another iteration through the same edge (the same child
state, another rollout).

Modes: ``tree`` grows one tree from the initial state for the whole budget; ``receding`` (the toolbox's
``stress_test`` mode, the one the paper ran) searches from a root, commits the root's best action after the
root's share of the budget (once one of its actions has a value), drops the other branches, and goes on from the
new root; iterations still in flight in dropped branches finish and count.

The same seed gives the same search: selections, prior samples and backups happen in a fixed order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import numba
import numpy as np

from search.core.problem import Assign, Problem, provides
from search.core.rollout import Tracker
from search.solvers.solver import ProblemSearch, register


@dataclass(frozen=True)
class MCTSConfig:
    """Widening (k = alpha = 0.5) and rollouts to the end are the paper's. The paper ran exploration 100, mean
    backup, one step per action and receding mode; the defaults here won clearly in BENCHMARKS.md ("Search"):
    exploration 10 (in reward units), max backup (the simulator is deterministic: an action is as good as the
    best trajectory through it) and actions held for 8 steps (2 s), which moves humans coherently. 64 iterations
    in flight find as much as 32 at equal budget and run the policies on batches twice as large."""

    exploration: float = 10.0
    k: float = 0.5
    alpha: float = 0.5
    rollout_depth: int = 0  # steps a rollout may take after its new node; 0: to the end of the trajectory
    repeat: int = 8  # steps each tree action (and each rollout action) is held for
    mode: str = "tree"  # "tree" or "receding"
    backup: str = "max"  # Q of an action: "mean" return through it (the toolbox) or its "max"
    batch: int = 64  # iterations in flight together (rows of the batched rollouts)
    branch: str = "snapshot"  # "snapshot", or "replay" from reset as the AST toolbox does

    def __post_init__(self) -> None:
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


# Columns of the tree's arrays. Tree.states: a state's visits, its first and last action and their count, the action
# that led to it (-1 at the initial state), its steps from the initial state, whether it ends the trajectory.
# Tree.links: an action's child state, the next action of its state, returns backed up, whether its child goes on,
# its state, whether it is still in the tree (receding mode drops branches). Tree.stats: q, selections, sum and
# best of the returns backed up.
VISITS, FIRST, LAST, COUNT, PARENT, DEPTH, TERMINAL = range(7)
CHILD, NEXT, COMPLETED, OPEN, STATE, KEPT = range(6)
Q, SELECTIONS, TOTAL, BEST = range(4)


class Tree:
    """The search tree in flat arrays (grown by doubling), so that selection and backup are each one compiled loop:
    an iteration of a few steps descends through a dozen states of dozens of actions, then backs up through as
    many. A state or an action is its row. A state's actions form a list through ``NEXT``, in the order they were
    added. An action's child is -1 until it is expanded, its q -inf while no return is back (its siblings go
    first), and it is open while its child does not end the trajectory. State 0 is the initial state."""

    def __init__(self, action_shape: tuple[int, ...], snapshot: Any) -> None:
        self.states = np.zeros((16, 7), np.int64)
        self.values = np.zeros(16)  # each state's reward accumulated from the initial state
        self.snapshots: list[Any] = []  # each state's simulator row; None when branching by replay, terminal or dropped
        self.links = np.zeros((16, 6), np.int64)
        self.stats = np.zeros((16, 4))
        self.actions = np.zeros((16, *action_shape))  # each action's environment action, held ``repeat`` steps
        self.n_actions = 0
        self._add_state(-1, 0, 0.0, False, snapshot)

    def _add_state(self, parent: int, depth: int, value: float, terminal: bool, snapshot: Any) -> int:
        index = len(self.snapshots)
        if index == self.states.shape[0]:
            self.states, self.values = _grown(self.states), _grown(self.values)
        self.states[index] = (0, -1, -1, 0, parent, depth, terminal)
        self.values[index] = value
        self.snapshots.append(snapshot)
        return index

    def add_action(self, state: int, action: np.ndarray) -> int:
        """A new action of ``state``, not yet selected."""
        index = self.n_actions
        if index == self.links.shape[0]:
            self.links, self.stats, self.actions = _grown(self.links), _grown(self.stats), _grown(self.actions)
        self.links[index] = (-1, -1, 0, 1, state, 1)
        self.stats[index] = (-math.inf, 0.0, 0.0, -math.inf)
        self.actions[index] = action
        last = self.states[state, LAST]
        if last < 0:
            self.states[state, FIRST] = index
        else:
            self.links[last, NEXT] = index
        self.states[state, LAST] = index
        self.states[state, COUNT] += 1
        self.n_actions += 1
        return index

    def expand(self, action: int, depth: int, value: float, terminal: bool, snapshot: Any) -> None:
        """Make the state ``action`` leads to (without its snapshot if the action was dropped meanwhile)."""
        child = self._add_state(action, depth, value, terminal, snapshot if self.links[action, KEPT] else None)
        self.links[action, CHILD] = child
        self.links[action, OPEN] = not terminal

    def children(self, state: int) -> list[int]:
        """The state's actions, in the order they were added."""
        out, action = [], int(self.states[state, FIRST])
        while action >= 0:
            out.append(action)
            action = int(self.links[action, NEXT])
        return out

    def q(self, action: int, backup: str) -> float:
        completed = self.links[action, COMPLETED]
        if not completed:
            return -math.inf  # still in flight: its siblings go first
        return float(self.stats[action, BEST] if backup == "max" else self.stats[action, TOTAL] / completed)

    def keep_only(self, state: int, action: int) -> None:
        """Drop every other action of ``state`` and what lies below it (receding mode's commit), with their
        snapshots, so that a long search keeps only the snapshots it can still branch from."""
        dropped = [a for a in self.children(state) if a != action]
        while dropped:
            other = dropped.pop()
            self.links[other, KEPT] = 0
            child = self.links[other, CHILD]
            if child >= 0:
                self.snapshots[child] = None
                dropped.extend(self.children(child))
        self.states[state, FIRST] = self.states[state, LAST] = action
        self.states[state, COUNT] = 1
        self.links[action, NEXT] = -1

    def write_actions_to(self, state: int, out: np.ndarray) -> None:
        """Write the environment actions from the initial state to ``state`` into ``out[: depth]``, step by step."""
        _write_actions(state, self.states, self.links, self.actions, out)

    def actions_to(self, state: int) -> np.ndarray:
        """The environment actions from the initial state to ``state``, step by step, (depth, *shape)."""
        out = np.empty((self.states[state, DEPTH], *self.actions.shape[1:]))
        self.write_actions_to(state, out)
        return out


def _grown(array: np.ndarray) -> np.ndarray:
    """The array with twice the rows, the new ones uninitialised."""
    grown = np.empty((2 * array.shape[0], *array.shape[1:]), array.dtype)
    grown[: array.shape[0]] = array
    return grown


@numba.njit(cache=True)
def _write_actions(state: int, states: np.ndarray, links: np.ndarray, actions: np.ndarray, out: np.ndarray) -> None:
    """``Tree.write_actions_to``: each action on the path to ``state``, once for every step it is held."""
    edge = states[state, PARENT]
    while edge >= 0:
        parent = links[edge, STATE]
        for t in range(states[parent, DEPTH], states[state, DEPTH]):
            out[t] = actions[edge]
        state, edge = parent, states[parent, PARENT]


@numba.njit(cache=True)
def _descend(
    root: int,
    states: np.ndarray,
    links: np.ndarray,
    stats: np.ndarray,
    k: float,
    alpha: float,
    exploration: float,
    path: np.ndarray,
) -> tuple[int, int]:
    """Selection's descent from ``root``, counting visits and selections, with the action ids it takes written
    into ``path``: at each state, while it has at least ``k * visits**alpha`` actions, the open one with the
    largest ``q + exploration * sqrt(ln visits / selections)`` (the first of equal scores), until an action
    whose child is not there yet. Returns (path length, the state that must widen instead, or -1)."""
    state, length = root, 0
    while True:
        states[state, VISITS] += 1
        chosen = -1
        if states[state, COUNT] >= k * states[state, VISITS] ** alpha:
            log_n, best_score = math.log(states[state, VISITS]), -math.inf
            action = states[state, FIRST]
            while action >= 0:
                if links[action, OPEN]:
                    score = stats[action, Q] + exploration * math.sqrt(log_n / stats[action, SELECTIONS])
                    if chosen < 0 or score > best_score:
                        chosen, best_score = action, score
                action = links[action, NEXT]
        if chosen < 0:  # widening is due, or every action ends the trajectory
            return length, state
        stats[chosen, SELECTIONS] += 1
        if length == path.shape[0]:
            raise ValueError("a path through the tree is longer than the problem's horizon")
        path[length] = chosen
        length += 1
        if links[chosen, CHILD] < 0:
            return length, -1
        state = links[chosen, CHILD]


@numba.njit(cache=True)
def _backup(path: np.ndarray, value: float, mean: bool, links: np.ndarray, stats: np.ndarray) -> None:
    """Back a return up through the actions ``path``."""
    for action in path:
        links[action, COMPLETED] += 1
        stats[action, TOTAL] += value
        stats[action, BEST] = max(stats[action, BEST], value)
        stats[action, Q] = stats[action, TOTAL] / links[action, COMPLETED] if mean else stats[action, BEST]


@numba.njit(cache=True)
def _record_step(
    held: np.ndarray,
    reward: np.ndarray,
    terminal: np.ndarray,
    actions: np.ndarray,
    lengths: np.ndarray,
    returns: np.ndarray,
    taken: np.ndarray,
    countdown: np.ndarray,
    repeat: int,
    rollout_depth: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Record one batched step in every row in use (as many as ``reward``): its action, length, return and step
    counts. Returns (expanded, ended): the rows whose new edge ends on this step (held ``repeat`` steps, or the
    trajectory ended first), and the rows whose iteration is over."""
    n = reward.shape[0]
    expanded, ended = np.zeros(n, np.bool_), np.zeros(n, np.bool_)
    for i in range(n):
        if lengths[i] >= actions.shape[1]:
            raise ValueError("a trajectory ran past the problem's horizon")
        actions[i, lengths[i]] = held[i]
        lengths[i] += 1
        returns[i] += reward[i]
        countdown[i] -= 1
        taken[i] += 1
        expanded[i] = taken[i] == repeat or (terminal[i] and taken[i] < repeat)
        ended[i] = terminal[i] or (rollout_depth > 0 and taken[i] >= repeat + rollout_depth)
    return expanded, ended


class MCTS:
    def __init__(self, problem: Problem, tracker: Tracker, rng: np.random.Generator, config: MCTSConfig) -> None:
        self.problem, self.tracker, self.rng, self.config = problem, tracker, rng, config
        problem.reset(1)
        self.tree = Tree(problem.action_shape, problem.snapshot() if config.branch == "snapshot" else None)
        self.root = 0  # the state selection starts from: the initial state (in receding mode, the last committed)
        self.replayed = 0  # simulator steps spent replaying prefixes from reset (branch="replay")
        self.rollouts = 0  # iterations finished (backed up)
        self.rollout_ends = 0  # their lengths from the initial state, summed
        self.batch_rows = 0  # rows stepped, summed over batched steps (batch_rows / batch_steps: mean batch)
        self.batch_steps = 0

    def run(self) -> None:
        self.until = self._commit_point() if self.config.mode == "receding" else math.inf
        InFlight(self).run()

    def _commit_point(self) -> float:
        """Receding mode: the step count after which the root commits (its share of the remaining budget)."""
        return self.tracker.steps + self.tracker.remaining / max(self._expected_steps_left(), 1)

    def _expected_steps_left(self) -> int:
        """Steps from the root to the end of the best trajectory so far (the horizon if none yet)."""
        ranked = self.tracker.queue.ranked()
        length = ranked[0].actions.shape[0] if ranked else self.problem.horizon
        return length - int(self.tree.states[self.root, DEPTH])

    def maybe_commit(self) -> None:
        """Receding mode: once the root's share of the budget is spent and one of its actions has a value, move
        the root to the child of its best action and forget the other branches (iterations still running in
        them finish and count, but no longer steer the search)."""
        tree = self.tree
        if self.tracker.steps < self.until or tree.states[self.root, TERMINAL]:
            return
        done = [a for a in tree.children(self.root) if tree.links[a, CHILD] >= 0 and tree.links[a, COMPLETED]]
        if not done:
            return
        best = max(done, key=lambda a: tree.q(a, self.config.backup))
        tree.keep_only(self.root, best)
        self.root = int(tree.links[best, CHILD])
        self.until = self._commit_point()

    @property
    def open(self) -> bool:
        """Whether new iterations may start: budget left, and (receding) a root that does not end the search."""
        return not self.tracker.exhausted and not self.tree.states[self.root, TERMINAL]

    def select(self, path: np.ndarray) -> tuple[int, int]:
        """Descend from the root to an action whose child is new or in flight, counting visits and selections
        (widening where due); the actions taken go into ``path``. Returns (their number, the last)."""
        c, tree = self.config, self.tree
        length, widen = _descend(self.root, tree.states, tree.links, tree.stats, c.k, c.alpha, c.exploration, path)
        if widen < 0:
            return length, int(path[length - 1])
        action = tree.add_action(widen, self.problem.prior.sample(self.rng, 1)[0])
        tree.stats[action, SELECTIONS] += 1
        path[length] = action
        return length + 1, action

    def backup(self, path: np.ndarray, value: float) -> None:
        _backup(path, value, self.config.backup == "mean", self.tree.links, self.tree.stats)

    def state_of(self, state: int) -> Any:
        """The state's simulator row: its snapshot, or (the toolbox's way) a replay of its actions from reset,
        which leaves the problem holding that one row."""
        snapshot = self.tree.snapshots[state]
        if snapshot is not None:
            return snapshot
        self.problem.reset(1)
        for action in self.tree.actions_to(state):
            self.problem.step(action[None])
            self.tracker.count(1)
            self.replayed += 1
        return self.problem.snapshot()


class InFlight:
    """The iterations in flight: up to ``batch`` rows stepped together. Each row expands its new edge (the edge's
    action held ``repeat`` steps, then a tree node with its snapshot) and rolls out with prior actions renewed
    every ``repeat`` steps. When rows end, their values are backed up at once and new iterations are selected
    into their places, so the policies keep seeing a full batch until the budget runs out.

    Row i of the simulator is row i of every array here (the first ``n`` rows are in use)."""

    def __init__(self, search: MCTS) -> None:
        self.search = search
        problem, width = search.problem, search.config.batch
        self.n = 0
        # Each row's actions from the initial state; the part up to its node is written out only when a finished
        # trajectory may enter the top-K queue (most may not).
        self.actions = np.zeros((width, problem.horizon, *problem.action_shape))
        self.lengths = np.zeros(width, dtype=np.int64)
        self.returns = np.zeros(width)
        self.taken = np.zeros(width, dtype=np.int64)  # steps each iteration has taken
        self.countdown = np.zeros(width, dtype=np.int64)  # steps until its held action is renewed
        self.held = np.zeros((width, *problem.action_shape))  # the new edge's action, then the rollout's
        # Each row's path through the tree (actions; an action takes at least a step) and its new edge.
        self.paths = np.zeros((width, problem.horizon + 1), dtype=np.int64)
        self.path_lengths = np.zeros(width, dtype=np.int64)
        self.edges = np.zeros(width, dtype=np.int64)

    def run(self) -> None:
        search, tree = self.search, self.search.tree
        self._fill(np.zeros(0, dtype=np.int64))
        while self.n:
            self._fit_budget()
            if not self.n:
                break
            terminal, ended = self._step()
            if not ended.any():
                continue
            ended = np.flatnonzero(ended)
            for i in ended.tolist():
                if terminal[i]:
                    if search.tracker.queue.admits(self.returns[i]):  # only then its tree part is written out
                        tree.write_actions_to(tree.links[self.edges[i], STATE], self.actions[i])
                    search.tracker.finish(self.returns[i], self.actions[i, : self.lengths[i]])
                search.backup(self.paths[i, : self.path_lengths[i]], float(self.returns[i]))
                search.rollouts += 1
                search.rollout_ends += int(self.lengths[i])
            search.maybe_commit()
            self._fill(ended)

    def _fit_budget(self) -> None:
        """Keep only the rows the budget still pays a step for (the first ones): the others' iterations stop
        unfinished, with no backup, so the budget bounds the search's steps."""
        remaining = self.search.tracker.remaining
        if self.n > remaining:
            keep = np.arange(remaining)
            self._compact(keep)
            if keep.size:
                self.search.problem.restore(self.search.problem.snapshot(keep))

    def _step(self) -> tuple[np.ndarray, np.ndarray]:
        """One batched step of every row; new tree nodes at the end of their edge. Returns (terminal, ended)."""
        search, n = self.search, self.n
        config, problem = search.config, search.problem
        countdown = self.countdown[:n]
        renew = np.flatnonzero(countdown == 0)
        if renew.size:
            self.held[renew] = problem.prior.sample(search.rng, renew.size)
            countdown[renew] = config.repeat
        reward, terminal = problem.step(self.held[:n])
        search.tracker.count(n)
        search.batch_rows += n
        search.batch_steps += 1
        expanded, ended = _record_step(
            self.held,
            reward,
            terminal,
            self.actions,
            self.lengths,
            self.returns,
            self.taken,
            countdown,
            config.repeat,
            config.rollout_depth,
        )
        tree = search.tree
        for i in np.flatnonzero(expanded).tolist():
            action = self.edges[i]
            if tree.links[action, CHILD] < 0:  # another row may have expanded it first
                keep = config.branch == "snapshot" and not terminal[i]
                tree.expand(
                    action,
                    int(self.lengths[i]),
                    float(self.returns[i]),
                    bool(terminal[i]),
                    problem.snapshot([i]) if keep else None,
                )
        return terminal, ended

    def _fill(self, ended: np.ndarray) -> None:
        """Start new iterations in the rows ``ended`` (their iterations are over), and in unused rows, while the
        budget is expected to allow them; drop the ended rows left over. The budget estimate: every iteration in
        flight or started runs to the mean length of those finished so far. Before any has, a budget of at least
        ``batch`` x horizon / 2 starts all ``batch``; a smaller one only as many as it pays to the horizon, so that
        they can finish."""
        search, problem, tree, n = self.search, self.search.problem, self.search.tree, self.n
        width, remaining = self.actions.shape[0], search.tracker.remaining
        end = search.rollout_ends / search.rollouts if search.rollouts else 0.0  # iterations end near one depth
        most = width
        if not search.rollouts and remaining < width * problem.horizon / 2:
            most = max(1, remaining // problem.horizon)
        if not search.rollouts or remaining > width * problem.horizon:
            spare = math.inf  # the first batch, or far from the end of the budget: no estimate needed
        else:
            running = np.ones(n, dtype=bool)
            running[ended] = False
            spare = remaining - np.maximum(end - self.lengths[:n][running], 1.0).sum()
        places = ended.tolist() + list(range(n, width))  # ended rows first, then unused ones
        saved = problem.snapshot() if n and search.config.branch == "replay" else None
        snapshots: list[Any] = []
        while len(snapshots) < min(len(places), most) and spare > 0 and search.open and self._replay_fits():
            i = places[len(snapshots)]
            self.path_lengths[i], edge = search.select(self.paths[i])
            state = tree.links[edge, STATE]
            depth = int(tree.states[state, DEPTH])
            snapshots.append(search.state_of(state))  # a replay from reset replaces the batch (saved above)
            self.edges[i] = edge
            self.lengths[i] = depth
            self.taken[i] = 0
            self.countdown[i] = search.config.repeat
            self.returns[i] = tree.values[state]
            self.held[i] = tree.actions[edge]
            spare -= max(end - depth, 1.0)
        if saved is not None:
            problem.restore(saved)
        reused = min(len(snapshots), ended.size)
        if reused and provides(problem, Assign):
            assign = cast(Assign, problem).assign
            for i, snapshot in zip(places[:reused], snapshots, strict=False):
                assign([i], snapshot)
        elif reused:  # a problem without assign: rebuild the batch row by row
            new_rows = dict(zip(places[:reused], snapshots, strict=False))
            problem.restore(problem.concat([new_rows[i] if i in new_rows else problem.snapshot([i]) for i in range(n)]))
        if len(snapshots) > reused:  # more rows than before: the new ones go after the others
            grown = snapshots[reused:]
            problem.restore(problem.concat(([problem.snapshot()] if n else []) + grown))
            self.n = n + len(grown)
        elif reused < ended.size:  # near the end of the budget: the batch shrinks
            keep = np.flatnonzero(np.isin(np.arange(n), ended[reused:], invert=True))
            self._compact(keep)
            if keep.size:
                problem.restore(problem.snapshot(keep))

    def _replay_fits(self) -> bool:
        """Whether the budget pays for a new iteration's replay from reset (``branch="replay"``; at most a
        horizon of steps): a snapshot costs nothing."""
        search = self.search
        return search.config.branch == "snapshot" or search.tracker.remaining > search.problem.horizon

    def _compact(self, keep: np.ndarray) -> None:
        """Keep rows ``keep`` (in order) as rows 0, 1, ..."""
        count = keep.size
        for array in (
            self.actions,
            self.lengths,
            self.returns,
            self.taken,
            self.countdown,
            self.held,
            self.paths,
            self.path_lengths,
            self.edges,
        ):
            array[:count] = array[keep]
        self.n = count


def mcts(problem: Problem, tracker: Tracker, rng: np.random.Generator, config: MCTSConfig | None = None) -> MCTS:
    """Search until the tracker's budget is spent; returns the search (its tree, for inspection)."""
    search = MCTS(problem, tracker, rng, config or MCTSConfig())
    search.run()
    return search


register(ProblemSearch("mcts", MCTSConfig, mcts))
