"""Social force humans as CrowdNav implements them (Helbing-style, A=2, B=1, KI=1), vectorised over worlds."""

from __future__ import annotations

import numpy as np


def social_force_velocities(
    positions: np.ndarray,
    velocities: np.ndarray,
    goals: np.ndarray,
    radii: np.ndarray,
    v_prefs: np.ndarray,
    *,
    A: float = 2.0,
    B: float = 1.0,
    KI: float = 1.0,
    dt: float = 0.25,
    others_pos: np.ndarray | None = None,
    others_radius: np.ndarray | None = None,
) -> np.ndarray:
    """New velocities (W, n, 2): relax towards the goal at v_pref, pushed away by every other agent.

    ``others_pos`` (W, m, 2) and ``others_radius`` (W, m) add agents that push but are not moved (a visible
    robot). The speed is capped at v_pref as in CrowdNav.
    """
    to_goal = goals - positions
    dist_to_goal = np.linalg.norm(to_goal, axis=-1, keepdims=True)
    desired = np.divide(to_goal, dist_to_goal, out=np.zeros_like(to_goal), where=dist_to_goal > 0)
    desired *= v_prefs[..., None]
    goal_term = KI * (desired - velocities)

    pos_all, rad_all = positions, radii
    if others_pos is not None:
        pos_all = np.concatenate([positions, others_pos], axis=1)
        rad_all = np.concatenate([radii, others_radius], axis=1)
    delta = positions[:, :, None, :] - pos_all[:, None, :, :]  # (W, n, n+m, 2): from others to self
    dist = np.linalg.norm(delta, axis=-1)
    n = positions.shape[1]
    self_pair = np.zeros(dist.shape[1:], dtype=bool)
    self_pair[np.arange(n), np.arange(n)] = True
    safe = np.where(self_pair | (dist == 0), 1.0, dist)
    magnitude = A * np.exp((radii[:, :, None] + rad_all[:, None, :] - safe) / B)
    magnitude = np.where(self_pair | (dist == 0), 0.0, magnitude)
    interaction = np.sum(magnitude[..., None] * delta / safe[..., None], axis=2)

    new_velocity = velocities + (goal_term + interaction) * dt
    speed = np.linalg.norm(new_velocity, axis=-1, keepdims=True)
    cap = v_prefs[..., None]
    scale = np.divide(cap, speed, out=np.ones_like(speed), where=speed > cap)
    capped: np.ndarray = new_velocity * scale
    return capped
