"""Training the highway agents with Stable-Baselines3 PPO (continuous acceleration and steering).

    foil train --config search/highway/train.toml --out runs/highway

The config file names its world with ``world = "highway"`` (or ``domain = "highway"``); its other keys are
``TrainConfig`` fields. The run directory gets ``config.json``, SB3's ``progress.csv`` and a checkpoint every
``save_every`` environment steps (``checkpoints/model_<steps>_steps.zip``, the initial policy included), from which
``foil release`` picks highway-lo, highway-med and highway-hi.
"""

from __future__ import annotations

import json
import time
import tomllib
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from app.toml_errors import load_toml
from search.core.settings import check_keys


@dataclass(frozen=True)
class TrainConfig:
    """PPO's settings for the highway run (SB3's defaults where not named; a small MLP policy)."""

    seed: int = 0
    total_steps: int = 40_960
    num_envs: int = 8
    num_steps: int = 128  # per environment and update
    batch_size: int = 64
    epochs: int = 10
    learning_rate: float = 5e-4
    gamma: float = 0.8  # highway-env's reward is dense; a short horizon learns faster
    log_std_init: float = -1.0  # initial action noise 0.37: wide random steering leaves the road within seconds
    save_every: int = 4096  # environment steps between checkpoints

    def __post_init__(self):
        if min(self.total_steps, self.num_envs, self.num_steps, self.batch_size, self.save_every) < 1:
            raise ValueError("highway training settings must be positive")


def is_highway_config(path: str | Path) -> bool:
    """Whether a training config file is a highway one (``domain = "highway"``)."""
    try:
        return tomllib.loads(Path(path).read_text()).get("domain") == "highway"
    except (OSError, tomllib.TOMLDecodeError):
        return False  # the crowd trainer reports what is wrong with the file


def load_config(path: str | Path) -> TrainConfig:
    data = load_toml(Path(path).read_text(), str(path))
    data.pop("domain", None)
    data.pop("world", None)  # world = "highway" names the config's world as domain = "highway" does
    try:
        check_keys(data, (f.name for f in fields(TrainConfig)), "highway training setting")
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    return TrainConfig(**data)


def train(config: TrainConfig, out: str | Path) -> Path:
    """Run PPO and save checkpoints; returns the last one."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CheckpointCallback
    from stable_baselines3.common.logger import configure

    from search.highway.vector import KernelVecEnv

    torch.set_num_threads(1)
    out = Path(out)
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps({"domain": "highway", **asdict(config)}, indent=1) + "\n")
    envs = KernelVecEnv(config.num_envs)  # the episodes make_vec_env over highway-env would step, faster
    envs.seed(config.seed)
    model = PPO(
        "MlpPolicy",
        envs,
        learning_rate=config.learning_rate,
        n_steps=config.num_steps,
        batch_size=config.batch_size,
        n_epochs=config.epochs,
        gamma=config.gamma,
        seed=config.seed,
        policy_kwargs={"log_std_init": config.log_std_init},
        device="cpu",
        verbose=0,
    )
    model.set_logger(configure(str(out), ["csv"]))
    model.save(out / "checkpoints" / "model_0_steps")
    every = max(1, config.save_every // config.num_envs)
    started = time.perf_counter()
    model.learn(config.total_steps, callback=CheckpointCallback(every, str(out / "checkpoints"), "model"))
    last = out / "checkpoints" / f"model_{model.num_timesteps}_steps.zip"
    model.save(last)
    (out / "training_seconds.txt").write_text(f"{time.perf_counter() - started:.1f}\n")
    return last
