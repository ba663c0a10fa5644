"""Scripted ego drivers for the highway tests (the trained agents are tested through their files)."""

import numpy as np


def cruise(observations):
    """Continuous control: keeps its speed and lane."""
    return np.zeros((len(observations), 2))


def cautious(observations):
    """Continuous control: eases off the accelerator and holds its lane."""
    return np.tile([-0.3, 0.0], (len(observations), 1))


def idle(observations):
    """Meta-action IDLE."""
    return np.ones(len(observations), dtype=np.int64)


def faster(observations):
    """Meta-action FASTER."""
    return np.full(len(observations), 3, dtype=np.int64)


def slower(observations):
    """Meta-action SLOWER: down to the slowest target speed, 72 km/h, and holds its lane."""
    return np.full(len(observations), 4, dtype=np.int64)
