"""One small Stable-Baselines3 PPO run on CartPole-v1 whose snapshots the close-pairs benchmark compares.

    python benchmarks/close_pairs/train_cartpole.py --out runs/close-pairs/cartpole [--steps 60000] [--every 2048]

A fixed seed, one environment, one torch thread: the same snapshots (``OUT/ppo_STEPS_steps.zip``) on every run
on the same machine and libraries.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--steps", type=int, default=60_000)
    parser.add_argument("--every", type=int, default=2048, help="environment steps between snapshots")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    import gymnasium
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CheckpointCallback

    torch.set_num_threads(1)
    model = PPO("MlpPolicy", gymnasium.make("CartPole-v1"), seed=args.seed, device="cpu", verbose=0)
    model.learn(args.steps, callback=CheckpointCallback(args.every, str(args.out), name_prefix="ppo"))


if __name__ == "__main__":
    main()
