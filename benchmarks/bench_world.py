"""Crowd stepping speed: Foil's batched world against CrowdNav's way of stepping a crowd.

CrowdNav gives every human its own RVO2 simulator and calls one doStep per human per step, one world at a
time; the reference below does exactly that with the RVO2 library (pyrvo), measured in the same run.

    .venv/bin/python benchmarks/bench_world.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from datetime import date

import numpy as np
import pyrvo

from search.crowd.sim import world
from search.crowd.sim.scenarios import sample_training_states
from search.crowd.sim.world import WorldConfig


def rate(step_once, worlds_per_call: int, seconds: float) -> float:
    step_once()  # compile / warm up
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step_once()
        calls += 1
    return calls * worlds_per_call / (time.perf_counter() - start)


def crowdnav_reference(config: WorldConfig, seconds: float) -> float:
    """One world: every human owns an RVO2 simulator of the whole crowd and runs one doStep per step."""
    state = sample_training_states(config, np.random.default_rng(0), 1)
    n = config.human_num
    radius = config.human_radius + 0.01 + config.safety_space
    sims = []
    for _ in range(n):
        sim = pyrvo.RVOSimulator(
            config.dt, config.neighbor_dist, config.max_neighbors, config.time_horizon, config.time_horizon, radius, 1.0
        )
        for _ in range(n):
            sim.add_agent(
                (0.0, 0.0),
                config.neighbor_dist,
                config.max_neighbors,
                config.time_horizon,
                config.time_horizon,
                radius,
                1.0,
                (0.0, 0.0),
            )
        sims.append(sim)
    pos, vel, goal = state.human_pos[0].copy(), state.human_vel[0].copy(), state.human_goal[0]

    def step_once():
        nonlocal pos, vel
        new_vel = np.empty_like(vel)
        for i, sim in enumerate(sims):
            order = [i] + [j for j in range(n) if j != i]  # the ego human is agent 0 of its own simulator
            for k, j in enumerate(order):
                sim.set_agent_position(k, (float(pos[j, 0]), float(pos[j, 1])))
                sim.set_agent_velocity(k, (float(vel[j, 0]), float(vel[j, 1])))
                sim.set_agent_pref_velocity(k, (0.0, 0.0))
            sim.set_agent_max_speed(0, config.human_v_pref)
            to_goal = goal[i] - pos[i]
            length = np.linalg.norm(to_goal)
            pref = to_goal / length if length > 1 else to_goal
            sim.set_agent_pref_velocity(0, (float(pref[0]), float(pref[1])))
            sim.do_step()
            v = sim.get_agent_velocity(0)
            new_vel[i] = (v.x, v.y)
        vel = new_vel
        pos = pos + vel * config.dt

    return rate(step_once, 1, seconds)


def foil_rate(config: WorldConfig, n_worlds: int, seconds: float) -> float:
    state = sample_training_states(config, np.random.default_rng(0), n_worlds)
    robot_action = np.zeros((n_worlds, 1, 2))
    return rate(lambda: world.step(state, config, robot_action), n_worlds, seconds)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="time per measurement")
    args = parser.parse_args()
    config = WorldConfig()
    reference = crowdnav_reference(config, args.seconds)
    print(
        f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, {date.today()}, "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    print("| setting | world-steps/s | vs CrowdNav reference |")
    print("|---|---:|---:|")
    print(f"| CrowdNav reference (RVO2 doStep per human, 1 world) | {reference:,.0f} | 1.0 |")
    for n_worlds in (1, 64, 256, 1024):
        r = foil_rate(config, n_worlds, args.seconds)
        print(f"| Foil world.step, B = {n_worlds} | {r:,.0f} | {r / reference:.1f} |")


if __name__ == "__main__":
    main()
