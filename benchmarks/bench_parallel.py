"""Batched agents and worker processes: `foil eval` on the highway kernel against a plain highway-env loop, and a
world without a kernel (`foil eval`, the representative search) in one process against every core.

    .venv/bin/python benchmarks/bench_parallel.py                 # all three tables (about 20 minutes on 2 cores)
    .venv/bin/python benchmarks/bench_parallel.py --only kernel   # or: python-world, mcts

Kernel: `search.highway.evaluate.evaluate` (64 episodes stepped at once, the agent deciding for all of them in one
call) against the loop a researcher writes with highway-env alone (one environment, the agent's ``predict`` on one
observation at a time), over the same test episodes; then how many of the batched decisions differ from the agent's
decision on the observation alone.

Python world: highway-env behind an adapter of its own (`PlainHighway`, which the Gymnasium world takes, not the
highway world, so nothing runs on the kernel: a researcher's world), with `foil eval` and the representative solver
at ``--jobs 1`` and at one per core; the results must be byte-identical.

MCTS: a search with its batch rows in one process and over every core (search.gym.rows), in highway-env behind
`PlainHighway` (a slow world) and in CartPole with gusts (a fast one, where the rows' trips to the workers cost more
than their steps); the summaries must be byte-identical.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from search.core.workers import cores, jobs  # noqa: E402
from search.gym.agents import GymAgent, load_agent  # noqa: E402
from search.gym.evaluate import EPISODE_BASE  # noqa: E402
from search.highway.adapter import HighwayAdapter  # noqa: E402


class PlainHighway(HighwayAdapter):
    """highway-env as any researcher's Gymnasium world: the Gymnasium world takes it, stepping highway-env."""


class Counted:
    """An agent's policy that decides on a batch and counts the decisions that differ from its own on each
    observation alone."""

    def __init__(self, agent: GymAgent):
        self.agent, self.decisions, self.differ = agent, 0, 0

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        batched = self.agent.act(observations)
        alone = np.concatenate([self.agent.act(o[None]) for o in observations])
        self.decisions += len(observations)
        self.differ += int((batched != alone).sum())
        return batched


def plain_loop(agent: GymAgent, episodes: int, seed: int) -> tuple[float, float, int]:
    """highway-env alone: wall seconds, success rate (lasting the drive), steps."""
    adapter = HighwayAdapter()
    env, successes, steps = adapter.make(), 0, 0
    started = time.perf_counter()
    for i in range(episodes):
        observation, _ = env.reset(seed=EPISODE_BASE * (seed + 1) + i)
        done = False
        while not done:
            observation, _, terminated, truncated, _ = env.step(agent.act(observation[None])[0])
            steps, done = steps + 1, terminated or truncated
        successes += bool(truncated and not terminated)
    return time.perf_counter() - started, successes / episodes, steps


def kernel_table(agent_name: str, episodes: int) -> None:
    from search.highway.evaluate import evaluate

    agent = load_agent(agent_name, HighwayAdapter())
    evaluate(agent, 2)  # compiled (numba caches it on disk)
    started = time.perf_counter()
    result = evaluate(agent, episodes)
    ours = time.perf_counter() - started
    reference, rate, steps = plain_loop(agent, episodes, 0)
    counted = Counted(agent)
    evaluate(GymAgent(agent.name, agent.source, counted), episodes)
    print(f"\n`foil eval {agent_name}`, {episodes} test episodes (seed 0), load average {os.getloadavg()[0]:.1f}:\n")
    print("| run | wall s | success rate | vs highway-env |")
    print("|---|---:|---:|---:|")
    print(f"| highway-env, one observation at a time ({steps} steps) | {reference:.1f} | {rate:.3f} | 1 |")
    print(f"| kernel, batch 64, batched agent | {ours:.1f} | {result['success_rate']:.3f} | {reference / ours:.1f}x |")
    print(f"\nbatched decisions that differ from the lone ones: {counted.differ} of {counted.decisions}")


def python_world_table(agent: str, episodes: int, budget: int, states: int, pushes: int) -> None:
    from search.core.domain import domain_for
    from search.solvers.representative import RepresentativeConfig
    from search.solvers.runner import SearchJob, run_search

    workers = cores()
    folder = Path(tempfile.mkdtemp())
    scenario, starts = folder / "plain.toml", folder / "plain-starts.toml"
    adapter = "bench_parallel:PlainHighway"
    scenario.write_text(f'adapter = "{adapter}"\nseed = 11\n')
    starts.write_text(f'adapter = "{adapter}"\n[distribution]\nseeds = [100000, 200000]\n')
    domain = domain_for([agent], str(scenario))
    assert domain.name == "gym", domain.name
    rows = []
    evaluations = {}
    for count in (1, workers):
        with jobs(count):
            started = time.perf_counter()
            evaluations[count] = json.dumps(domain.evaluate(agent, episodes, 0, {}, str(scenario)))
            rows.append(
                ("eval", count, time.perf_counter() - started, episodes * json.loads(evaluations[count])["length_mean"])
            )
    searches = {}
    job = SearchJob(
        agents=(agent, str(Path(agent).with_name("lo.zip"))),
        scenario=str(starts),
        solver="representative",
        budget=budget,
        seed=0,
        top_k=3,
        solver_config=RepresentativeConfig(states=states, pushes=pushes, batch_states=states),
    )
    for count in (1, workers):
        with jobs(count):
            files = run_search(job)
        run = json.loads(files["run.json"])
        searches[count] = [files[name] for name in sorted(files) if name.startswith("summary-")], run["vote"]
        rows.append(("representative", count, run["search_wall_s"], run["sim_steps"]))
    print(
        f"\nA Python world (highway-env behind `PlainHighway`), {agent}: `foil eval` of {episodes} episodes and a "
        f"representative search ({states} states x {pushes + 1} rollouts, budget {budget}); load average "
        f"{os.getloadavg()[0]:.1f}:\n"
    )
    print("| work | processes | wall s | world steps/s | speed-up |")
    print("|---|---:|---:|---:|---:|")
    for work, count, seconds, steps in rows:
        one = next(s for w, c, s, _ in rows if w == work and c == 1)
        print(f"| {work} | {count} | {seconds:.1f} | {steps / seconds:,.0f} | {one / seconds:.2f}x |")
    print(
        f"\nbyte-identical in 1 and {workers} processes: eval {evaluations[1] == evaluations[workers]}, "
        f"representative {searches[1] == searches[workers]}"
    )


def mcts_table(world: str, agents: tuple[str, ...], scenario: str, budget: int) -> None:
    """An MCTS search with its batch rows in one process, over every core where they move when it pays (the
    default), and moved at once however quick the world (search.gym.rows): wall time, world steps/s, the
    speed-up, and whether the summaries are byte-identical."""
    from search.gym import rows as spread
    from search.solvers.mcts import MCTSConfig
    from search.solvers.runner import SearchJob, run_search

    job = SearchJob(agents=agents, scenario=scenario, solver="mcts", budget=budget, seed=0, top_k=3)
    runs, found = [], []
    rule = spread.SPREAD_AFTER_S, spread.SPREAD_STEP_S
    for count, how, (after, step) in ((1, "", rule), (cores(), "when it pays", rule), (cores(), "at once", (0, 0))):
        spread.SPREAD_AFTER_S, spread.SPREAD_STEP_S = after, step
        with jobs(count):
            files = run_search(job)
        run = json.loads(files["run.json"])
        found.append([files[name] for name in sorted(files) if name.startswith("summary-")])
        runs.append((f"{count} {how}".strip(), run["search_wall_s"], run["sim_steps"]))
    spread.SPREAD_AFTER_S, spread.SPREAD_STEP_S = rule
    print(
        f"\nMCTS in {world} (budget {budget}, {MCTSConfig().batch} rows in flight), its rows in one process and "
        f"over {cores()}; load average {os.getloadavg()[0]:.1f}:\n"
    )
    print("| processes (rows moved) | wall s | world steps/s | speed-up |")
    print("|---|---:|---:|---:|")
    for name, seconds, steps in runs:
        print(f"| {name} | {seconds:.1f} | {steps / seconds:,.0f} | {runs[0][1] / seconds:.2f}x |")
    print(f"\nbyte-identical summaries in every run: {all(f == found[0] for f in found)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("kernel", "python-world", "mcts"))
    parser.add_argument("--agent", default="highway-hi")
    parser.add_argument("--kernel-episodes", type=int, default=200)
    parser.add_argument("--episodes", type=int, default=64, help="eval episodes in the Python world (default 64)")
    parser.add_argument("--budget", type=int, default=8000, help="representative search budget (default 8000)")
    parser.add_argument("--states", type=int, default=8)
    parser.add_argument("--pushes", type=int, default=7)
    parser.add_argument("--mcts-budget", type=int, default=2000, help="MCTS budget in highway-env (CartPole: 20x)")
    args = parser.parse_args()
    os.chdir(ROOT / "benchmarks")  # the adapter's module imports from the working directory, as a researcher's does
    print(f"{time.strftime('%Y-%m-%d')}, {cores()} cores, load average {os.getloadavg()[0]:.1f}")
    if args.only in (None, "kernel"):
        kernel_table(args.agent, args.kernel_episodes)
    if args.only in (None, "python-world"):
        python_world_table(
            str(ROOT / "search/highway/agents/hi.zip"), args.episodes, args.budget, args.states, args.pushes
        )
    if args.only in (None, "mcts"):
        folder = Path(tempfile.mkdtemp())
        (folder / "plain.toml").write_text('adapter = "bench_parallel:PlainHighway"\nseed = 11\n')
        highway = tuple(str(ROOT / f"search/highway/agents/{name}.zip") for name in ("hi", "lo"))
        mcts_table("highway-env behind `PlainHighway`", highway, str(folder / "plain.toml"), args.mcts_budget)
        os.chdir(ROOT / "docs/examples/cartpole")
        cartpole = ("cartpole_push:nudge", "cartpole_push:steady")
        mcts_table("CartPole with gusts (docs/examples/cartpole)", cartpole, "cartpole.toml", 20 * args.mcts_budget)


if __name__ == "__main__":
    main()
