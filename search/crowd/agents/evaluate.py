"""`foil eval`: an agent's success, collision and timeout rates and mean episode reward on test episodes.

Test episodes come from the training distribution, drawn from seed sequences that start with ``TEST_STREAM``
while training's start with ``TRAIN_STREAM``, so no test episode is ever a training episode. All episodes run
at once as a batch of worlds; the policy acts deterministically, so the same agent, episode count and seed
always give the same numbers. ``time_limit`` shortens (or lengthens) the episodes, so agents can be judged at the
horizon their clips show (25 s) as well as at the training time limit (50 s).
"""

from __future__ import annotations

import math

import numpy as np

from search.core.outcomes import COLLISION, SUCCESS, TIMEOUT
from search.crowd.sim import world
from search.crowd.sim.observation import Policy, observe
from search.crowd.sim.scenarios import sample_training_states
from search.crowd.sim.world import WorldConfig

TEST_STREAM = 1


def play(
    policy: Policy, episodes: int, seed: int = 0, config: WorldConfig | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, WorldConfig]:
    """``episodes`` test episodes of ``policy`` in ``config``'s world, all at once: each one's return, outcome code
    and the time of its outcome (episode i starts from the seed's i-th drawn state, the same for every agent)."""
    if episodes < 2:
        raise ValueError("evaluation needs at least 2 episodes (for a confidence interval)")
    config = config or WorldConfig()
    state = sample_training_states(config, np.random.default_rng([TEST_STREAM, seed]), episodes)
    policy_state = policy.initial_state(episodes)
    returns = np.zeros(episodes)
    while not state.done.all():
        observation = observe(state, config, robot=0)
        action, policy_state = policy.act(observation, policy_state)
        action = np.where(observation.done[:, None], 0.0, action)
        returns += world.step(state, config, action[:, None, :])[:, 0]
    return returns, state.outcome[:, 0], state.event_time[:, 0], config


def evaluate(
    policy: Policy, episodes: int = 500, seed: int = 0, config: WorldConfig | None = None, per_episode: bool = False
) -> dict:
    """The ``foil eval --json`` object for ``policy`` on ``episodes`` test episodes of ``config``'s world (`play`);
    with ``per_episode``, each episode's reward too (``episode_rewards``, so a bundle can pair them)."""
    returns, outcome, event_time, config = play(policy, episodes, seed, config)
    success = outcome == SUCCESS
    half_width = 1.96 * returns.std(ddof=1) / math.sqrt(episodes)
    mean = float(returns.mean())
    result = {
        "agent": getattr(policy, "name", type(policy).__name__),
        "episodes": episodes,
        "success_rate": float(success.mean()),
        "collision_rate": float((outcome == COLLISION).mean()),
        "timeout_rate": float((outcome == TIMEOUT).mean()),
        "reward_mean": mean,
        "reward_ci95": [float(mean - half_width), float(mean + half_width)],
        "nav_time_mean": float(event_time[success].mean()) if success.any() else None,
        "time_limit": float(config.time_limit),
    }
    return result | ({"episode_rewards": returns.tolist()} if per_episode else {})


def format_result(result: dict) -> str:
    low, high = result["reward_ci95"]
    nav = "n/a" if result["nav_time_mean"] is None else f"{result['nav_time_mean']:.2f} s"
    return "\n".join(
        [
            f"agent            {result['agent']}",
            f"episodes         {result['episodes']}  ({result['time_limit']:g} s each at most)",
            f"success rate     {result['success_rate']:.3f}",
            f"collision rate   {result['collision_rate']:.3f}",
            f"timeout rate     {result['timeout_rate']:.3f}",
            f"mean reward      {result['reward_mean']:.2f}  (95% CI {low:.2f} to {high:.2f})",
            f"mean nav time    {nav}  (successful episodes)",
        ]
    )
