"""DS-RNN speed: policy inference against a bare run of its layers, and PPO training against the bound its
forward and backward passes set. Both comparisons are measured in the same run, interleaved, so load from
other work affects both sides alike.

    .venv/bin/python benchmarks/bench_agents.py [--seconds 4] [--updates 1] [--rounds 7] [--threads 1]
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from datetime import date

import numpy as np
import torch

from search.crowd.agents.dsrnn import DSRNN, DSRNNPolicy, NetworkConfig, observation_tensors
from search.crowd.agents.train import TrainConfig, train
from search.crowd.sim.observation import observe
from search.crowd.sim.scenarios import sample_training_states
from search.crowd.sim.world import WorldConfig

CROWDNAV_ENV_STEPS = 922  # CrowdNav_DSRNN's logged training speed: 12 processes and a GPU
SHIPPED = NetworkConfig(edge_hidden=64, node_hidden=64, embed=32, attention=32, mlp_hidden=64)


def interleaved(a, b, items_per_call: int, seconds: float) -> tuple[float, float]:
    """Rates of two calls timed one call each in turn, so that load from other work falls on both alike."""
    a(), b()  # warm up
    spent = [0.0, 0.0]
    calls = 0
    while sum(spent) < seconds:
        for i, call in enumerate((a, b)):
            start = time.perf_counter()
            call()
            spent[i] += time.perf_counter() - start
        calls += 1
    return calls * items_per_call / spent[0], calls * items_per_call / spent[1]


def inference(config: NetworkConfig, batch: int, seconds: float) -> tuple[float, float]:
    """(policy agent-steps/s, bare layers agent-steps/s) on real observations of the training world."""
    torch.manual_seed(0)
    net = DSRNN(config)
    policy = DSRNNPolicy(net)
    state = sample_training_states(WorldConfig(), np.random.default_rng(0), batch)
    obs = observe(state, WorldConfig(), robot=0)
    policy_state = policy.initial_state(batch)
    tensors, hidden = observation_tensors(obs, config.max_humans), net.initial_state(batch)

    def bare():
        with torch.no_grad():
            net.act_mean(*tensors, hidden)

    return interleaved(lambda: policy.act(obs, policy_state), bare, batch, seconds)


def network_bound(config: TrainConfig, updates: int) -> float:
    """Env-steps/s if an update were nothing but its network passes: one forward per rollout step (plus the
    bootstrap value), then every epoch's forward and backward over every recurrent minibatch, split across
    ``config.threads`` threads as the trainer splits it."""
    torch.manual_seed(0)
    net = DSRNN(config.network)
    params = [p for name, p in net.named_parameters() if name != "action_logstd"]  # the loss below skips it
    n, t, m = config.num_envs, config.num_steps, config.network.max_humans
    sequence = (torch.randn(t, n, 7), torch.randn(t, n, 2), torch.randn(t, n, m, 2), torch.ones(t, n, m))
    starts = torch.zeros(t, n)
    per_batch = n // config.minibatches
    initial = net.initial_state(n)
    pool = ThreadPoolExecutor(config.threads)

    def passes(part: torch.Tensor) -> None:
        with config.autocast():
            mean, value, _ = net(*(x[:, part] for x in sequence), starts[:, part], [h[part] for h in initial])
        torch.autograd.grad(mean.square().sum() + value.square().sum(), params)

    def update():
        hidden = initial
        with torch.no_grad(), config.autocast():
            for i in range(t + 1):
                _, _, hidden = net(*(x[i % t : i % t + 1] for x in sequence), starts[:1], hidden)
        for _ in range(config.epochs):
            for k in range(config.minibatches):
                parts = torch.arange(k * per_batch, (k + 1) * per_batch).tensor_split(min(config.threads, per_batch))
                list(pool.map(passes, parts))

    update()  # warm-up
    start = time.perf_counter()
    for _ in range(updates):
        update()
    pool.shutdown()
    return updates * config.steps_per_update / (time.perf_counter() - start)


def training_against_bound(config: TrainConfig, updates: int, rounds: int) -> tuple[float, float, float]:
    """(trainer env-steps/s, bound env-steps/s, median of the per-round fractions): each round resumes one
    real run for ``updates`` more updates after one that warms it up (the run is rebuilt from its checkpoint
    on every resume), then times as many bare updates after one warm-up, so both see the same load."""
    trained, bound = [], []
    with tempfile.TemporaryDirectory() as out:
        train(config, out, show_progress=False, stop_after_updates=1)  # warm up (compiles the world's kernels)
        network_bound(config, 1)
        for _ in range(rounds):
            train(config, out, show_progress=False, stop_after_updates=updates + 1)
            with open(os.path.join(out, "progress.csv")) as f:
                rows = list(csv.DictReader(f))[-updates:]
            trained.append(len(rows) / sum(1 / float(r["steps_per_s"]) for r in rows))
            bound.append(network_bound(config, updates))
    fractions = [t / b for t, b in zip(trained, bound, strict=True)]
    return float(np.median(trained)), float(np.median(bound)), float(np.median(fractions))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="seconds per inference measurement")
    parser.add_argument("--updates", type=int, default=1, help="training updates per round")
    parser.add_argument("--rounds", type=int, default=7, help="rounds per training measurement")
    parser.add_argument("--threads", type=int, default=1, help="torch threads for inference")
    parser.add_argument("--skip-inference", action="store_true", help="measure training only")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    load = os.getloadavg()[0]
    print(
        f"{date.today()}, {os.cpu_count()} cores {platform.machine()}, torch {torch.__version__}, "
        f"load average {load:.1f}\n"
    )

    if not args.skip_inference:
        print(f"Inference (torch threads {torch.get_num_threads()}), agent-steps/s:\n")
        print("| network | batch | policy.act | bare layers | fraction |\n|---|---:|---:|---:|---:|")
        for label, config in (("full size", NetworkConfig()), ("shipped (small)", SHIPPED)):
            for batch in (1, 64, 256):
                policy, bare = inference(config, batch, args.seconds)
                print(f"| {label} | {batch} | {policy:,.0f} | {bare:,.0f} | {policy / bare:.2f} |", flush=True)

    print("\nTraining, env-steps/s:\n")
    print(
        "| network | worlds x steps | precision | threads | trainer | network-pass bound | fraction | "
        "trainer / 922 |\n|---|---|---|---:|---:|---:|---:|---:|"
    )
    shipped_run = TrainConfig(num_envs=32, learning_rate=3e-4, network=SHIPPED, precision="float32")
    runs = [
        ("full size", TrainConfig(precision=precision, threads=threads))
        for precision in ("bfloat16", "float32")
        for threads in (1, 2)
    ] + [("shipped (small)", shipped_run)]
    for label, config in runs:
        config = replace(config, save_every=10_000)
        trained, bound, fraction = training_against_bound(config, args.updates, args.rounds)
        print(
            f"| {label} | {config.num_envs} x {config.num_steps} | {config.precision} | {config.threads} | "
            f"{trained:,.0f} | {bound:,.0f} | {fraction:.2f} | {trained / CROWDNAV_ENV_STEPS:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
