"""The prior over environment actions: what the solvers sample new actions from, and what the optional
plausibility term of the reward scores actions by (adaptive stress testing's log-likelihood)."""

from __future__ import annotations

import math

import numpy as np

PRIOR_KINDS = ("uniform", "gaussian")


class ActionPrior:
    """Independent per-coordinate distribution on [-bound, bound]: uniform (the paper's ``action_space.sample()``)
    or a zero-mean Gaussian of standard deviation ``sigma`` truncated to the bound."""

    def __init__(self, shape: tuple[int, ...], bound: float, kind: str = "uniform", sigma: float = 0.1):
        if kind not in PRIOR_KINDS:
            raise ValueError(f"unknown action prior {kind!r}: use one of {PRIOR_KINDS}")
        if bound <= 0:
            raise ValueError("the environment action bound must be positive to search over it")
        if kind == "gaussian" and sigma <= 0:
            raise ValueError("prior_sigma must be positive for a gaussian prior")
        self.shape, self.bound, self.kind, self.sigma = tuple(shape), float(bound), kind, float(sigma)
        dims = int(np.prod(self.shape))
        if kind == "uniform":
            self._log_norm = -dims * math.log(2 * self.bound)
        else:
            mass = math.erf(self.bound / (self.sigma * math.sqrt(2)))
            self._log_norm = -dims * (math.log(self.sigma * math.sqrt(2 * math.pi)) + math.log(mass))

    def sample(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` actions, shaped (count, *shape)."""
        size = (count, *self.shape)
        if self.kind == "uniform":
            uniform: np.ndarray = rng.uniform(-self.bound, self.bound, size)
            return uniform
        draws = rng.normal(0.0, self.sigma, size)
        outside = np.abs(draws) > self.bound
        while outside.any():  # rejection keeps the truncated Gaussian exact
            draws[outside] = rng.normal(0.0, self.sigma, int(outside.sum()))
            outside = np.abs(draws) > self.bound
        return draws

    def log_prob(self, actions: np.ndarray) -> np.ndarray:
        """Log-density of actions (..., *shape), summed over one action's coordinates."""
        actions = np.asarray(actions, dtype=np.float64)
        axes = tuple(range(actions.ndim - len(self.shape), actions.ndim))
        if self.kind == "uniform":
            return np.full(actions.shape[: actions.ndim - len(self.shape)], self._log_norm)
        log_prob: np.ndarray = self._log_norm - 0.5 * np.sum((actions / self.sigma) ** 2, axis=axes)
        return log_prob
