"""The shipped highway scenarios: initial traffic states from a seed (highway-env places the traffic with the
environment's generator), in three kinds of traffic."""

from __future__ import annotations

from search.gym.problem import GymScenario

ADAPTER = "search.highway.adapter:HighwayAdapter"
SCENARIOS = {
    "highway-dense": GymScenario(
        "highway-dense",
        ADAPTER,
        11,
        {"vehicles_density": 1.5},
        "Three lanes of dense traffic: gaps are short, cut-ins come close.",
    ),
    "highway-light": GymScenario(
        "highway-light",
        ADAPTER,
        12,
        {"vehicles_density": 0.8},
        "Three lanes of light traffic: room to overtake, speed matters.",
    ),
    "highway-four-lanes": GymScenario(
        "highway-four-lanes",
        ADAPTER,
        13,
        {"lanes_count": 4},
        "Four lanes of ordinary traffic: more lane changes around the ego.",
    ),
}


def load_highway_scenario(name: str) -> GymScenario:
    if name not in SCENARIOS:
        raise ValueError(f"unknown highway scenario {name!r}: use one of {sorted(SCENARIOS)}")
    return SCENARIOS[name]
