"""Agents in a Gymnasium domain: deterministic functions from a batch of observations to a batch of actions.

An agent is named by a Stable-Baselines3 model file (``.zip``, any algorithm), by ``module:attribute`` (a
callable ``observations -> actions``, or an object with such an ``act`` method), or by a name the domain's
adapter ships (``highway-lo``). Agents keep no memory between steps: a snapshot of the world is all a search
needs to branch.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

# SB3 algorithms by the module of their saved policy class; A2C and PPO share "common" (both load as PPO)
SB3_ALGORITHMS = {"sac": "SAC", "td3": "TD3", "ddpg": "DDPG", "dqn": "DQN", "common": "PPO"}


@dataclass
class GymAgent:
    """A named policy: ``act(observations (B, ...)) -> actions (B, ...)``, deterministic. It pickles as its name and
    source, and a worker process loads it from them once (search.core.workers)."""

    name: str
    source: str
    policy: Any

    def __reduce__(self):
        source = Path(self.source)
        stamp = source.stat().st_mtime_ns if source.suffix == ".zip" and source.is_file() else None
        return reloaded, (self.name, self.source, stamp)

    def act(self, observations: np.ndarray) -> np.ndarray:
        if hasattr(self.policy, "predict"):
            with self._observed(observations):
                return np.asarray(self.policy.predict(observations, deterministic=True)[0])
        act = getattr(self.policy, "act", self.policy)
        return np.asarray(act(observations))

    def action_values(self, observations: np.ndarray) -> np.ndarray | None:
        """(B, A) the agent's value of each action (a DQN's Q, or an ``action_values`` method of its own), or None
        for an agent that has none."""
        if _sb3_family(self.policy) == "DQN":
            with _torch_no_grad():
                return self.policy.q_net(self._tensor(observations)).double().numpy()
        own = getattr(self.policy, "action_values", None)
        return None if own is None else np.asarray(own(observations), dtype=np.float64)

    def value(self, observations: np.ndarray) -> np.ndarray | None:
        """(B,) the agent's value of the state: the best action value, a PPO or A2C critic, an actor-critic's Q of
        its own action (SAC, TD3, DDPG: the first critic), a ``value`` method of its own; None where it has none."""
        family = _sb3_family(self.policy)
        if family in ("PPO", "A2C"):
            with _torch_no_grad():
                return self.policy.policy.predict_values(self._tensor(observations)).double().numpy().reshape(-1)
        if family in ("SAC", "TD3", "DDPG"):
            with _torch_no_grad():
                tensor = self._tensor(observations)
                action = self.policy.actor(tensor, deterministic=True) if family == "SAC" else self.policy.actor(tensor)
                return self.policy.critic(tensor, action)[0].double().numpy().reshape(-1)
        values = self.action_values(observations)
        if values is not None:
            return values.max(axis=1)
        own = getattr(self.policy, "value", None)
        return None if own is None else np.asarray(own(observations), dtype=np.float64).reshape(-1)

    def _tensor(self, observations: np.ndarray):
        with self._observed(observations):
            return self.policy.policy.obs_to_tensor(np.asarray(observations))[0]

    @contextmanager
    def _observed(self, observations: np.ndarray) -> Iterator[None]:
        """Where the policy refuses the observations and their shape is not the one it was trained on, an error
        that names the likely cause: the environment ``make()`` builds lacks the wrappers it was trained with."""
        try:
            yield
        except ValueError as error:
            expected = getattr(getattr(self.policy, "observation_space", None), "shape", None)
            found = np.asarray(observations).shape[1:]
            if expected is None or tuple(expected) == found:
                raise
            raise ValueError(
                f"agent {self.name!r} was trained on observations of shape {tuple(expected)}, but the environment "
                f"gives {found}: the adapter's make() likely lacks the observation wrappers the agent was trained "
                f"with (wrap the environment there as in training; docs/gym.md, 'Agents'). {error}"
            ) from None


def _sb3_family(policy) -> str | None:
    """The Stable-Baselines3 algorithm a loaded model is, or None for any other policy."""
    kind = type(policy)
    return kind.__name__ if kind.__module__.startswith("stable_baselines3.") else None


def _torch_no_grad():
    import torch

    return torch.no_grad()


def load_sb3(path: str | Path):
    """Any Stable-Baselines3 model file, its algorithm read from the file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no model file {str(path)!r}")
    try:
        with zipfile.ZipFile(path) as archive:
            module = json.loads(archive.read("data"))["policy_class"]["__module__"]
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError) as error:
        raise ValueError(f"{path}: not a Stable-Baselines3 model file ({error})") from None
    family = module.split(".")[1] if module.startswith("stable_baselines3.") else ""
    if family not in SB3_ALGORITHMS:
        raise ValueError(
            f"{path}: a policy of {module!r}; Foil loads Stable-Baselines3's {sorted(SB3_ALGORITHMS.values())}"
        )
    import stable_baselines3

    return getattr(stable_baselines3, SB3_ALGORITHMS[family]).load(path, device="cpu")


@cache
def reloaded(name: str, source: str, stamp: int | None) -> GymAgent:
    """The agent a pickled `GymAgent` stands for, loaded once per process (and again once its file changed:
    ``stamp``)."""
    if source.endswith(".zip"):
        return GymAgent(name, source, load_sb3(source))
    from search.gym.adapter import import_attribute

    return GymAgent(name, source, import_attribute(source, "agent"))


def load_agent(spec: str, adapter) -> GymAgent:
    """The agent ``spec`` names (see the module docstring)."""
    shipped = adapter.agent_file(spec)
    if shipped is not None:
        return GymAgent(spec, str(shipped), load_sb3(shipped))
    if spec.endswith(".zip"):
        return GymAgent(spec, str(Path(spec).resolve()), load_sb3(spec))
    if ":" in spec:
        from search.gym.adapter import import_attribute

        return GymAgent(spec, spec, import_attribute(spec, "agent"))
    raise ValueError(
        f"unknown agent {spec!r}: give a shipped name ({', '.join(adapter.agent_names()) or 'none'}), "
        "a Stable-Baselines3 .zip file or module:attribute"
    )
