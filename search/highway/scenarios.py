"""The shipped highway scenarios: initial traffic states from a seed (highway-env places the traffic with the
environment's generator), in three kinds of traffic; and the distribution of starting states they come from."""

from __future__ import annotations

from search.gym.problem import GymScenario
from search.gym.scenarios import GymDistribution

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


# The agents' training traffic (highway-env's own placement, default settings), one starting state per seed: the
# distribution the representative solver draws from and a study's fixed scenarios are checked against.
DISTRIBUTIONS = {
    "highway-traffic": GymDistribution(
        "highway-traffic",
        ADAPTER,
        (100_000, 200_000),
        description="Highway traffic as the shipped agents were trained in it: three lanes, 20 other vehicles.",
    ),
}


def load_highway_scenario(name: str) -> GymScenario | GymDistribution:
    """A shipped scenario or distribution by name."""
    shipped: dict[str, GymScenario | GymDistribution] = {**SCENARIOS, **DISTRIBUTIONS}
    if name not in shipped:
        raise ValueError(f"unknown highway scenario {name!r}: use one of {sorted(shipped)}")
    return shipped[name]
