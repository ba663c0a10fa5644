"""Search benchmarks: speed of the search loop and quality of the solvers at equal budgets.

    .venv/bin/python benchmarks/bench_search.py                 # both parts (a few minutes on 2 cores)
    .venv/bin/python benchmarks/bench_search.py --part speed
    .venv/bin/python benchmarks/bench_search.py --part quality --seeds 10 --budget 40000
    .venv/bin/python benchmarks/bench_search.py --agents lo,med,hi --budget 100000 --jobs 2   # shipped DS-RNN agents

Speed: coupled steps per second of the whole MCTS loop (selection, snapshot branching, batched rollouts,
reward, top-K) against the policy-only bound (the agents' act() alone on batches of the same size, measured in
the same run) and against the AST toolbox's way (replay every branch from reset, one at a time). Run for a
scripted pair and for a pair of DS-RNN agents (`--speed-agents`, default the shipped lo and med; `untrained` for
two untrained networks of the default size).

Quality: best reward found against simulator steps for MCTS, N-first (the first trajectory, as the paper's
baseline clip), random search and CEM on every pair of `--agents` (default: the scripted agents) and both paper
scenarios, in `--jobs` processes (torch at one thread each); MCTS settings with `--set key=value`; mean and 95%
confidence interval over seeds, and the area under the best-so-far curve (its mean from 20% to 100% of the
budget). Writes
benchmarks/search_quality.png and prints Markdown tables.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from search.core.rollout import Tracker  # noqa: E402
from search.crowd.agents.policies import load_policy  # noqa: E402
from search.crowd.problem import CoupledProblem  # noqa: E402
from search.crowd.sim.coupled import CoupledSimulator  # noqa: E402
from search.crowd.sim.scenarios import load_scenario  # noqa: E402
from search.solvers.baselines import cem, n_first, random_search  # noqa: E402
from search.solvers.mcts import MCTSConfig, mcts  # noqa: E402
from search.solvers.runner import parse_settings  # noqa: E402

SCRIPTED = ["goal", "orca", "social_force"]
SCENARIOS = ["paper-bl-tr", "paper-tl-br"]
MCTS_CONFIG = MCTSConfig()  # replaced by --set in main() and in every worker process
SOLVERS = {
    "mcts": lambda problem, tracker, rng: mcts(problem, tracker, rng, MCTS_CONFIG),
    "nfirst": lambda problem, tracker, rng: n_first(problem, tracker, rng),
    "random": lambda problem, tracker, rng: random_search(problem, tracker, rng),
    "cem": lambda problem, tracker, rng: cem(problem, tracker, rng),
}


def one_thread() -> None:
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(1)


def dsrnn_pair(names: str):
    one_thread()
    if names != "untrained":
        return [load_policy(name) for name in names.split(",")]
    import torch

    from search.crowd.agents.dsrnn import DSRNN, DSRNNPolicy

    policies = []
    for seed in (1, 2):
        torch.manual_seed(seed)
        policies.append(DSRNNPolicy(DSRNN().eval(), name=f"dsrnn-{seed}"))
    return policies


def policy_bound(policies, scenario, batch: int, repeats: int) -> float:
    """Coupled steps/s if the world and the search cost nothing: every agent's act() on a batch of observations."""
    sim = CoupledSimulator(policies, scenario, batch=batch)
    rng = np.random.default_rng(0)
    for _ in range(5):
        sim.step(rng.uniform(-0.25, 0.25, (batch, sim.config.human_num, 2)))
    observations = sim.observations()
    states = [s.copy() for s in sim.policy_states]
    for policy, observation, state in zip(policies, observations, states, strict=True):
        policy.act(observation, state)  # warm-up
    started = time.perf_counter()
    for _ in range(repeats):
        for policy, observation, state in zip(policies, observations, states, strict=True):
            policy.act(observation, state)
    return batch * repeats / (time.perf_counter() - started)


def timed_search(policies, scenario, budget: int, config: MCTSConfig) -> tuple[float, float, float]:
    """(new simulator steps/s, all simulator steps/s, mean rows per batched step) of one MCTS run."""
    problem = CoupledProblem(policies, scenario)
    tracker = Tracker(budget, 30)
    started = time.perf_counter()
    search = mcts(problem, tracker, np.random.default_rng(0), config)
    elapsed = time.perf_counter() - started
    rows = search.batch_rows / max(search.batch_steps, 1)
    return (tracker.steps - search.replayed) / elapsed, tracker.steps / elapsed, rows


def speed(budget: int, speed_agents: str, batch: int, repeats: int = 5) -> None:
    scenario = load_scenario("paper-bl-tr")
    label = (
        "DS-RNN vs DS-RNN (untrained weights)"
        if speed_agents == "untrained"
        else f"{' vs '.join(speed_agents.split(','))} (DS-RNN)"
    )
    pairs = {"goal vs orca (scripted)": [load_policy("goal"), load_policy("orca")], label: dsrnn_pair(speed_agents)}
    loop_config = MCTSConfig(batch=batch)
    loop_name = f"batch {batch}" + (" (default" if batch == MCTSConfig().batch else " (not the default")
    runs = [  # (label, config, share of the budget)
        ("MCTS tree, snapshots, batch 1", MCTSConfig(batch=1), 0.25),
        ("MCTS tree, replay from reset, batch 1", MCTSConfig(batch=1, branch="replay"), 0.25),
        ("MCTS receding, snapshots, batch 1", MCTSConfig(batch=1, mode="receding", repeat=1), 0.25),
        (
            "MCTS receding, replay from reset, batch 1 (the AST toolbox's way)",
            MCTSConfig(batch=1, mode="receding", repeat=1, branch="replay"),
            0.25,
        ),
    ]
    print(f"\n### Throughput (coupled steps/s, paper-bl-tr, T = 100, budget {budget:,} steps)\n")
    print(
        f"New simulator steps per second (replayed prefixes not counted; in brackets with them). The bound is "
        f"every agent's act() alone on batches of {batch} observations, the loop's batch; the bound and the "
        f"loop are each measured {repeats} times, alternately (about a second each), and the share is the median "
        f"of the {repeats} pairs' shares.\n"
    )
    print("| agents | search loop | steps/s | share of policy-only bound |")
    print("|---|---|---|---|")
    for label, policies in pairs.items():
        timed_search(policies, scenario, 2000, MCTSConfig())  # warm-up: numba compilation, first torch calls
        bounds, loops, rows = [], [], []
        for _ in range(repeats):
            bounds.append(policy_bound(policies, scenario, batch, repeats=400))
            new, _, mean_rows = timed_search(policies, scenario, budget, loop_config)
            loops.append(new)
            rows.append(mean_rows)
        bound, loop = float(np.median(bounds)), float(np.median(loops))
        pair_shares = np.array(loops) / np.array(bounds)
        shares = [f"{share:.0%}" for share in sorted(pair_shares)]
        print(f"| {label} | policy-only bound, batch {batch} | {bound:,.0f} | 100% |")
        print(
            f"| {label} | MCTS tree, snapshots, {loop_name}; {np.mean(rows):.1f} rows per step on average) "
            f"| {loop:,.0f} | {np.median(pair_shares):.0%} (runs: {', '.join(shares)}) |",
            flush=True,
        )
        for name, config, share in runs:
            new, total, _ = timed_search(policies, scenario, int(budget * share), config)
            extra = f" ({total:,.0f})" if config.branch == "replay" else ""
            print(f"| {label} | {name} | {new:,.0f}{extra} | {new / bound:.0%} |", flush=True)


def best_at(curve: list[tuple[int, float]], grid: np.ndarray) -> np.ndarray:
    """Best reward found by each grid point of simulator steps (NaN before the first trajectory)."""
    steps = np.array([s for s, _ in curve])
    rewards = np.array([r for _, r in curve])
    index = np.searchsorted(steps, grid, side="right") - 1
    return np.where(index >= 0, rewards[np.maximum(index, 0)], np.nan)


def ci95(values: np.ndarray) -> float:
    from scipy import stats

    values = values[~np.isnan(values)]
    if len(values) < 2:
        return float("nan")
    return float(stats.t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / np.sqrt(len(values)))


def init_worker(settings: dict) -> None:
    global MCTS_CONFIG
    one_thread()
    MCTS_CONFIG = MCTSConfig(**settings)


def one_search(pair, scenario_name: str, solver: str, seed: int, budget: int, grid: np.ndarray) -> np.ndarray:
    problem = CoupledProblem([load_policy(a) for a in pair], load_scenario(scenario_name))
    tracker = Tracker(budget, 1 if solver == "nfirst" else 30)
    SOLVERS[solver](problem, tracker, np.random.default_rng(seed))
    curve = tracker.curve if solver != "nfirst" else [(0, tracker.best)]  # its one clip, shown as is
    return best_at(curve, grid)


def quality(agents: list[str], budget: int, seeds: int, plot: Path, jobs: int) -> None:
    from concurrent.futures import ProcessPoolExecutor

    grid = np.linspace(budget / 5, budget, 9).astype(int)  # batched solvers report nothing before 10% or so
    results = {}  # (pair, scenario, solver) -> (seeds, grid) best-so-far
    started = time.perf_counter()
    pairs = list(itertools.combinations(agents, 2))
    cases = list(itertools.product(pairs, SCENARIOS))
    settings = dataclasses.asdict(MCTS_CONFIG)
    with ProcessPoolExecutor(jobs, initializer=init_worker, initargs=(settings,)) as pool:
        futures = {
            (pair, scenario_name, solver, seed): pool.submit(
                one_search, pair, scenario_name, solver, seed, budget, grid
            )
            for pair, scenario_name in cases
            for solver in SOLVERS
            for seed in range(seeds)
        }
        for pair, scenario_name in cases:
            for solver in SOLVERS:
                results[pair, scenario_name, solver] = np.array(
                    [futures[pair, scenario_name, solver, seed].result() for seed in range(seeds)]
                )
            print(f"  {'-'.join(pair)} {scenario_name}: {time.perf_counter() - started:.0f} s", file=sys.stderr)

    changed = {k: v for k, v in settings.items() if v != getattr(MCTSConfig(), k)}
    print(
        f"\n### Search quality ({', '.join(agents)}, budget {budget:,} simulator steps, {seeds} seeds"
        f"{', MCTS ' + str(changed) if changed else ''}; {time.perf_counter() - started:.0f} s on {jobs} "
        f"processes)\n"
    )
    print(
        "Best reward at the full budget, mean ± 95% CI; AUC = mean best-so-far over the budget "
        "(9 points from 20% to 100% of the budget).\n"
    )
    print("| pair | scenario | " + " | ".join(f"{s} best | {s} AUC" for s in SOLVERS) + " |")
    print("|---|---|" + "---|---|" * len(SOLVERS))
    wins = {s: 0 for s in SOLVERS if s != "mcts"}
    for pair, scenario_name in itertools.product(pairs, SCENARIOS):
        cells = []
        for solver in SOLVERS:
            values = results[pair, scenario_name, solver]
            final = values[:, -1]
            cells.append(f"{np.mean(final):.1f} ± {ci95(final):.1f} | {np.mean(values):.1f}")  # NaN shows gaps
        print(f"| {' vs '.join(pair)} | {scenario_name} | " + " | ".join(cells) + " |")
        mcts_final = results[pair, scenario_name, "mcts"][:, -1]
        for other in wins:
            wins[other] += bool(
                np.mean(mcts_final) - ci95(mcts_final) > np.mean(results[pair, scenario_name, other][:, -1])
            )
    cases = len(pairs) * len(SCENARIOS)
    print(
        "\nMCTS's lower 95% bound above the other's mean: "
        + ", ".join(f"{other} in {n}/{cases}" for other, n in wins.items())
    )
    draw(results, grid, pairs, plot)


def draw(results, grid, pairs, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        len(SCENARIOS), len(pairs), figsize=(4.2 * len(pairs), 3.4 * len(SCENARIOS)), sharex=True, squeeze=False
    )
    for (row, scenario_name), (col, pair) in itertools.product(enumerate(SCENARIOS), enumerate(pairs)):
        ax = axes[row, col]
        for solver in SOLVERS:
            values = results[pair, scenario_name, solver]
            mean = np.nanmean(values, axis=0)
            half = np.array([ci95(values[:, i]) for i in range(values.shape[1])])
            ax.plot(grid, mean, label=solver, marker="o", markersize=3)
            ax.fill_between(grid, mean - half, mean + half, alpha=0.2)
        ax.set_title(f"{' vs '.join(pair)}, {scenario_name}", fontsize=9)
        ax.xaxis.set_major_formatter(lambda x, _: f"{x / 1000:.0f}k")
        ax.grid(alpha=0.3)
        if row == len(SCENARIOS) - 1:
            ax.set_xlabel("simulator steps")
        if col == 0:
            ax.set_ylabel("best reward found")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"\nplot: {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--part", choices=("speed", "quality", "both"), default="both")
    parser.add_argument("--budget", type=int, default=40_000, help="simulator steps per search (quality)")
    parser.add_argument("--speed-budget", type=int, default=20_000, help="simulator steps per timed search")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--agents", default=",".join(SCRIPTED), help="agents whose every pair is searched (quality)")
    parser.add_argument("--speed-agents", default="lo,med", help="DS-RNN pair timed (speed), or 'untrained'")
    parser.add_argument(
        "--speed-batch",
        type=int,
        default=MCTSConfig().batch,
        help="MCTS batch of the timed default loop and of the policy-only bound (speed)",
    )
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="processes (quality)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="MCTS setting (quality)")
    parser.add_argument("--plot", type=Path, default=Path(__file__).with_name("search_quality.png"))
    args = parser.parse_args()
    global MCTS_CONFIG
    MCTS_CONFIG = MCTSConfig(**parse_settings(MCTSConfig, args.set, "MCTS"))
    print(
        f"machine: {os.cpu_count()} cores; numpy {np.__version__}; load average "
        + " ".join(f"{x:.2f}" for x in os.getloadavg())
    )
    if args.part in ("speed", "both"):
        speed(args.speed_budget, args.speed_agents, args.speed_batch)
    if args.part in ("quality", "both"):
        quality(args.agents.split(","), args.budget, args.seeds, args.plot, args.jobs)
        print("load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
