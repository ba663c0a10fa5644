"""The highway world every highway agent is trained and compared in: highway-env's `highway-fast-v0` (3 lanes,
20 other vehicles, one decision per simulated second, 30 s) with highway-env's default ego control, the discrete
meta-actions (change lane left or right, keep going, faster, slower between target speeds of 20, 25 and 30 m/s:
72 to 108 km/h), leaving the road ending the episode. Meta-actions are what highway-env's own examples and the
field's highway agents drive with: a car cannot stop or reverse on the highway, so its reward (paid for speed and
for not crashing) cannot be won by parking. Continuous acceleration and steering remain a setting
(``discrete = false``). One place defines the world, so training, evaluation, search and clips never disagree."""

from __future__ import annotations

import os

ENV_ID = "highway-fast-v0"
DURATION_S = 30  # decisions per episode, one per simulated second
CONFIG = {
    "action": {"type": "DiscreteMetaAction"},
    "offroad_terminal": True,
    "duration": DURATION_S,
    "lanes_count": 3,
    "vehicles_count": 20,
}
# the continuous alternative: steering within +-7.5 degrees, enough to change lanes at highway speeds, while
# untrained (random) steering does not leave the road within a second
CONTINUOUS_CONFIG = CONFIG | {"action": {"type": "ContinuousAction", "steering_range": [-0.13, 0.13]}}


def make_env(discrete: bool = True, render: bool = False, config: dict | None = None):
    """A fresh highway environment. Rendering needs no display: pygame draws on SDL's "offscreen" video driver
    (highway-env switches its drawing off under the "dummy" driver, so that one is replaced)."""
    if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
        os.environ["SDL_VIDEODRIVER"] = "offscreen"
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the environments)

    base = (CONFIG if discrete else CONTINUOUS_CONFIG) | {"offscreen_rendering": True}
    return gym.make(ENV_ID, config=base | (config or {}), render_mode="rgb_array" if render else None)
