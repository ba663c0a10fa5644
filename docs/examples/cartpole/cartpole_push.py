"""CartPole with gusts: Gymnasium's CartPole-v1 as a Foil world (docs/gym.md walks through it).

The environment action is a gust on the pole (it changes the pole's angular velocity a little each step), so a
search looks for the gusts under which two controllers differ most. The agents are two simple controllers, as
functions from a batch of observations (x, x_dot, theta, theta_dot) to a batch of actions (0: push the cart left,
1: push it right); a Stable-Baselines3 model file of CartPole-v1 works the same way.
"""

from __future__ import annotations

import gymnasium
import numpy as np

from search.api import Adapter, Words

GUST = 0.08  # rad/s of angular velocity a full gust adds to the pole in one step


class CartPolePush(Adapter):
    env_action_shape = (1,)  # one number in [-1, 1]: the gust, leftwards to rightwards
    dt = 0.02  # CartPole's own time step (its tau)
    domain = "cartpole"
    rule = "survival"  # the task is to keep the pole up: falling later is better
    words = Words(
        agent="Controller",
        clip_title="Clip of two controllers, each balancing a pole on its own cart in the same gusts",
        example_caption="An example: two controllers, each balancing a pole on a cart, side by side.",
        legend_robots=(
            "Controllers: each view shows one cart with its pole; its name, such as Controller 7, is below it."
        ),
        legend_others="Gusts: both poles get the same gusts of wind, which you cannot see, only their effect.",
        legend_crash="A yellow-and-black burst marks the moment a pole falls; the list below then says **failed**.",
        legend_status="Below the picture each controller's line shows the pole's angle and says **failed** once "
        "its pole has fallen.",
        success="kept the pole up until the end",
        collision="let the pole fall after {seconds} seconds",
        timeout="kept the pole up until the end",
        running="still had the pole up when the clip ended",
    )

    status_words = {"success": "kept it up", "collision": "pole fell", "timeout": "kept it up", "running": "balancing"}

    def make(self, render=False):
        return gymnasium.make("CartPole-v1", render_mode="rgb_array" if render else None)

    def apply(self, env, action):
        state = env.unwrapped.state
        env.unwrapped.state = (state[0], state[1], state[2], state[3] + GUST * float(action[0]))

    def position(self, env):
        x, _, theta, _ = env.unwrapped.state
        return np.array([x, theta], dtype=np.float64)

    def outcome(self, terminated, truncated, info):
        return "collision" if terminated else "success"  # a fallen pole, or the cart off its track

    def crash_point(self, env):
        x = float(env.unwrapped.state[0])
        return (0.5 + x / (2 * env.unwrapped.x_threshold), 0.7)  # at the cart

    def caption(self, env):
        return f"pole {np.degrees(float(env.unwrapped.state[2])):+.0f}°"


def nudge(observations):
    """Pushes the cart the way the pole leans: keeps it up in calm air, not for long in gusts."""
    return (np.asarray(observations)[:, 2] > 0).astype(np.int64)


def steady(observations):
    """Also weighs how fast the pole falls and where the cart is: rides out most gusts."""
    x, x_dot, theta, theta_dot = np.asarray(observations, dtype=np.float64).T
    return (theta + 0.5 * theta_dot + 0.01 * x + 0.1 * x_dot > 0).astype(np.int64)
