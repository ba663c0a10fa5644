"""Which world a command works in, inferred from its agents and scenario: the crowd world, highway driving, or
another Gymnasium environment (a scenario file naming an adapter). Mixing them is refused."""

from __future__ import annotations

from pathlib import Path

from app.toml_errors import load_toml
from search.gym.problem import GymScenario
from search.highway.adapter import AGENT_PREFIX
from search.highway.scenarios import SCENARIOS, load_highway_scenario

CROWD, HIGHWAY, GYM = "crowd", "highway", "gym"


def agent_domain(spec: str) -> str | None:
    """highway for the shipped highway agents, gym for a Stable-Baselines3 file, None for module:attribute
    (any world), crowd otherwise."""
    if spec.startswith(AGENT_PREFIX):
        return HIGHWAY
    if spec.endswith(".zip"):
        return GYM
    if ":" in spec and not spec.endswith(".pt"):
        return None
    return CROWD


def _gym_file(name: str) -> dict | None:
    path = Path(name)
    if path.suffix != ".toml" or not path.is_file():
        return None
    data = load_toml(path.read_text(), name)
    return data if "adapter" in data else None


def scenario_domain(name: str) -> str:
    if name in SCENARIOS or name.startswith(AGENT_PREFIX):
        return HIGHWAY
    return GYM if _gym_file(name) is not None else CROWD


def infer_domain(agents: list[str], scenario: str | None = None) -> str:
    """The one world the agents (and the scenario) belong to, or a clear error."""
    found = {spec: agent_domain(spec) for spec in agents}
    if scenario is not None:
        found[f"scenario {scenario}"] = scenario_domain(scenario)
    kinds = {kind for kind in found.values() if kind is not None}
    if kinds == {GYM, HIGHWAY}:  # a Stable-Baselines3 file may well be a highway agent
        kinds = {HIGHWAY}
    if len(kinds) > 1:
        listing = ", ".join(f"{name} ({kind or 'any'})" for name, kind in found.items())
        raise ValueError(
            f"cannot mix worlds: {listing}. Compare crowd agents (lo, med, hi, checkpoints) on crowd "
            "scenarios, and highway agents (highway-lo, highway-med, highway-hi, .zip files) on highway "
            f"scenarios ({', '.join(sorted(SCENARIOS))})"
        )
    return kinds.pop() if kinds else CROWD


def load_gym_scenario(name: str) -> GymScenario:
    """A shipped highway scenario, or a scenario file with ``name``, ``adapter``, ``seed`` and ``[settings]``."""
    data = _gym_file(name)
    if data is None:
        return load_highway_scenario(name)
    return GymScenario.from_dict({"name": Path(name).stem} | data)
