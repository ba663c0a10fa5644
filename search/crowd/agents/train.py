"""PPO for the DS-RNN robot, in one file that reads top to bottom (after CleanRL's ppo.py).

``num_envs`` worlds step together in one process; finished worlds restart from the training distribution.
Each update collects ``num_steps`` steps per world, computes GAE advantages (normalised over the rollout), then
runs ``epochs`` passes over ``minibatches`` recurrent minibatches (whole world sequences, so the GRUs see the
rollout in order) with the clipped policy loss and, as CrowdNav_DSRNN's PPO, the clipped value loss.
Every ``save_every`` updates a checkpoint holds the network, optimiser, world, hidden states and random
generators, so a run resumes exactly where it stopped; raising ``total_steps`` trains a finished run longer.

Config files are TOML: top-level keys are ``TrainConfig`` fields, ``[network]`` and ``[world]`` tables
override the network sizes and the world settings.
"""

from __future__ import annotations

import csv
import ctypes
import functools
import math
import sys
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from app.toml_errors import load_toml
from search.core.outcomes import SUCCESS
from search.core.settings import check_keys
from search.crowd.agents.dsrnn import DSRNN, NetworkConfig, observation_tensors, read_checkpoint, save_checkpoint
from search.crowd.sim import world
from search.crowd.sim.observation import ROBOT_NODE_SIZE, observe
from search.crowd.sim.scenarios import sample_training_states
from search.crowd.sim.world import WorldConfig, WorldState

TRAIN_STREAM = 0  # first word of every training seed sequence; evaluation uses another, so seeds never overlap
PROGRESS_COLUMNS = (
    "update",
    "env_steps",
    "seconds",
    "steps_per_s",
    "episodes",
    "reward_mean",
    "success_rate",
    "policy_loss",
    "value_loss",
    "entropy",
    "approx_kl",
)


PRECISIONS = ("auto", "float32", "bfloat16")


@functools.cache
def native_bfloat16() -> bool:
    """Whether this CPU multiplies bfloat16 natively (asked once: the answer does not change)."""
    return torch.ops.mkldnn._is_mkldnn_bf16_supported()


@dataclass(frozen=True)
class TrainConfig:
    """Every hyperparameter of a run. Defaults: CrowdNav_DSRNN's PPO on the paper's world (docs/agents.md)."""

    seed: int = 0
    total_steps: int = 10_000_000
    num_envs: int = 12
    num_steps: int = 30
    learning_rate: float = 4e-5
    adam_eps: float = 1e-5
    epochs: int = 5
    minibatches: int = 2
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.2
    value_coef: float = 0.5
    entropy_coef: float = 0.0
    max_grad_norm: float = 0.5
    save_every: int = 200  # updates between checkpoints
    threads: int = 1  # each PPO minibatch is split across this many threads (torch itself runs on one)
    # "bfloat16": the network's matrix products in bfloat16 (sums, hidden states and the loss stay float32);
    # "auto" picks it where the CPU multiplies bfloat16 natively (about 4x float32 here), else "float32"
    precision: str = "auto"
    network: NetworkConfig = field(default_factory=NetworkConfig)
    world: WorldConfig = field(default_factory=WorldConfig)

    def __post_init__(self):
        if self.num_envs % self.minibatches:
            raise ValueError(f"num_envs ({self.num_envs}) must be a multiple of minibatches ({self.minibatches})")
        if (
            min(
                self.total_steps,
                self.num_envs,
                self.num_steps,
                self.epochs,
                self.minibatches,
                self.save_every,
                self.threads,
            )
            < 1
        ):
            raise ValueError(
                "total_steps, num_envs, num_steps, epochs, minibatches, save_every and threads must be positive"
            )
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {list(PRECISIONS)}, got {self.precision!r}")
        if self.network.max_humans < self.world.human_num:
            raise ValueError(
                f"network.max_humans ({self.network.max_humans}) is smaller than the world's "
                f"human_num ({self.world.human_num})"
            )

    @property
    def steps_per_update(self) -> int:
        return self.num_envs * self.num_steps

    def autocast(self) -> torch.autocast:
        """The precision of the network's passes, as a context."""
        low = self.precision == "bfloat16" or (self.precision == "auto" and native_bfloat16())
        return torch.autocast("cpu", dtype=torch.bfloat16, enabled=low)

    @classmethod
    def from_dict(cls, values: dict) -> TrainConfig:
        values = dict(values)
        check_keys(values, (f.name for f in fields(cls)), "training setting")
        network = NetworkConfig.from_dict(values.pop("network", {}))
        world_config = WorldConfig.from_dict(values.pop("world", {}))
        try:
            return cls(network=network, world=world_config, **values)
        except TypeError as error:
            raise ValueError(f"bad training setting: {error}") from None

    def to_dict(self) -> dict:
        return asdict(self) | {"world": self.world.to_dict()}


def load_train_config(path: str | Path) -> TrainConfig:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no training config at {str(path)!r}")
    data = load_toml(path.read_text(), str(path))
    if data.get("world") == "crowd":  # names the config's world (search.core.domain), not its [world] settings
        del data["world"]
    return TrainConfig.from_dict(data)


def _without_length(config: dict | None) -> dict | None:
    return None if config is None else {k: v for k, v in config.items() if k != "total_steps"}


def gaussian_entropy(log_std: Tensor) -> Tensor:
    """Of the diagonal Gaussian policy."""
    return (0.5 + 0.5 * math.log(2 * math.pi) + log_std).sum()


def gaussian_log_prob(actions, mean, log_std):
    return (-0.5 * ((actions - mean) / log_std.exp()) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)


class Rollout(NamedTuple):
    """One update's rollout, (T, N, ...) tensors, with the hidden states it started from."""

    robot: Tensor
    temporal: Tensor
    spatial: Tensor
    mask: Tensor
    start: Tensor
    actions: Tensor
    logprobs: Tensor
    values: Tensor
    advantages: Tensor  # normalised over the rollout
    returns: Tensor
    initial_hidden: list[Tensor]


def minibatch_gradients(
    net: DSRNN,
    params: list[Tensor],
    config: TrainConfig,
    rollout: Rollout,
    samples: int,
    part: Tensor,
    with_entropy: bool,
) -> tuple[list[Tensor], Tensor]:
    """The PPO loss's gradients from the worlds ``part`` of a minibatch of ``samples`` samples (the parts'
    gradients add up to the minibatch's), and the part's sums of policy loss, value loss and approximate KL."""
    r = rollout
    with config.autocast():
        mean, value, _ = net(
            r.robot[:, part],
            r.temporal[:, part],
            r.spatial[:, part],
            r.mask[:, part],
            r.start[:, part],
            [h[part] for h in r.initial_hidden],
        )
    log_ratio = gaussian_log_prob(r.actions[:, part], mean, net.action_logstd) - r.logprobs[:, part]
    ratio = log_ratio.exp()
    adv, returns, old_value = r.advantages[:, part], r.returns[:, part], r.values[:, part]
    # the value loss clipped around the rollout's values, as CrowdNav_DSRNN's PPO does
    clipped_value = old_value + (value - old_value).clamp(-config.clip, config.clip)
    value_loss = torch.max((value - returns).pow(2), (clipped_value - returns).pow(2))
    sums = torch.stack(
        [
            -torch.min(adv * ratio, adv * ratio.clamp(1 - config.clip, 1 + config.clip)).sum(),
            0.5 * value_loss.sum(),
            ((ratio - 1) - log_ratio).detach().sum(),
        ]
    )
    loss = (sums[0] + config.value_coef * sums[1]) / samples
    if with_entropy:
        loss = loss - config.entropy_coef * gaussian_entropy(net.action_logstd)
    return torch.autograd.grad(loss, params), sums.detach()


def checkpoints(out_dir: Path) -> list[Path]:
    """The run's checkpoints, oldest first."""
    return sorted((out_dir / "checkpoints").glob("*.pt"))


class Progress:
    """One status line: a rewritten bar on a terminal, a plain line every ``every`` updates otherwise."""

    def __init__(self, total_updates: int, every: int = 10):
        self.total, self.every, self.tty = total_updates, every, sys.stderr.isatty()

    def show(self, update: int, steps: int, steps_per_s: float, recent_reward: float) -> None:
        if not self.tty and update % self.every and update != self.total:
            return
        done = update / self.total
        bar = "#" * int(30 * done) + "-" * (30 - int(30 * done))
        line = (
            f"[{bar}] {update}/{self.total} updates  {steps:,} steps  {steps_per_s:,.0f} steps/s  "
            f"reward(last 100) {recent_reward:6.2f}"
        )
        print(("\r" + line) if self.tty else line, end="" if self.tty else "\n", file=sys.stderr, flush=True)
        if self.tty and update == self.total:
            print(file=sys.stderr)


def keep_freed_memory() -> None:
    """Have glibc keep freed memory for reuse. By default it hands blocks over 128 KiB back to the system on
    free, so every minibatch page-faults its tens of megabytes of activations and gradients in again, which
    cost about a third of a full-size update on this machine. Elsewhere than glibc this does nothing."""
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return
    libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD: serve blocks up to 32 MiB (glibc's maximum) from the heap
    libc.mallopt(-1, 1 << 30)  # M_TRIM_THRESHOLD: keep up to 1 GiB of freed heap


def train(
    config: TrainConfig, out_dir: str | Path, show_progress: bool = True, stop_after_updates: int | None = None
) -> Path:
    """Run (or resume) PPO into ``out_dir``; returns the last checkpoint. ``stop_after_updates`` ends this
    sitting early (the run stays resumable)."""
    out = Path(out_dir)
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    keep_freed_memory()
    wc, nc = config.world, config.network
    n_envs, n_steps = config.num_envs, config.num_steps
    total_updates = max(1, config.total_steps // config.steps_per_update)

    torch.manual_seed(config.seed)
    rng = np.random.default_rng([TRAIN_STREAM, config.seed])
    net = DSRNN(nc)
    params = list(net.parameters())
    optimizer = torch.optim.Adam(params, lr=config.learning_rate, eps=config.adam_eps, fused=True)
    pool = ThreadPoolExecutor(config.threads) if config.threads > 1 else None
    parallel_map = pool.map if pool else map
    state = sample_training_states(wc, rng, n_envs)
    hidden = net.initial_state(n_envs)
    episode_start = torch.ones(n_envs)
    episode_return = np.zeros(n_envs)
    recent_returns: deque[float] = deque(maxlen=100)
    recent_success: deque[float] = deque(maxlen=100)
    episodes, first_update, seconds = 0, 1, 0.0

    saved = checkpoints(out)
    if saved:  # resume: everything that the next update depends on comes back
        data = read_checkpoint(saved[-1])
        if _without_length(data.get("train_config")) != _without_length(config.to_dict()):
            raise ValueError(
                f"{out} holds a run with a different config (only total_steps may change, to train "
                "a run longer); use a new --out directory"
            )
        net.load_state_dict(data["model"])
        optimizer.load_state_dict(data["optimizer"])
        run = data["run"]
        state = WorldState(**run["world_state"])
        hidden, episode_start = run["hidden"], run["episode_start"]
        episode_return = run["episode_return"]
        recent_returns.extend(run["recent_returns"])
        recent_success.extend(run["recent_success"])
        episodes, seconds = run["episodes"], run["seconds"]
        rng.bit_generator.state = run["numpy_rng"]
        torch.set_rng_state(run["torch_rng"])
        first_update = data["update"] + 1
    progress_path = out / "progress.csv"
    rows = []
    if progress_path.exists() and first_update > 1:  # keep the rows up to the checkpoint we resumed from
        with progress_path.open() as f:
            rows = [r for r in csv.DictReader(f) if int(r["update"]) < first_update]
    with progress_path.open("w", newline="") as f:
        writer = csv.DictWriter(f, PROGRESS_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    progress = Progress(total_updates)
    last = saved[-1] if saved else None

    # rollout buffers, (T, N, ...)
    m = nc.max_humans
    b_robot = torch.zeros(n_steps, n_envs, ROBOT_NODE_SIZE)
    b_temporal = torch.zeros(n_steps, n_envs, 2)
    b_spatial = torch.zeros(n_steps, n_envs, m, 2)
    b_mask = torch.zeros(n_steps, n_envs, m)
    b_start = torch.zeros(n_steps, n_envs)
    b_actions = torch.zeros(n_steps, n_envs, 2)
    b_logprobs = torch.zeros(n_steps, n_envs)
    b_rewards = torch.zeros(n_steps, n_envs)
    b_dones = torch.zeros(n_steps, n_envs)
    b_values = torch.zeros(n_steps, n_envs)

    for update in range(first_update, total_updates + 1):
        started = time.perf_counter()
        initial_hidden = [h.clone() for h in hidden]
        obs = observation_tensors(observe(state, wc, robot=0), m)
        with config.autocast():  # one region for the whole rollout, so weights are cast once
            for t in range(n_steps):
                b_robot[t], b_temporal[t], b_spatial[t], b_mask[t] = obs
                b_start[t] = episode_start
                with torch.no_grad():
                    mean, value, hidden = net(*(o[None] for o in obs), episode_start[None], hidden)
                    mean, value = mean[0], value[0]
                    action = mean + net.action_logstd.exp() * torch.randn_like(mean)
                    b_logprobs[t] = gaussian_log_prob(action, mean, net.action_logstd)
                b_actions[t], b_values[t] = action, value

                reward = world.step(state, wc, action.numpy().astype(np.float64)[:, None, :])[:, 0]
                done = state.done[:, 0].copy()
                episode_return += reward
                b_rewards[t], b_dones[t] = (
                    torch.from_numpy(reward.astype(np.float32)),
                    torch.from_numpy(done.astype(np.float32)),
                )
                finished = np.flatnonzero(done)
                if finished.size:
                    for i in finished:
                        recent_returns.append(float(episode_return[i]))
                        recent_success.append(float(state.outcome[i, 0] == SUCCESS))
                    episodes += finished.size
                    episode_return[finished] = 0.0
                    state.assign(finished, sample_training_states(wc, rng, finished.size))
                episode_start = torch.from_numpy(done.astype(np.float32))
                obs = observation_tensors(observe(state, wc, robot=0), m)

            with torch.no_grad():
                next_value = net(*(o[None] for o in obs), episode_start[None], hidden)[1][0]

        # GAE: a finished step does not bootstrap from the next (fresh) episode
        advantages = torch.zeros(n_steps, n_envs)
        last_gae = torch.zeros(n_envs)
        for t in reversed(range(n_steps)):
            following = next_value if t == n_steps - 1 else b_values[t + 1]
            not_done = 1.0 - b_dones[t]
            delta = b_rewards[t] + config.gamma * following * not_done - b_values[t]
            last_gae = delta + config.gamma * config.gae_lambda * not_done * last_gae
            advantages[t] = last_gae
        returns = advantages + b_values
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-5)  # as CrowdNav_DSRNN's PPO

        # PPO epochs over recurrent minibatches of whole world sequences; each minibatch is split into one part
        # per thread, whose gradients add up (in a fixed order) to the minibatch's
        per_batch = n_envs // config.minibatches
        rollout = Rollout(
            b_robot,
            b_temporal,
            b_spatial,
            b_mask,
            b_start,
            b_actions,
            b_logprobs,
            b_values,
            advantages,
            returns,
            initial_hidden,
        )
        stats = []
        for _ in range(config.epochs):
            order = torch.randperm(n_envs)
            for k in range(config.minibatches):
                parts = order[k * per_batch : (k + 1) * per_batch].tensor_split(min(config.threads, per_batch))
                gradients = functools.partial(minibatch_gradients, net, params, config, rollout, n_steps * per_batch)
                results = list(parallel_map(gradients, parts, [i == 0 for i in range(len(parts))]))
                for param, *grads in zip(params, *(r[0] for r in results), strict=True):
                    param.grad = functools.reduce(torch.add, grads)
                policy_loss, value_loss, approx_kl = (sum(r[1] for r in results) / (n_steps * per_batch)).tolist()
                stats.append([policy_loss, value_loss, gaussian_entropy(net.action_logstd).item(), approx_kl])
                torch.nn.utils.clip_grad_norm_(params, config.max_grad_norm)
                optimizer.step()

        seconds += time.perf_counter() - started
        steps = update * config.steps_per_update
        steps_per_s = config.steps_per_update / (time.perf_counter() - started)
        reward_mean = float(np.mean(recent_returns)) if recent_returns else float("nan")
        policy_loss, value_loss, entropy, approx_kl = np.mean(stats, axis=0)
        row = dict(
            zip(
                PROGRESS_COLUMNS,
                (
                    update,
                    steps,
                    round(seconds, 2),
                    round(steps_per_s, 1),
                    episodes,
                    round(reward_mean, 4),
                    round(float(np.mean(recent_success)) if recent_success else float("nan"), 4),
                    round(policy_loss, 6),
                    round(value_loss, 6),
                    round(entropy, 6),
                    round(approx_kl, 6),
                ),
                strict=True,
            )
        )
        with progress_path.open("a", newline="") as f:
            csv.DictWriter(f, PROGRESS_COLUMNS).writerow(row)
        if show_progress:
            progress.show(update, steps, steps_per_s, reward_mean)

        stopping = stop_after_updates is not None and update - first_update + 1 >= stop_after_updates
        if update % config.save_every == 0 or update == total_updates or stopping:
            last = out / "checkpoints" / f"{update:06d}.pt"
            run = {
                "world_state": state.fields(),
                "hidden": hidden,
                "episode_start": episode_start,
                "episode_return": episode_return,
                "recent_returns": list(recent_returns),
                "recent_success": list(recent_success),
                "episodes": episodes,
                "seconds": seconds,
                "numpy_rng": rng.bit_generator.state,
                "torch_rng": torch.get_rng_state(),
            }
            save_checkpoint(
                last,
                net,
                update=update,
                env_steps=steps,
                train_config=config.to_dict(),
                optimizer=optimizer.state_dict(),
                run=run,
            )
        if stopping:
            break
    if pool:
        pool.shutdown()
    return last
