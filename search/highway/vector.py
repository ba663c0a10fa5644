"""The highway kernel as a Stable-Baselines3 vector environment, for training the highway agents on it.

``KernelVecEnv(n, settings)`` steps the same episodes as ``DummyVecEnv`` over n highway-env environments does:
``seed(s)`` gives environment i the seed s + i at the next reset, an ended episode is reset at once without a
seed (highway-env's generator goes on), its last observation is in ``info["terminal_observation"]``, and
``info["episode"]`` carries the return and length as SB3's Monitor wrapper reports them.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn

from search.highway.adapter import HighwayAdapter
from search.highway.kernel import HighwayKernel, spec_of


class KernelVecEnv(VecEnv):
    """n highway environments in one kernel (settings the kernel does not cover are refused: train those with
    SB3's own vector environments over highway-env)."""

    def __init__(self, n: int, settings: dict | None = None):
        env = HighwayAdapter(settings).make()
        spec = spec_of(env)
        if isinstance(spec, str):
            raise ValueError(f"the highway kernel does not cover {spec}")
        super().__init__(n, env.observation_space, env.action_space)
        env.close()
        self.kernel = HighwayKernel(spec, n)
        self.actions = np.zeros(0)
        self.returns, self.lengths = np.zeros(n), np.zeros(n, np.int64)
        self.started = time.perf_counter()

    def reset(self) -> VecEnvObs:
        observations = self.kernel.reset(self._seeds)
        self._reset_seeds()
        self._reset_options()
        self.returns[:], self.lengths[:] = 0, 0
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self.actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        observations, rewards, terminated, truncated = self.kernel.step(self.actions)
        self.returns += rewards
        self.lengths += 1
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [
            {"TimeLimit.truncated": bool(truncated[i] and not terminated[i])} for i in range(self.num_envs)
        ]
        ended = np.flatnonzero(dones)
        for i in ended:
            infos[i]["terminal_observation"] = observations[i].copy()
            elapsed = round(time.perf_counter() - self.started, 6)
            infos[i]["episode"] = {"r": round(float(self.returns[i]), 6), "l": int(self.lengths[i]), "t": elapsed}
        if len(ended):
            observations[ended] = self.kernel.reset([None] * len(ended), ended)
            self.returns[ended], self.lengths[ended] = 0, 0
        return observations, rewards.astype(np.float32), dones, infos  # float32, as DummyVecEnv's reward buffer

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        raise AttributeError(f"the highway kernel's environments have no attribute {attr_name!r}")

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"the highway kernel's environments have no attribute {attr_name!r}")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        raise AttributeError(f"the highway kernel's environments have no method {method_name!r}")

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(list(self._get_indices(indices)))
