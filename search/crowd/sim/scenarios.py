"""Initial states: fixed scenarios from TOML files, and the random training distribution of CrowdNav_DSRNN.

A scenario file looks like::

    name = "paper-bl-tr"
    description = "robot from bottom-left to top-right through 10 humans"

    [robot]
    start = [-5.0, -5.0]
    goal = [5.0, 5.0]
    heading = 0.785          # radians, optional (default pi/2)

    [[humans]]
    position = [-2.0, -1.0]
    goal = [-1.0, -2.0]      # optional: the antipode of the position by default

    [world]                  # optional WorldConfig settings (e.g. time_limit, human_v_pref)
    time_limit = 25.0

The number of humans in the file sets ``human_num``. A file without settings may name its world instead, with
``world = "crowd"`` in place of the ``[world]`` table (the crowd claims files with a ``[robot]`` table or a
``[distribution]`` kind anyway).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from app.toml_errors import load_toml
from search.core.settings import check_keys
from search.crowd.sim.world import HUMAN_RADIUS_RANGE, HUMAN_V_PREF_RANGE, WorldConfig, WorldState, new_state

SHIPPED_DIR = Path(__file__).parent / "scenarios"


@dataclass(frozen=True)
class Scenario:
    name: str
    robot_start: tuple[float, float]
    robot_goal: tuple[float, float]
    human_positions: tuple[tuple[float, float], ...]
    human_goals: tuple[tuple[float, float], ...]
    robot_heading: float = math.pi / 2
    description: str = ""
    world: dict[str, Any] = field(default_factory=dict)

    def config(self, base: WorldConfig | None = None) -> WorldConfig:
        """The world config for this scenario: ``base`` with the file's settings and its crowd size."""
        base = base or WorldConfig()
        values = base.to_dict() | self.world | {"human_num": len(self.human_positions)}
        return WorldConfig.from_dict(values)

    def initial_state(self, config: WorldConfig, n_worlds: int = 1, n_robots: int = 1) -> WorldState:
        """``n_worlds`` identical copies of this initial state with ``n_robots`` robots each."""
        humans = np.array(self.human_positions, dtype=np.float64).reshape(-1, 2)
        goals = np.array(self.human_goals, dtype=np.float64).reshape(-1, 2)
        tile_h = (n_worlds, 1, 1)
        tile_r = (n_worlds, n_robots, 1)
        return new_state(
            np.tile(humans, tile_h),
            np.tile(goals, tile_h),
            np.tile(np.array(self.robot_start, dtype=np.float64), tile_r),
            np.tile(np.array(self.robot_goal, dtype=np.float64), tile_r),
            self.robot_heading,
            config,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "robot": {"start": list(self.robot_start), "goal": list(self.robot_goal), "heading": self.robot_heading},
            "humans": [
                {"position": list(p), "goal": list(g)}
                for p, g in zip(self.human_positions, self.human_goals, strict=True)
            ],
            "world": dict(self.world),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "scenario") -> Scenario:
        def fail(message: str) -> NoReturn:
            raise ValueError(f"{source}: {message}")

        def point(value: object, where: str) -> tuple[float, float]:
            if (
                not isinstance(value, list | tuple)
                or len(value) != 2
                or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
            ):
                fail(f"{where} must be a pair of numbers [x, y], got {value!r}")
            if not all(math.isfinite(v) for v in value):
                fail(f"{where} must be finite, got {value!r}")
            return float(value[0]), float(value[1])

        def keys(table: dict[str, Any], known: set[str], where: str = "") -> None:
            try:
                check_keys(table, known, "key")
            except ValueError as error:
                fail(f"{where}{error}")

        keys(data, {"name", "description", "robot", "humans", "world"})
        robot = data.get("robot")
        if not isinstance(robot, dict):
            fail("missing [robot] table with start and goal")
        for key in ("start", "goal"):
            if key not in robot:
                fail(f"[robot] needs '{key}' = [x, y]")
        keys(robot, {"start", "goal", "heading"}, "[robot]: ")
        heading = robot.get("heading", math.pi / 2)
        if not isinstance(heading, int | float) or not math.isfinite(heading):
            fail(f"[robot] heading must be a number of radians, got {heading!r}")
        humans = data.get("humans", [])
        if not isinstance(humans, list):
            fail("humans must be an array of tables [[humans]]")
        positions, goals = [], []
        for i, human in enumerate(humans):
            if not isinstance(human, dict) or "position" not in human:
                fail(f"human {i} needs 'position' = [x, y]")
            keys(human, {"position", "goal"}, f"human {i}: ")
            p = point(human["position"], f"human {i} position")
            positions.append(p)
            goals.append(point(human["goal"], f"human {i} goal") if "goal" in human else (-p[0], -p[1]))
        world = _settings(data)
        if not isinstance(world, dict):
            fail("[world] must be a table of world settings")
        scenario = cls(
            name=str(data.get("name", source)),
            description=str(data.get("description", "")),
            robot_start=point(robot["start"], "[robot] start"),
            robot_goal=point(robot["goal"], "[robot] goal"),
            robot_heading=float(heading),
            human_positions=tuple(positions),
            human_goals=tuple(goals),
            world=dict(world),
        )
        try:
            scenario.config()
        except (ValueError, TypeError) as error:
            fail(f"[world]: {error}")
        return scenario


DISTRIBUTION_KINDS = ("circle-crossing",)


@dataclass(frozen=True)
class ScenarioDistribution:
    """A task's distribution of starting states, from which concrete scenarios are drawn with a seeded generator.

    A distribution file has a ``[distribution]`` table instead of ``[robot]`` and ``[[humans]]``::

        name = "training"
        description = "the agents' training distribution"

        [distribution]
        kind = "circle-crossing"   # CrowdNav_DSRNN's: robot start and goal uniform in the square of half-width
                                   # circle_radius, humans on that circle heading for their antipodes
        [world]                    # optional WorldConfig settings (human_num, circle_radius, ...)
        human_num = 10
    """

    name: str
    kind: str = "circle-crossing"
    description: str = ""
    world: dict[str, Any] = field(default_factory=dict)

    def config(self, base: WorldConfig | None = None) -> WorldConfig:
        return WorldConfig.from_dict((base or WorldConfig()).to_dict() | self.world)

    def sample(self, rng: np.random.Generator, count: int) -> list[Scenario]:
        """``count`` starting states, each a fixed scenario named after its draw (``training#3``)."""
        state = sample_training_states(self.config(), rng, count)
        return [
            Scenario(
                name=f"{self.name}#{i}",
                description=f"starting state {i} drawn from {self.name}",
                robot_start=tuple(state.robot_pos[i, 0].tolist()),
                robot_goal=tuple(state.robot_goal[i, 0].tolist()),
                human_positions=tuple(map(tuple, state.human_pos[i].tolist())),
                human_goals=tuple(map(tuple, state.human_goal[i].tolist())),
                robot_heading=float(state.robot_theta[i, 0]),
                world=dict(self.world),
            )
            for i in range(count)
        ]

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "scenario distribution") -> ScenarioDistribution:
        try:
            check_keys(data, {"name", "description", "distribution", "world"}, "key")
        except ValueError as error:
            raise ValueError(f"{source}: {error}") from None
        table = data["distribution"]
        kind = table.get("kind") if isinstance(table, dict) else None
        if kind not in DISTRIBUTION_KINDS or set(table) != {"kind"}:
            raise ValueError(f"{source}: [distribution] takes one key, kind, one of {list(DISTRIBUTION_KINDS)}")
        world = _settings(data)
        if not isinstance(world, dict):
            raise ValueError(f"{source}: [world] must be a table of world settings")
        distribution = cls(
            name=str(data.get("name", source)),
            kind=kind,
            description=str(data.get("description", "")),
            world=dict(world),
        )
        try:
            distribution.config()
        except (ValueError, TypeError) as error:
            raise ValueError(f"{source}: [world]: {error}") from None
        return distribution


def _settings(data: dict[str, Any]) -> object:
    """A file's ``[world]`` settings; ``world = "crowd"`` names the file's world instead (search.core.domain)."""
    world = data.get("world", {})
    return {} if world == "crowd" else world


def shipped_scenarios() -> list[str]:
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A fixed scenario: shipped by name (``paper-bl-tr``, ``paper-tl-br``, ``paper-code``) or a TOML file."""
    scenario = load_scenario_or_distribution(name_or_path)
    if isinstance(scenario, ScenarioDistribution):
        raise ValueError(
            f"{str(name_or_path)!r} is a distribution of starting states, not one scenario: the "
            f"representative solver draws from it (--solver representative); other solvers search "
            f"from a fixed scenario such as paper-bl-tr"
        )
    return scenario


def load_scenario_or_distribution(name_or_path: str | Path) -> Scenario | ScenarioDistribution:
    """A shipped scenario or distribution by name (``training`` is the agents' training distribution) or a TOML
    file of either kind."""
    path = Path(name_or_path)
    if not path.suffix and (SHIPPED_DIR / f"{name_or_path}.toml").exists():
        path = SHIPPED_DIR / f"{name_or_path}.toml"
    if not path.exists():
        raise FileNotFoundError(
            f"no scenario {str(name_or_path)!r}: give a TOML file or one of the shipped scenarios {shipped_scenarios()}"
        )
    data = load_toml(path.read_text(), str(path))
    if "distribution" in data:
        return ScenarioDistribution.from_dict(data, source=str(path))
    return Scenario.from_dict(data, source=str(path))


def sample_training_states(config: WorldConfig, rng: np.random.Generator, n_worlds: int) -> WorldState:
    """CrowdNav_DSRNN's training distribution: robot start and goal uniform in the square, at least
    ``min_start_goal_distance`` apart, heading pi/2 (with ``robot_start = "circle"``, CrowdNav's unicycle start:
    on the circle with a uniform heading, humans kept half the circle radius from its start and goal); humans
    circle-crossing towards their antipodes, kept apart from each other and from the robot's start and goal by
    their radii plus the discomfort distance. With ``randomize_attributes`` each human's v_pref and radius are
    drawn first (the placement noise scales with that v_pref); with goal changes each world's random stream is
    seeded from ``rng`` last."""
    n, r = config.human_num, config.circle_radius
    humans = np.zeros((n_worlds, n, 2))
    robots = np.zeros((n_worlds, 1, 2))
    goals = np.zeros((n_worlds, 1, 2))
    headings = np.full(n_worlds, np.pi / 2)
    radii = np.full((n_worlds, n), config.human_radius)
    v_prefs = np.full((n_worlds, n), config.human_v_pref)
    on_circle = config.robot_start == "circle"
    for w in range(n_worlds):
        if on_circle:
            angle = rng.uniform(0, 2 * np.pi)
            start = np.array([r * np.cos(angle), r * np.sin(angle)])
        while True:
            if not on_circle:
                start = rng.uniform(-r, r, 2)
            goal = rng.uniform(-r, r, 2)
            if np.linalg.norm(start - goal) >= config.min_start_goal_distance:
                break
        if on_circle:
            headings[w] = rng.uniform(0, 2 * np.pi)
        robots[w, 0], goals[w, 0] = start, goal
        for i in range(n):
            if config.randomize_attributes:
                v_prefs[w, i], radii[w, i] = rng.uniform(*HUMAN_V_PREF_RANGE), rng.uniform(*HUMAN_RADIUS_RANGE)
            # (position, goal, distance) of every agent placed so far: the human keeps that far from both ends
            min_dist = radii[w, i] + config.discomfort_dist
            placed = [(start, goal, r / 2 if on_circle else min_dist + config.robot_radius)]
            placed += [(humans[w, j], -humans[w, j], min_dist + radii[w, j]) for j in range(i)]
            while True:
                angle = rng.random() * 2 * np.pi
                noise = (rng.random(2) - 0.5) * v_prefs[w, i]
                p = np.array([r * np.cos(angle), r * np.sin(angle)]) + noise
                if all(np.linalg.norm(p - q) >= d and np.linalg.norm(p - g) >= d for q, g, d in placed):
                    break
            humans[w, i] = p
    streams = rng.integers(0, 2**63, n_worlds).astype(np.uint64) if config.random_crowd else None
    return new_state(
        humans, -humans, robots, goals, headings[:, None], config, human_radius=radii, human_v_pref=v_prefs, rng=streams
    )
