"""The highway world every highway agent is trained and compared in: highway-env's `highway-fast-v0` (3 lanes,
20 other vehicles, one decision per simulated second, 30 s) with continuous ego control (acceleration,
steering), leaving the road ending the episode. One place defines it, so training, evaluation, search and clips
never disagree about the world."""

from __future__ import annotations

import os

ENV_ID = "highway-fast-v0"
DURATION_S = 30  # decisions per episode, one per simulated second
CONFIG = {
    # steering within +-7.5 degrees: enough to change lanes at highway speeds, while untrained (random) steering
    # does not leave the road within a second
    "action": {"type": "ContinuousAction", "steering_range": [-0.13, 0.13]},
    "offroad_terminal": True,
    "duration": DURATION_S,
    "lanes_count": 3,
    "vehicles_count": 20,
}
META_CONFIG = CONFIG | {"action": {"type": "DiscreteMetaAction"}}  # the discrete alternative (5 meta-actions)


def make_env(discrete: bool = False, render: bool = False, config: dict | None = None):
    """A fresh highway environment. Rendering needs no display: pygame draws on SDL's "offscreen" video driver
    (highway-env switches its drawing off under the "dummy" driver, so that one is replaced)."""
    if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
        os.environ["SDL_VIDEODRIVER"] = "offscreen"
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the environments)

    base = (META_CONFIG if discrete else CONFIG) | {"offscreen_rendering": True}
    return gym.make(ENV_ID, config=base | (config or {}), render_mode="rgb_array" if render else None)
