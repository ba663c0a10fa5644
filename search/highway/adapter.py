"""Highway driving's environment action: the other drivers' intentions, within bounds.

The environment action is an array (PERTURBED, 2) in [-1, 1], one row per other vehicle in the order highway-env
created them (the ``PERTURBED`` nearest ahead of the ego at the start; a row always means the same vehicle, in
every agent's instance). Per vehicle:

- ``[0]`` sets its **target speed** to its own initial target speed plus up to +-``SPEED_RANGE`` m/s (IDM then
  accelerates or brakes towards it, and never above the lane's speed limit);
- ``[1]`` beyond +-``LANE_THRESHOLD`` **commands a lane change** to the right (positive) or left (negative) lane
  where one exists and the vehicle is not changing lanes already; in between, MOBIL decides as usual.

Why: a driver's wish for a speed and a lane is what differs between real drivers, so these are the levers that
make a traffic situation hard for one ego policy and easy for another (cut-ins, slow-downs ahead). The physics is
left alone: IDM still keeps the gap to the vehicle ahead and aborts a lane change into a vehicle changing into the
same lane, so a searched scenario stays one that traffic could produce. The bounds keep speeds in the traffic's
range, and the dead zone makes a commanded lane change a deliberate choice of the search (about one step in ten
under the uniform prior) rather than constant weaving. The ego vehicle is never touched.

Clips (the generic renderer, search/gym/clips.py, through this adapter's hooks): a view follows the ego along the
road and keeps the whole road across it, so it is no taller than the road; the ego wears its car's colour and
all other traffic one grey that no car's colour is near; the caption is the ego's mean speed so far (the visible
score); every simulation step (5 per simulated second) is captured through highway-env's video-recording hook;
where cars that followed one part, the header says so in a driver's words.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from app.visible import Score, Words
from search.gym.adapter import Adapter
from search.highway.env import CONFIG, make_env

PERTURBED = 8
SPEED_RANGE = 5.0  # m/s either side of a vehicle's own target speed
LANE_THRESHOLD = 0.8
AGENTS_DIR = Path(__file__).parent / "agents"
AGENT_PREFIX = "highway-"
WORDS = Words(
    agent="Car",
    clip_title="Clip of two self-driving cars, each on its own copy of the same highway",
    reels_intro="Each car is shown on its own, in moments from its own drives.",
    reel_title="Clip of one self-driving car on its own",
    example_caption="An example: two self-driving cars, each on its own copy of the same highway, in the same traffic.",
    legend_robots=(
        "Self-driving cars: each view follows one, drawn in a colour of its own; its name, such as Car 7, is"
        " listed below the picture."
    ),
    others_marker="",
    legend_others=(
        "Traffic: the other cars, in grey, start alike in both views and want the same speeds and lanes in both"
        " views; they react to the cars around them."
    ),
    legend_trails="",
    legend_crash=(
        "A yellow-and-black burst and **CRASH** mark a car crashing or leaving the road; the list below the"
        " picture then says **CRASHED**."
    ),
    legend_status=(
        "Below the picture each car's line shows its **mean speed** so far and says **drove through** once it has"
        " lasted the whole drive, or **CRASHED**, with the time."
    ),
    success="drove through the traffic without crashing",
    collision="crashed after {seconds} seconds",
    timeout="was still driving when the drive ended",
    running="was still driving when the clip ended",
    close_call="",
    names=(
        "Every self-driving car has a name (such as Car 7) and a colour of its own. A name"
        " never stands for two different cars in this study, and in a ranking round each name is one car in all of"
        " the round's clips. Each new round brings cars with new names."
    ),
    names_in_round="In this round each name and colour is one car in all three clips.",
    new_round=(
        "A new round begins. Its cars have names you have not seen in the earlier rounds: judge them from this"
        " round's clips."
    ),
)
VIEW_METRES = 48.0  # of road along a view: about 34 m ahead of the ego and 14 m behind; a car 34 px long on a phone
EGO_AT = 0.3  # where along the view the ego stays (highway-env's centering_position)
ROAD_MARGIN = 2.0  # metres of verge above and below the road in a view
LANE_WIDTH = 4.0  # highway-env's
TRAFFIC = (200, 200, 200)  # light grey: apart from the road's dark grey, the lane marks' white and every robot


def kmh(speed):
    """A speed in m/s (a number or an array) in km/h, as each view's caption and the visible score read it."""
    return 3.6 * speed


class HighwayAdapter(Adapter):
    """highway-env's highway with the other drivers' intentions as the environment action. Settings: any
    highway-env config keys over Foil's (search.highway.env), and ``discrete = false`` for continuous control."""

    env_action_shape = (PERTURBED, 2)
    dt = 1.0  # one decision per simulated second
    domain, rule, words = "highway", "survival", WORDS  # a car should last the drive: crashing later is better
    # and between two that last alike, the faster is better, as the study's instructions say: each view shows its
    # car's mean speed so far, and a clip is judged by it where the outcomes tie
    score = Score("speed", "km/h", "higher", "mean", digits=0, span=20.0)

    def measure(self, env) -> float:
        """The ego's speed in km/h: never below 72 under the meta-actions, which cannot stop or reverse."""
        return float(kmh(env.unwrapped.vehicle.speed))

    def make(self, render: bool = False):
        settings = dict(self.settings)
        discrete = bool(settings.pop("discrete", True))
        return make_env(discrete=discrete, render=render, config=settings)

    def apply(self, env, action: np.ndarray) -> None:
        road, ego = env.unwrapped.road, env.unwrapped.vehicle
        others = [v for v in road.vehicles if v is not ego][:PERTURBED]
        for vehicle, (speed, lane) in zip(others, np.asarray(action).reshape(-1, 2), strict=False):
            if not hasattr(vehicle, "foil_target_speed"):
                vehicle.foil_target_speed = vehicle.target_speed  # its own wish, before any perturbation
            vehicle.target_speed = vehicle.foil_target_speed + SPEED_RANGE * float(speed)
            if abs(lane) > LANE_THRESHOLD and vehicle.lane_index == vehicle.target_lane_index:
                _, _, index = vehicle.lane_index
                wanted = index + (1 if lane > 0 else -1)
                lanes = road.network.graph[vehicle.lane_index[0]][vehicle.lane_index[1]]
                if 0 <= wanted < len(lanes):
                    vehicle.target_lane_index = (vehicle.lane_index[0], vehicle.lane_index[1], wanted)

    def position(self, env) -> np.ndarray:
        return np.asarray(env.unwrapped.vehicle.position, dtype=np.float64)

    def others(self, env) -> list:
        ego = env.unwrapped.vehicle
        return [np.asarray(v.position, dtype=np.float64).tolist() for v in env.unwrapped.road.vehicles if v is not ego]

    def outcome(self, terminated: bool, truncated: bool, info: dict, reward: float = 0.0, env: Any = None) -> str:
        """A crash, or leaving the road, is a collision; lasting the whole drive is a success (there is no goal
        to reach on a highway: getting through the traffic is it)."""
        if terminated:
            return "collision"
        return "success" if truncated else "timeout"

    def agent_names(self) -> list[str]:
        return sorted(AGENT_PREFIX + path.stem for path in AGENTS_DIR.glob("*.zip"))

    def agent_file(self, name: str):
        if not name.startswith(AGENT_PREFIX):
            return None
        path = AGENTS_DIR / f"{name.removeprefix(AGENT_PREFIX)}.zip"
        if not path.is_file():
            raise ValueError(f"unknown highway agent {name!r}: the shipped ones are {self.agent_names()}")
        return path

    status_words = {
        "success": "drove through",
        "collision": "CRASHED",
        "timeout": "out of time",
        "running": "on its way",
    }

    parting_caption = "Here the {count} cars would drive differently"  # a disagreement clip's moment ({count}: two)

    def view_settings(self, width_px: int) -> dict:
        lanes = int(self.settings.get("lanes_count", CONFIG["lanes_count"]))
        scaling = width_px / VIEW_METRES  # px per metre
        return {
            "screen_width": width_px,
            "screen_height": round((lanes * LANE_WIDTH + 2 * ROAD_MARGIN) * scaling),
            "scaling": scaling,
            "centering_position": [EGO_AT, 0.5],
        }

    def record(self, env, capture) -> int:
        from highway_env.envs.common.graphics import EnvViewer

        road = env.unwrapped
        road.viewer = EnvViewer(road)
        road.viewer.observer_vehicle = _RoadCamera(road)
        road.set_record_video_wrapper(_Capture(capture))
        return int(road.config["simulation_frequency"] // road.config["policy_frequency"])

    def mark_agent(self, env, rgb: tuple[int, int, int]) -> None:
        ego = env.unwrapped.vehicle
        for vehicle in env.unwrapped.road.vehicles:
            vehicle.color = rgb if vehicle is ego else TRAFFIC  # a set colour also overrides highway-env's crash red

    def crash_point(self, env) -> tuple[float, float]:
        viewer = env.unwrapped.viewer
        surface, ego = viewer.sim_surface, env.unwrapped.vehicle
        _, y = surface.pos2pix(*ego.position)
        return EGO_AT, y / surface.get_height()


class _RoadCamera:
    """What highway-env's viewer follows: the ego along the road, the road's middle across it."""

    def __init__(self, env):
        self.env = env
        ys = [lane.position(0.0, 0.0)[1] for lane in env.road.network.lanes_list()]
        self.middle = (min(ys) + max(ys)) / 2

    @property
    def position(self) -> np.ndarray:
        return np.array([self.env.vehicle.position[0], self.middle])


class _Capture:
    """highway-env's video-recording hook: called after each intermediate simulation step."""

    frames_per_sec = 0

    def __init__(self, capture):
        self._capture_frame = capture
