"""A world Foil was never written for, as a package of its own installs it: carts on a line, each driving towards
a flag while gusts of wind (the environment action) push them on; a cart going too fast tips over. No Gymnasium
environment: its own scenarios, agents, coupled problem, summaries, clips and words, found through the
``foil.domains`` entry point."""

from __future__ import annotations

import json
import math
import time
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from search.api import (
    COLLISION,
    OUTCOME_NAMES,
    RUNNING,
    SUCCESS,
    SUMMARY_FORMAT,
    TIMEOUT,
    ActionPrior,
    Claim,
    Coupled,
    Domain,
    Episode,
    Problem,
    RenderOptions,
    RenderResult,
    RewardConfig,
    Shipped,
    Words,
    World,
    h264_writer,
    side_paths,
)

AGENTS = {"line-hasty": 1.0, "line-careful": 0.5}  # each cart's own speed, metres per step
SCENARIOS = {"line-short": {"goal": 3.0, "limit": 6}, "line-long": {"goal": 5.0, "limit": 10}}
TIP_SPEED = 1.2  # a cart faster than this in one step tips over
COLOURS = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40))  # by the cart's number
DT = 0.5
WORDS = Words(  # the carts' words where Foil's defaults (in the agent's word) do not fit
    agent="Cart",
    clip_title="Clip of two carts on a line, side by side, in the same wind",
    example_caption="An example: two carts, each on its own line, drive to a flag in the same wind.",
    legend_robots="Carts: each line shows one cart, named beside it, such as Cart 7, in a colour of its own.",
    legend_others="The flag on each line is the cart's goal.",
    legend_crash="A cart that tips over turns black; its line then says **tipped over**.",
    legend_status="Beside each line the cart's status says **at the flag**, **tipped over** or **out of time**.",
    success="reached the flag after {seconds} seconds",
    collision="tipped over after {seconds} seconds",
    timeout="ran out of time before the flag",
    running="was still driving when the clip ended",
    shown="which cart tipped over, which reached the flag and when",
)


@dataclass(frozen=True)
class LineState:
    """A starting state: the flag's distance and the steps a run may take."""

    name: str
    goal: float
    limit: int

    def to_dict(self) -> dict:
        return {"name": self.name, "line": {"goal": self.goal, "limit": self.limit}}


def _scenario_file(name: str) -> dict | None:
    path = Path(name)
    if path.suffix != ".toml" or not path.is_file():
        return None
    data = tomllib.loads(path.read_text())
    return data if isinstance(data.get("line"), dict) else None


def load_state(name: str, settings: Mapping[str, Any]) -> LineState:
    """A shipped scenario or a TOML file with a ``[line]`` table (goal, limit), under ``settings``."""
    found = SCENARIOS.get(name) or (_scenario_file(name) or {}).get("line")
    if found is None:
        raise ValueError(f"no line scenario {name!r}: use one of {sorted(SCENARIOS)} or a .toml file with [line]")
    values = {"goal": 4.0, "limit": 8} | dict(found) | dict(settings)
    return LineState(Path(name).stem, float(values["goal"]), int(values["limit"]))


class LineProblem(Problem):
    """The carts side by side in one batch of rows, one gust per row and step: the protocol every solver steps."""

    action_shape = (1,)

    def __init__(self, agents: Sequence[str], state: LineState, reward: RewardConfig):
        unknown = [a for a in agents if a not in AGENTS]
        if unknown:
            raise ValueError(f"unknown line agent {unknown[0]!r}: use one of {sorted(AGENTS)}")
        self.speeds = np.array([AGENTS[a] for a in agents])
        self.state, self.horizon = state, min(reward.horizon, state.limit)
        self.prior = ActionPrior(self.action_shape, 1.0)
        self.reset(1)

    @property
    def batch(self) -> int:
        return len(self.t)

    def reset(self, batch: int) -> None:
        n = len(self.speeds)
        self.x, self.outcome = np.zeros((batch, n)), np.full((batch, n), RUNNING)
        self.event_step, self.t = np.zeros((batch, n), dtype=int), np.zeros(batch, dtype=int)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        running = self.outcome == RUNNING
        speed = self.speeds[None, :] + 0.5 * np.clip(np.asarray(actions).reshape(-1, 1), -1.0, 1.0)
        self.x = np.where(running, self.x + speed, self.x)
        self.t = self.t + 1
        ending = [
            (speed > TIP_SPEED, COLLISION),
            (self.x >= self.state.goal, SUCCESS),
            (self.t[:, None] >= self.horizon, TIMEOUT),
        ]
        for happened, code in ending:
            now = running & happened & (self.outcome == RUNNING)
            self.outcome[now], self.event_step[now] = code, self.t[np.nonzero(now)[0]]
        done = (self.outcome != RUNNING).all(axis=1)
        differ = self.outcome[:, 0] != self.outcome[:, -1]
        return 0.1 * np.abs(self.x[:, 0] - self.x[:, -1]) + (done & differ), done

    def snapshot(self, index=None) -> tuple:
        rows = slice(None) if index is None else np.asarray(index)
        return self.x[rows].copy(), self.outcome[rows].copy(), self.event_step[rows].copy(), self.t[rows].copy()

    def restore(self, snapshot: tuple) -> None:
        self.x, self.outcome, self.event_step, self.t = (a.copy() for a in snapshot)

    def concat(self, snapshots: list) -> tuple:
        return tuple(np.concatenate(parts) for parts in zip(*snapshots, strict=True))


def summarize(agents: Sequence[str], state: LineState, reward: RewardConfig, actions, solver: dict) -> dict:
    """The summary of ``actions`` replayed at batch size 1: every cart's place after every step."""
    problem = LineProblem(agents, state, reward)
    steps, total = [], 0.0
    for action in np.asarray(actions, dtype=float).reshape(-1, 1):
        gained, done = problem.step(action[None])
        total += float(gained[0])
        steps.append({"t": float(problem.t[0] * DT), "agent_positions": [[float(x), 0.0] for x in problem.x[0]]})
        if done[0]:
            break
    return {
        "format": SUMMARY_FORMAT,
        "agents": [{"name": a, "source": {"kind": "scripted"}} for a in agents],
        "scenario": state.to_dict(),
        "solver": solver,
        "reward_parameters": reward.to_dict(),
        "env_actions": [[float(a)] for a in np.asarray(actions, dtype=float).reshape(-1)[: len(steps)]],
        "steps": steps,
        "outcomes": [
            {"event": OUTCOME_NAMES[code], "time": float(at * DT) if at else None, "min_other_distance": None}
            for code, at in zip(problem.outcome[0], problem.event_step[0], strict=True)
        ],
        "reward": total,
        "reward_terms": {},
    }


def render_clip(summary: Mapping[str, Any], out: Path, numbers: list[int], options: RenderOptions) -> RenderResult:
    """One line per cart, drawn with PIL and encoded by Foil's H.264 writer, with a poster and a contact sheet."""
    started, goal = time.perf_counter(), float(summary["scenario"]["line"]["goal"])
    width, row = max(160, (options.width or 480) // 16 * 16), 48
    places = [[0.0] * len(numbers)] + [[p[0] for p in s["agent_positions"]] for s in summary["steps"]]
    frames = []
    for i, xs in enumerate(places):
        image = Image.new("RGB", (width, row * len(numbers)), (245, 245, 240))
        draw = ImageDraw.Draw(image)
        for k, (x, number) in enumerate(zip(xs, numbers, strict=True)):
            scale, y = (width - 40) / (goal * 1.2), k * row + row // 2
            draw.line((10, y, width - 10, y), fill=(120, 120, 120))
            draw.polygon([(10 + goal * scale, y - 14), (10 + goal * scale, y), (22 + goal * scale, y - 7)], "red")
            ended = summary["outcomes"][k]["event"] == "collision" and i == len(places) - 1
            colour = (0, 0, 0) if ended else COLOURS[(number - 1) % len(COLOURS)]
            draw.rectangle((10 + x * scale - 6, y - 6, 10 + x * scale + 6, y + 6), fill=colour)
        frames.append(image)
    out.parent.mkdir(parents=True, exist_ok=True)
    shown = max(1, round(DT / options.speed * options.fps))  # video frames per step
    writer = h264_writer(out, frames[0].size, options.fps, options)
    for frame in frames:
        for _ in range(shown):
            writer.send(frame.tobytes())
    writer.close()
    poster, sheet = side_paths(out)
    frames[0].save(poster)
    columns = min(3, len(frames))
    grid = Image.new("RGB", (frames[0].width * columns, frames[0].height * math.ceil(len(frames) / columns)))
    for n, frame in enumerate(frames):
        grid.paste(frame, ((n % columns) * frame.width, (n // columns) * frame.height))
    grid.save(sheet)
    count = len(frames) * shown
    return RenderResult(
        out, poster, sheet, count, count / options.fps, width, frames[0].height, time.perf_counter() - started
    )


class LineDomain(Domain):
    """Carts on a line: shipped agents and scenarios named line-..., scenario files with a [line] table; Foil
    gives every other method its default (the evaluation from `play`, the settings' check from ``settings``)."""

    name = "line"
    settings = {"goal": 4.0, "limit": 8}  # the world settings a study or --world may give

    def shipped(self) -> Shipped:
        return Shipped(prefixes=("line-",))

    def takes_scenario(self, name: str) -> Claim | None:
        return Claim.OWN if _scenario_file(name) is not None else None

    def state(self, name: str, world: dict) -> LineState:
        return load_state(name, world)

    def step_seconds(self, name: str, world: dict) -> float:
        return DT

    def play(self, agent: str, episodes: int, seed: int, world: dict, scenario: str | None = None) -> list[Episode]:
        """Each episode in a gust of its own, constant through the run; sooner at the flag is better."""
        state = load_state(scenario or "line-short", world)
        gusts = np.random.default_rng(seed).uniform(-1, 1, episodes)
        problem = LineProblem([agent], state, RewardConfig(horizon=state.limit))
        problem.reset(episodes)
        while not (problem.outcome != RUNNING).all():
            problem.step(gusts)
        outcome, steps = problem.outcome[:, 0], problem.event_step[:, 0]
        rewards = (outcome == SUCCESS) - 0.1 * steps
        return [
            Episode(float(r), float(n * DT), OUTCOME_NAMES[code])
            for r, n, code in zip(rewards, steps, outcome, strict=True)
        ]

    def takes_summary(self, summary: Mapping[str, Any]) -> Claim | None:
        scenario = summary.get("scenario")
        return Claim.OWN if isinstance(scenario, dict) and "line" in scenario else None

    def coupled(self, agents: Sequence[str], state: Any, reward: dict) -> Coupled:
        config = RewardConfig.from_dict(reward)
        return Coupled(
            LineProblem(agents, state, config),
            state.name,
            lambda actions, solver, follow=None, window=None, horizon=None: summarize(
                agents, state, config, actions, solver
            ),
            self.world(),
        )

    def rebuild(self, summary: Mapping[str, Any]) -> dict:
        state = LineState(summary["scenario"]["name"], **summary["scenario"]["line"])
        agents = [a["name"] for a in summary["agents"]]
        config = RewardConfig.from_dict(summary["reward_parameters"])
        return summarize(agents, state, config, summary["env_actions"], summary["solver"])

    def render(self, summary: Path, out: Path, numbers: list[int], options: RenderOptions) -> RenderResult:
        return render_clip(json.loads(Path(summary).read_text()), Path(out), numbers, options)

    def world(self, scenario: str | None = None) -> World:
        return World(domain="line", rule="goal", words=WORDS)
