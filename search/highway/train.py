"""Training the highway agents with Stable-Baselines3 DQN on highway-env's meta-actions, as highway-env's own
example trains its highway agent (``scripts/sb3_highway_dqn.py``: the same network and settings) and as the field's
highway agents are built.

    foil train --config search/highway/train.toml --out runs/highway

The config file names its world with ``world = "highway"`` (or ``domain = "highway"``); its other keys are
``TrainConfig`` fields. The run directory gets ``config.json``, SB3's ``progress.csv`` and a checkpoint every
``save_every`` environment steps (``checkpoints/model_<steps>_steps.zip``), from which ``foil release`` picks
highway-lo, highway-med and highway-hi. The untrained network is not saved: it picks one fixed meta-action
whatever it sees, which is no driver at all.
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
    """DQN's settings for the highway run: highway-env's example's (SB3's defaults where not named)."""

    seed: int = 1
    total_steps: int = 60_000
    hidden: int = 256  # two hidden layers of this width
    learning_rate: float = 5e-4
    buffer_size: int = 15_000
    learning_starts: int = 200
    batch_size: int = 32
    gamma: float = 0.8  # highway-env's reward is dense; a short horizon learns faster
    target_update_interval: int = 50
    exploration_fraction: float = 0.7
    save_every: int = 1000  # environment steps between checkpoints

    def __post_init__(self):
        sizes = (self.total_steps, self.hidden, self.buffer_size, self.batch_size, self.target_update_interval)
        if min(*sizes, self.save_every) < 1 or self.learning_starts < 0:
            raise ValueError("highway training settings must be positive")
        if not 0 < self.exploration_fraction <= 1:
            raise ValueError(f"exploration_fraction must be in (0, 1], not {self.exploration_fraction}")


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
    """Run DQN and save checkpoints; returns the last one."""
    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.callbacks import CheckpointCallback
    from stable_baselines3.common.logger import configure

    from search.highway.vector import KernelVecEnv

    torch.set_num_threads(1)
    out = Path(out)
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps({"domain": "highway", **asdict(config)}, indent=1) + "\n")
    envs = KernelVecEnv(1)  # the episodes highway-env would play, faster
    envs.seed(config.seed)
    model = DQN(
        "MlpPolicy",
        envs,
        policy_kwargs={"net_arch": [config.hidden, config.hidden]},
        learning_rate=config.learning_rate,
        buffer_size=config.buffer_size,
        learning_starts=config.learning_starts,
        batch_size=config.batch_size,
        gamma=config.gamma,
        train_freq=1,
        gradient_steps=1,
        target_update_interval=config.target_update_interval,
        exploration_fraction=config.exploration_fraction,
        seed=config.seed,
        device="cpu",
        verbose=0,
    )
    model.set_logger(configure(str(out), ["csv"]))
    started = time.perf_counter()
    model.learn(config.total_steps, callback=CheckpointCallback(config.save_every, str(out / "checkpoints"), "model"))
    last = out / "checkpoints" / f"model_{model.num_timesteps}_steps.zip"
    model.save(last)
    (out / "training_seconds.txt").write_text(f"{time.perf_counter() - started:.1f}\n")
    return last
