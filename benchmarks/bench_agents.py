"""DS-RNN speed: policy inference against a bare run of its layers, and PPO training against the bound its
forward and backward passes set. Both comparisons are measured in the same run, alternating, so load from
other work affects both sides alike.

    .venv/bin/python benchmarks/bench_agents.py [--seconds 2] [--updates 6]
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import tempfile
import time
from dataclasses import replace
from datetime import date

import numpy as np
import torch

from search.dsrnn import DSRNN, DSRNNPolicy, NetworkConfig, observation_tensors
from search.policies import observe
from search.scenarios import sample_training_states
from search.train import TrainConfig, train
from search.world import WorldConfig

SHIPPED = NetworkConfig(edge_hidden=64, node_hidden=64, embed=32, attention=32, mlp_hidden=64)


def rate(run_once, items_per_call: int, seconds: float) -> float:
    run_once()  # warm up
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        run_once()
        calls += 1
    return calls * items_per_call / (time.perf_counter() - start)


def best_of_alternating(a, b, rounds: int = 5) -> tuple[float, float]:
    """Best rate of each side over alternating rounds (the least disturbed measurement of each)."""
    results = [(a(), b()) for _ in range(rounds)]
    return max(r[0] for r in results), max(r[1] for r in results)


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

    return best_of_alternating(lambda: rate(lambda: policy.act(obs, policy_state), batch, seconds),
                               lambda: rate(bare, batch, seconds))


def network_bound(config: TrainConfig, repeats: int) -> float:
    """Env-steps/s if an update were nothing but its network passes: one forward per rollout step (plus the
    bootstrap value), then every epoch's forward and backward over every recurrent minibatch."""
    torch.manual_seed(0)
    net = DSRNN(config.network)
    n, t, m = config.num_envs, config.num_steps, config.network.max_humans
    sequence = (torch.randn(t, n, 7), torch.randn(t, n, 2), torch.randn(t, n, m, 2), torch.ones(t, n, m))
    starts = torch.zeros(t, n)
    per_batch = n // config.minibatches

    def update():
        hidden = net.initial_state(n)
        with torch.no_grad():
            for i in range(t + 1):
                _, _, hidden = net(*(x[i % t: i % t + 1] for x in sequence), starts[:1], hidden)
        for _ in range(config.epochs):
            for k in range(config.minibatches):
                idx = slice(k * per_batch, (k + 1) * per_batch)
                mean, value, _ = net(*(x[:, idx] for x in sequence), starts[:, idx],
                                     [h[idx] for h in net.initial_state(n)])
                net.zero_grad()
                (mean.square().mean() + value.square().mean()).backward()

    update()
    start = time.perf_counter()
    for _ in range(repeats):
        update()
    return repeats * config.steps_per_update / (time.perf_counter() - start)


def training(config: TrainConfig, updates: int) -> float:
    """The trainer's env-steps/s over ``updates`` updates after a warm-up update."""
    with tempfile.TemporaryDirectory() as out:
        train(config, out, show_progress=False, stop_after_updates=updates + 1)
        with open(os.path.join(out, "progress.csv")) as f:
            rows = list(csv.DictReader(f))[1:]
    return config.steps_per_update * len(rows) / sum(config.steps_per_update / float(r["steps_per_s"])
                                                     for r in rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="seconds per inference measurement")
    parser.add_argument("--updates", type=int, default=6, help="training updates per measurement")
    args = parser.parse_args()
    torch.set_num_threads(min(2, os.cpu_count() or 1))
    load = os.getloadavg()[0]
    print(f"{date.today()}, {os.cpu_count()} cores {platform.machine()}, torch {torch.__version__}, "
          f"load average {load:.1f}\n")

    print(f"Inference (torch threads {torch.get_num_threads()}), agent-steps/s:\n")
    print("| network | batch | policy.act | bare layers | fraction |\n|---|---:|---:|---:|---:|")
    for label, config in (("full size", NetworkConfig()), ("shipped (small)", SHIPPED)):
        for batch in (1, 64, 256):
            policy, bare = inference(config, batch, args.seconds)
            print(f"| {label} | {batch} | {policy:,.0f} | {bare:,.0f} | {policy / bare:.2f} |", flush=True)

    print("\nTraining, env-steps/s:\n")
    print("| network | worlds x steps | threads | trainer | network-pass bound | fraction |\n"
          "|---|---|---:|---:|---:|---:|")
    shipped_run = TrainConfig(num_envs=32, learning_rate=3e-4, network=SHIPPED)
    for label, config in (("full size", TrainConfig()), ("full size", TrainConfig(threads=2)),
                          ("shipped (small)", shipped_run)):
        config = replace(config, save_every=10_000)
        torch.set_num_threads(config.threads)
        trained, bound = best_of_alternating(lambda c=config: training(c, args.updates),
                                             lambda c=config: network_bound(c, args.updates), rounds=2)
        print(f"| {label} | {config.num_envs} x {config.num_steps} | {config.threads} | {trained:,.0f} | "
              f"{bound:,.0f} | {trained / bound:.2f} |", flush=True)


if __name__ == "__main__":
    main()
