"""Rendering speed: a 25 s clip (the paper's 100-step horizon at real time) drawn and encoded, in frames/s.

Target: the whole clip (frames, H.264 encoding, poster and contact sheet) in under 5 s on the development machine.
Prints a Markdown table row per measurement for BENCHMARKS.md.
"""

from __future__ import annotations

import os
import platform
import resource
import statistics
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from search.clips.render import RenderOptions  # noqa: E402
from search.core.outcomes import OUTCOME_NAMES  # noqa: E402
from search.crowd.agents.policies import load_policy  # noqa: E402
from search.crowd.render import CrowdClipRenderer, render  # noqa: E402
from search.crowd.scene import Scene  # noqa: E402
from search.crowd.sim.coupled import replay  # noqa: E402
from search.crowd.sim.scenarios import load_scenario  # noqa: E402

STEPS = 100  # 25 s at dt = 0.25 s
REPEATS = 3


def horizon_scene(seed: int = 0) -> Scene:
    """Two scripted robots for the full horizon under seeded random environment actions."""
    scenario = load_scenario("paper-bl-tr")
    config = scenario.config()
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-config.env_action_bound, config.env_action_bound, (STEPS, config.human_num, 2))
    trajectory = replay([load_policy("goal"), load_policy("orca")], scenario, actions, stop_when_done=False)
    start = np.tile(np.asarray(scenario.robot_start, dtype=float), (2, 1))
    humans = np.asarray(scenario.human_positions, dtype=float)
    return Scene(
        agents=("goal", "orca"),
        times=np.concatenate([[0.0], trajectory.time]),
        robots=np.concatenate([start[None], trajectory.agent_pos]),
        humans=np.concatenate([humans[None], trajectory.other_pos])[:, None],
        starts=start,
        goals=np.tile(np.asarray(scenario.robot_goal, dtype=float), (2, 1)),
        outcomes=tuple(
            (OUTCOME_NAMES[o], float(t) if np.isfinite(t) else float(trajectory.time[-1]))
            for o, t in zip(trajectory.outcome, trajectory.event_time, strict=True)
        ),
        robot_radius=config.robot_radius,
        human_radius=config.human_radius,
        dt=config.dt,
    )


def cpu_seconds() -> float:
    """User + system CPU time of this process and its finished children (ffmpeg): less sensitive to load than
    wall time on a shared machine."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    scene = horizon_scene()
    options = RenderOptions()
    renderer = CrowdClipRenderer(scene, options=options)
    frames = renderer.frames
    draw_times = []
    for _ in range(REPEATS):
        started = time.perf_counter()
        for frame in frames:
            renderer.draw(frame).tobytes()
        draw_times.append(time.perf_counter() - started)
    full_times, cpu_times = [], []
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(REPEATS):
            before = cpu_seconds()
            result = render(scene, Path(folder) / "clip.mp4", options=options)
            cpu_times.append(cpu_seconds() - before)
            full_times.append(result.render_s)
        size_kb = result.clip.stat().st_size / 1024
    draw, full, cpu = (statistics.median(t) for t in (draw_times, full_times, cpu_times))
    print(
        f"{date.today()}, {os.cpu_count()} cores {platform.machine()}, load average "
        f"{os.getloadavg()[0]:.1f}; median of {REPEATS}"
    )
    print(
        f"clip: {result.seconds:.1f} s of video, {result.frames} frames at {options.fps} fps, "
        f"{result.width}x{result.height}, crf {options.crf}, preset {options.preset}, {size_kb:.0f} KiB"
    )
    print("| stage | time | frames/s |")
    print("|---|---:|---:|")
    print(f"| drawing frames only (Pillow) | {draw:.2f} s | {len(frames) / draw:.0f} |")
    print(
        f"| whole clip: frames + H.264 encoding + poster + contact sheet | {full:.2f} s | {result.frames / full:.0f} |"
    )
    print(f"| whole clip, CPU time (this process and ffmpeg) | {cpu:.2f} s | {result.frames / cpu:.0f} |")


if __name__ == "__main__":
    main()
