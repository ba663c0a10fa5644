import numpy as np
import pytest

from search.core.rollout import Tracker
from search.crowd.agents.policies import load_policy
from search.crowd.problem import CoupledProblem
from search.crowd.sim.coupled import replay
from search.crowd.sim.scenarios import load_scenario
from search.solvers.baselines import random_search
from search.solvers.mcts import CHILD, DEPTH, PARENT, STATE, TERMINAL, VISITS, MCTSConfig, Tree, mcts
from search.solvers.reward import RewardConfig
from tests.support.synthetic import LockProblem

SEEDS = range(5)


def coupled(horizon: int = 40) -> CoupledProblem:
    return CoupledProblem(
        [load_policy("goal"), load_policy("orca")], load_scenario("paper-bl-tr"), reward=RewardConfig(horizon=horizon)
    )


def nodes(tree: Tree, root: int = 0):
    """The states below ``root`` (itself included), through the actions the tree keeps."""
    stack = [root]
    while stack:
        state = stack.pop()
        yield state
        stack.extend(int(tree.links[a, CHILD]) for a in tree.children(state) if tree.links[a, CHILD] >= 0)


def test_mcts_finds_the_lock_optimum_that_random_search_misses():
    for seed in SEEDS:
        tracker = Tracker(2000, 5)
        mcts(LockProblem(), tracker, np.random.default_rng(seed), MCTSConfig(repeat=1))
        assert tracker.best == 8.0, seed
        random = Tracker(2000, 5)
        random_search(LockProblem(), random, np.random.default_rng(seed))
        assert random.best < 8.0, seed
        best = tracker.queue.ranked()[0].actions
        assert best.shape == (8, 1) and np.all(best > 0.6)


@pytest.mark.parametrize("problem, budget", [(LockProblem, 1500), (coupled, 1500)])
def test_widening_rule(problem, budget):
    config = MCTSConfig(k=0.5, alpha=0.5, batch=8, repeat=1)
    search = mcts(problem(), Tracker(budget, 5), np.random.default_rng(1), config)
    tree, checked = search.tree, 0
    for state in nodes(tree, search.root):
        visits, children = tree.states[state, VISITS], tree.children(state)
        limit = config.k * visits**config.alpha
        terminal = sum(tree.links[a, CHILD] >= 0 and tree.states[tree.links[a, CHILD], TERMINAL] for a in children)
        assert limit <= len(children), "a node visited n times holds at least k * n**alpha actions"
        # beyond the limit only when every action so far ended the trajectory (then it must widen to go on)
        assert len(children) < limit + 1 + terminal
        checked += visits > 0
    assert checked >= 5


def test_search_rewards_equal_replays_from_reset():
    problem = coupled()
    tracker = Tracker(2500, 10)
    mcts(problem, tracker, np.random.default_rng(0), MCTSConfig(batch=8, repeat=3))
    assert len(tracker.queue) == 10
    for found in tracker.queue.ranked():
        trajectory = replay(problem.sim.policies, problem.sim.scenario, found.actions)
        total, _, terminal = problem.reward.trajectory(trajectory, problem.sim.config.dt)
        assert total == found.reward  # exactly: branching from snapshots is the same simulation
        assert terminal[-1] and not terminal[:-1].any()


def test_snapshot_branching_matches_the_toolbox_replay_from_reset():
    curves = {}
    for branch in ("snapshot", "replay"):
        tracker = Tracker(1200, 5)
        mcts(coupled(horizon=20), tracker, np.random.default_rng(3), MCTSConfig(batch=1, branch=branch))
        curves[branch] = [reward for _, reward in tracker.curve]
    # replaying costs simulator steps, so the same budget gets fewer iterations, along the same search
    assert len(curves["replay"]) >= 2
    assert curves["snapshot"][: len(curves["replay"])] == curves["replay"]


def test_same_seed_same_search_and_another_seed_another():
    def run(seed):
        tracker = Tracker(800, 5)
        mcts(coupled(horizon=20), tracker, np.random.default_rng(seed), MCTSConfig(batch=4))
        return [(f.reward, f.actions.tobytes()) for f in tracker.queue.ranked()]

    assert run(7) == run(7)
    assert run(7) != run(8)


def test_repeat_holds_each_action_for_its_steps():
    tracker = Tracker(1500, 10)
    search = mcts(coupled(), tracker, np.random.default_rng(0), MCTSConfig(repeat=4, batch=8))
    for found in tracker.queue.ranked():
        steps = np.arange(len(found.actions))
        assert np.array_equal(found.actions, found.actions[steps - steps % 4])
    tree = search.tree
    depths = {tree.states[state, DEPTH] for state in nodes(tree) if not tree.states[state, TERMINAL]}
    assert depths and all(depth % 4 == 0 for depth in depths)


def test_receding_horizon_commits_step_by_step_and_drops_other_branches():
    tracker = Tracker(2000, 5)
    search = mcts(
        coupled(horizon=20), tracker, np.random.default_rng(0), MCTSConfig(mode="receding", batch=8, repeat=2)
    )
    tree = search.tree
    assert tree.states[search.root, DEPTH] >= 4
    state = search.root
    while tree.states[state, PARENT] >= 0:  # every committed state kept only the action it committed
        state = tree.links[tree.states[state, PARENT], STATE]
        assert len(tree.children(state)) == 1
    assert tracker.steps >= tracker.budget or tree.states[search.root, TERMINAL]
    # the dropped branches' snapshots are gone: a long search keeps only those of the states it still holds
    kept = set(nodes(tree))
    assert len(kept) < len(tree.snapshots)
    assert {i for i, snapshot in enumerate(tree.snapshots) if snapshot is not None} <= kept


def test_bad_settings_say_what_is_wrong():
    with pytest.raises(ValueError, match="mode"):
        MCTSConfig(mode="sideways")
    with pytest.raises(ValueError, match="alpha"):
        MCTSConfig(alpha=0.0)


class Recording:
    """A problem that records the batch size of every step."""

    def __init__(self, problem):
        self.problem, self.sizes = problem, []

    def __getattr__(self, name):
        return getattr(self.problem, name)

    def step(self, actions):
        self.sizes.append(len(actions))
        return self.problem.step(actions)


@pytest.mark.parametrize("problem", [LockProblem, coupled])
def test_rows_whose_iteration_ended_take_the_next_iteration(problem):
    recording = Recording(problem())
    tracker = Tracker(3000, 5)
    search = mcts(recording, tracker, np.random.default_rng(2), MCTSConfig(batch=16, repeat=2))
    sizes = np.array(recording.sizes)
    assert search.rollouts > 3 * 16  # iterations ended and were replaced many times over
    full = np.flatnonzero(sizes == 16)
    # full until the budget is nearly spent; then the rows in flight finish without successors
    assert full.size > 0.8 * sizes.size and np.all(sizes[: full[-1]] == 16)
    assert np.all(np.diff(sizes[full[-1] :]) <= 0)
    assert tracker.steps >= tracker.budget and sizes.sum() == tracker.steps


def test_replay_from_reset_with_a_full_batch_matches_replays():
    problem = coupled(horizon=30)
    tracker = Tracker(2000, 8)
    search = mcts(problem, tracker, np.random.default_rng(4), MCTSConfig(batch=4, branch="replay", repeat=2))
    assert search.replayed > 0
    for found in tracker.queue.ranked():
        trajectory = replay(problem.sim.policies, problem.sim.scenario, found.actions)
        assert problem.reward.trajectory(trajectory, problem.sim.config.dt)[0] == found.reward


def test_rollout_depth_cuts_iterations_after_their_new_edge():
    problem = LockProblem(horizon=30, threshold=-0.9)  # 95% of actions are right: long trajectories
    tracker = Tracker(600, 5)
    search = mcts(problem, tracker, np.random.default_rng(0), MCTSConfig(batch=4, repeat=1, rollout_depth=3))
    assert tracker.steps <= 4 * search.rollouts  # every iteration: its new edge and at most 3 more steps
    assert tracker.trajectories < search.rollouts  # cut iterations back up without a finished trajectory
    assert max(search.tree.states[state, DEPTH] for state in nodes(search.tree)) >= 5


class WithoutAssign(LockProblem):
    """The combination lock as a problem written before ``assign`` joined the interface."""

    def __getattribute__(self, name):
        if name == "assign":
            raise AttributeError(name)
        return super().__getattribute__(name)


def test_a_problem_without_assign_gets_the_same_search():
    def run(problem):
        tracker = Tracker(1500, 5)
        search = mcts(problem, tracker, np.random.default_rng(6), MCTSConfig(batch=8, repeat=1))
        return [(f.reward, f.actions.tobytes()) for f in tracker.queue.ranked()], search.rollouts

    assert not hasattr(WithoutAssign(), "assign")
    assert run(WithoutAssign()) == run(LockProblem())
