"""What a bundle build does differently in the crowd world and in a Gymnasium world (highway driving): evaluating
an agent, identifying its file, resolving a scenario, searching, verifying and rendering. The build itself is the
same for both; the world is inferred from the agents and scenarios (`search.highway.domain`)."""

from __future__ import annotations

from pathlib import Path

from app.formats import load_summary
from search.highway.domain import CROWD, agent_domain, infer_domain, load_gym_scenario


def is_crowd(agents, scenario: str | None = None) -> bool:
    return infer_domain(list(agents), scenario) == CROWD


def agent_file(agent: str) -> Path | None:
    """The file a shipped highway agent is loaded from (None for others: the crowd build finds those)."""
    if agent_domain(agent) == "highway":
        from search.highway.adapter import HighwayAdapter

        return HighwayAdapter().agent_file(agent)
    return None


def evaluate(agent: str, episodes: int, seed: int, world: dict | None = None) -> dict:
    """An agent's `foil eval --json` object; a crowd agent's in the ``world`` settings."""
    if is_crowd([agent]):
        from search.agents.evaluate import evaluate as evaluate_crowd
        from search.agents.policies import load_policy
        from search.sim.world import WorldConfig

        return evaluate_crowd(
            load_policy(agent), episodes=episodes, seed=seed, config=WorldConfig.from_dict(world or {})
        )
    from search.gym.agents import load_agent
    from search.highway.adapter import HighwayAdapter
    from search.highway.evaluate import evaluate as evaluate_highway

    adapter = HighwayAdapter()
    return evaluate_highway(load_agent(agent, adapter), episodes, seed, adapter)


def scenario_dict(agents, name: str, world: dict) -> dict:
    """The scenario a search runs on, complete (its world settings written in); a crowd distribution of starting
    states with the world settings it draws them in."""
    if is_crowd(agents, name):
        from dataclasses import asdict, replace

        from search.sim.scenarios import ScenarioDistribution, load_scenario_or_distribution
        from search.solvers.summary import frozen_scenario

        scenario = load_scenario_or_distribution(name)
        if isinstance(scenario, ScenarioDistribution):
            return asdict(replace(scenario, world=scenario.world | world))
        return frozen_scenario(scenario, world).to_dict()
    scenario = load_gym_scenario(name).to_dict()
    return scenario | {"settings": scenario["settings"] | world}


def search_files(search) -> dict[str, str]:
    """Run a SearchJob in its world."""
    if is_crowd(search.agents, search.scenario):
        from search.solvers.runner import run_search

        return run_search(search)
    from search.gym.summary import run_gym_search

    return run_gym_search(search, load_gym_scenario(search.scenario))


def verify(summary: Path) -> list[str]:
    from search.gym.summary import is_gym_summary, verify_gym
    from search.solvers.summary import verify as verify_crowd

    return verify_gym(summary) if is_gym_summary(load_summary(summary)) else verify_crowd(summary)


def renderer_file(summary: Path) -> Path:
    """The renderer's source, part of a rendered clip's cache key."""
    from search.gym.summary import is_gym_summary

    if is_gym_summary(load_summary(summary)):
        import search.highway.clips as renderer
    else:
        import search.clips.render as renderer
    return Path(renderer.__file__)


def render(summary: Path, out: Path, numbers: list[int], options):
    from search.gym.summary import is_gym_summary

    if is_gym_summary(load_summary(summary)):
        from search.highway.clips import render_highway

        return render_highway(summary, out, numbers, options)
    from search.clips.render import render as render_crowd
    from search.clips.scene import load_scene

    return render_crowd(load_scene(summary), out, numbers, options)
