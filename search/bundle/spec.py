"""The study file's `[build]` table, owned by the bundle builder: its models, and its parsing, once, into a BuildSpec
holding what the searches and renders take: each scheme's solver config and RewardConfig, its world settings checked
against WorldConfig, and the RenderOptions. Every problem is refused before any work with its line and field, as
the server refuses the survey tables (`app.toml_errors`); the server leaves `[build]` alone.

The table as the researcher writes it (docs/clips.md)::

    [build]                            seed of the agent-to-robot-number mapping
    [build.eval]                       episodes and seed of each agent's `foil eval` (the ground truth)
    [build.representativeness]         the distribution the fixed scenarios are measured against
    [build.budget]                     steps and clip_seconds every scheme is held to
    [build.render]                     RenderOptions fields
    [build.schemes.NAME]               solver, budget, seed, top_k, select, reels; [.settings], [.reward], [.world]
    [[build.sets]]                     parts, schemes, scenarios; agents (every pair) or pairs
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BeforeValidator, Field, model_validator

from app.survey.study import Names, Pair, Strict, StudyError, Text, distinct, parse_study
from app.toml_errors import Problem, TomlFileError, load_toml, refuse, validated
from search.clips.render import AGENT_STYLES, RenderOptions
from search.core.domain import Domain, domain_for
from search.core.settings import check_keys, check_values, in_steps
from search.solvers.reward import RewardConfig
from search.solvers.solver import Solver, solver_named, solvers

DOCS = "docs/clips.md"


class BuildError(TomlFileError):
    """A `[build]` table that cannot be built; the message names the file, the line and the field."""


Scalar = bool | int | float | str


def _scalars(value: object) -> object:
    """A table of key = value settings as `foil search --set` takes them: scalars, no nested tables."""
    if not isinstance(value, dict) or not all(isinstance(v, Scalar) for v in value.values()):
        raise ValueError("must be a table of key = value settings (numbers, strings, true/false; no nested tables)")
    return value


ScalarTable = Annotated[dict[str, Scalar], BeforeValidator(_scalars)]
Whole = Annotated[int, Field(ge=0, strict=True)]  # strict: a string or true/false is refused, not converted
Positive = Annotated[int, Field(ge=1, strict=True)]


class EvalTable(Strict):
    """The ground truth: each agent's `foil eval` on these test episodes."""

    episodes: Annotated[int, Field(ge=2, strict=True)] = 500
    seed: Whole = 0


class SchemeTable(Strict):
    """How one scheme's clips are found: a solver of `foil search` with its simulator-step budget, seed and top-K,
    and its solver, reward and world settings (checked against their fields when parsed)."""

    solver: Text  # a registered solver's name (search.solvers.solver)
    budget: Positive | None = None  # simulator steps; [build.budget] steps when not given
    seed: Whole
    top_k: Positive = 1
    select: Literal["reward", "contrast"] = "reward"  # which of the top-K becomes the clip (docs/clips.md)
    # a reel solver's: an agent's reels in several questions of one part show other moments, or may "repeat"
    reels: Literal["distinct", "repeat"] = "distinct"
    settings: ScalarTable = {}
    reward: ScalarTable = {}
    world: ScalarTable = {}


class SetTable(Strict):
    """Every pair under every scheme on every scenario, feeding the survey parts named."""

    parts: Annotated[list[Literal["pairwise", "ranking", "example"]], Field(min_length=1), AfterValidator(distinct)]
    schemes: Names
    scenarios: Names
    agents: Annotated[Names, Field(min_length=2)] | None = None  # every pair of these ...
    pairs: Annotated[list[Pair], Field(min_length=1)] | None = None  # ... or these pairs

    @model_validator(mode="after")
    def _agents_or_pairs(self) -> SetTable:
        if (self.agents is None) == (self.pairs is None):
            raise ValueError("give either agents = [...] (every pair of them) or pairs = [[a, b], ...]")
        if self.agents is None and "ranking" in self.parts:
            raise ValueError(
                "a set that feeds a ranking part lists its agents (agents = [...]), so each agent "
                "keeps one agent number in all its clips"
            )
        return self

    def clip_pairs(self) -> tuple[tuple[str, str], ...]:
        if self.agents is not None:
            return tuple(itertools.combinations(self.agents, 2))
        assert self.pairs is not None  # _agents_or_pairs
        return tuple(self.pairs)

    def all_agents(self) -> tuple[str, ...]:
        """Every agent of the set's clips, in the order given."""
        return tuple(dict.fromkeys(a for pair in self.clip_pairs() for a in pair))


class Representativeness(Strict):
    """How `foil bundle` measures the study's fixed scenarios against the task's distribution of starting states
    (`[build.representativeness]`)."""

    distribution: Text | None = None  # default: the world's own (the crowd's "training")
    states: Positive = 64  # starting states drawn from the distribution
    pushes: Positive = 32  # rollouts per state (and per fixed scenario) under uniform pushes
    seed: Whole = 0


class BudgetTable(Strict):
    """What every scheme of the study is held to: simulator steps per search and seconds of clip per question."""

    steps: Positive | None = None
    clip_seconds: Annotated[float, Field(gt=0)] | None = None


class BuildTable(Strict):
    """The `[build]` table as written: which clips `foil bundle` searches for and renders (docs/clips.md)."""

    seed: Whole  # seeds which robot number each agent gets in each clip
    eval: EvalTable = EvalTable()
    representativeness: Representativeness = Representativeness()
    budget: BudgetTable = BudgetTable()
    render: ScalarTable = {}  # RenderOptions fields
    schemes: Annotated[dict[str, SchemeTable], Field(min_length=1)]
    sets: Annotated[list[SetTable], Field(min_length=1)]
    world: Text | None = None  # the world's name, where its agents and scenarios leave it open


@dataclass(frozen=True)
class Scheme:
    """How one scheme's clips are found, as the search takes it: a solver with its config, simulator-step budget,
    seed and top-K, the reward, and the world settings the scheme sets (checked by the world's domain; they go
    over the scenario's and the study's own, so only those given are kept)."""

    name: str
    solver: str
    budget: int
    seed: int
    top_k: int
    select: str  # the clip is the search's best summary by "reward", or its largest visible "contrast"
    solver_config: Any  # an instance of its solver's config_class
    reward: RewardConfig
    world: dict[str, Scalar]
    reels: str = "distinct"  # a reel solver's: "distinct" moments for an agent's reels in one part, or "repeat"


@dataclass(frozen=True)
class ClipSet:
    """Every pair under every scheme on every scenario; a set that feeds a ranking labels each agent once per
    scheme and scenario (a round)."""

    parts: tuple[str, ...]
    schemes: tuple[str, ...]
    scenarios: tuple[str, ...]
    pairs: tuple[tuple[str, str], ...]
    agents: tuple[str, ...]  # every agent of the pairs, in the order given

    @property
    def ranking(self) -> bool:
        return "ranking" in self.parts


@dataclass(frozen=True)
class BuildSpec:
    seed: int  # seeds the agent-to-robot-number mapping of every clip
    eval_episodes: int
    eval_seed: int
    render: RenderOptions
    schemes: dict[str, Scheme]
    sets: tuple[ClipSet, ...]
    representativeness: Representativeness = Representativeness()
    world: str | None = None  # the world the study names (world = "..."), else found by its agents and scenarios
    clip_seconds: float | None = None  # seconds of clip per question every scheme is held to ([build.budget])

    @property
    def agents(self) -> list[str]:
        return list(dict.fromkeys(a for s in self.sets for a in s.agents))


def _set_problems(build: BuildTable) -> list[Problem]:
    """Checks across the tables: every scheme a set names is defined, every clip is listed once, and a ranking
    shows no more robots than there are colours and shapes."""
    problems: list[Problem] = []
    seen: dict[tuple[str, str, frozenset[str]], int] = {}
    for i, clip_set in enumerate(build.sets):
        for j, name in enumerate(clip_set.schemes):
            if name not in build.schemes:
                problems.append(
                    (("build", "sets", i, "schemes", j), f"no scheme {name!r}; defined: {sorted(build.schemes)}")
                )
        for scheme, scenario, pair in itertools.product(clip_set.schemes, clip_set.scenarios, clip_set.clip_pairs()):
            key = (scheme, scenario, frozenset(pair))
            if key in seen:
                problems.append(
                    (
                        ("build", "sets", i),
                        f"the clip of {scheme}, {scenario}, {pair[0]} and {pair[1]} "
                        f"is already in sets[{seen[key]}]; list each clip once, with every part it feeds",
                    )
                )
                break
            seen[key] = i
        if "ranking" in clip_set.parts and len(clip_set.all_agents()) > len(AGENT_STYLES):
            message = (
                f"a ranking shows at most {len(AGENT_STYLES)} agents (one colour and shape each), got "
                f"{len(clip_set.all_agents())}"
            )
            problems.append((("build", "sets", i, "agents"), message))
    return problems


def _study_domain(build: BuildTable, problems: list[Problem]) -> Domain | None:
    """The one world of a study, from its agents and its first scenario (an agent given as module:attribute may
    act in any world) and the world it names, if it does; None, with a problem, where there is none. The bundle
    builder finds it the same way (`search.bundle.study.Study`)."""
    try:
        agents = [a for clip_set in build.sets for a in clip_set.all_agents()]
        return domain_for(agents, build.sets[0].scenarios[0] if build.sets[0].scenarios else None, build.world)
    except ValueError as error:
        problems.append((("build", "sets"), str(error)))
        return None


def _other_world(name: str, found: Domain, study: Domain | None) -> str | None:
    """Why a scenario or distribution of a world other than the study's cannot be built, if it is one."""
    if study is None or found is study:
        return None
    return (
        f"{name!r} is in the {found.name} world, the study's agents and first scenario in the {study.name} world: "
        f"a study compares its agents in one world"
    )


def _scenario_problems(build: BuildTable, study: Domain | None) -> list[Problem]:
    """Each set's scenarios found, in the study's world (``study``), and of the kind its solvers search (a
    distribution for the representative solver, a fixed scenario for the others), and the representativeness
    distribution a distribution."""
    problems: list[Problem] = []
    domain = None
    for i, clip_set in enumerate(build.sets):
        for j, scenario in enumerate(clip_set.scenarios):
            try:
                domain = domain_for(clip_set.all_agents(), scenario, build.world)
                domain.scenario_dict(scenario, {})
                distribution = domain.is_distribution(scenario)
            except (ValueError, FileNotFoundError) as error:
                problems.append((("build", "sets", i, "scenarios", j), str(error)))
                continue
            elsewhere = _other_world(scenario, domain, study)
            if elsewhere is not None:
                problems.append((("build", "sets", i, "scenarios", j), elsewhere))
                continue
            known = solvers()
            names = {build.schemes[name].solver for name in clip_set.schemes if name in build.schemes}
            if any(not known[s].takes(distribution) for s in names if s in known):
                problems.append(
                    (
                        ("build", "sets", i, "scenarios", j),
                        f"{scenario!r} is a {'distribution' if distribution else 'fixed scenario'}: the "
                        f"representative solver draws from a distribution (such as "
                        f"{domain.default_distribution or 'a distribution file'!r}), the other searches from a "
                        f"fixed scenario (the methods that watch agents play take either); give each kind a set of "
                        f"its own",
                    )
                )
    distribution_name = build.representativeness.distribution
    at = ("build", "representativeness", "distribution")
    if distribution_name is not None and domain is not None:
        try:
            found = domain_for([], distribution_name, build.world)
            elsewhere = _other_world(distribution_name, found, study)
            if elsewhere is not None:
                problems.append((at, elsewhere))
            elif not found.is_distribution(distribution_name):
                problems.append(
                    (
                        at,
                        f"{distribution_name!r} is one fixed scenario; give a distribution of starting states such "
                        f"as {domain.default_distribution or 'a distribution file'!r}",
                    )
                )
        except (ValueError, FileNotFoundError) as error:
            problems.append((at, str(error)))
    return problems


def _schemes(build: BuildTable, domain: Domain | None, problems: list[Problem]) -> dict[str, Scheme]:
    """Each scheme with its solver, reward and world settings checked against their fields (the study's world's,
    ``domain``), one problem per bad key (or per bad table, where the values together are refused)."""
    schemes = {}
    for name, table in build.schemes.items():
        at = ("build", "schemes", name)
        found = len(problems)
        try:
            solver: Solver | None = solver_named(table.solver)
        except ValueError as error:
            problems.append(((*at, "solver"), str(error)))
            solver = None
        checked: dict[str, dict[str, Scalar]] = {}
        check: Callable[[dict[str, Scalar]], dict[str, Any]]
        for key, check in (
            (
                "settings",
                lambda values, solver=solver: check_values(solver.config_class, values, "solver") if solver else values,
            ),
            ("reward", lambda values: check_values(RewardConfig, values, "reward")),
            ("world", lambda values: domain.check_world(values, "world") if domain else values),
        ):
            checked[key] = {}
            for setting, value in getattr(table, key).items():
                try:
                    checked[key] |= check({setting: value})
                except ValueError as error:
                    problems.append(((*at, key, setting), str(error)))
        if solver is not None and "reels" in table.model_fields_set and not solver.reels:
            problems.append(((*at, "reels"), f"the {table.solver} solver shows no reels: leave reels out"))
        if len(problems) > found or solver is None:
            continue
        step_seconds = domain.step_seconds(build.sets[0].scenarios[0], {}) if domain is not None else None
        try:
            defaults = {}
            if step_seconds is not None:  # its lengths of time in steps (search.core.settings)
                defaults = in_steps(solver.config_class, {}, step_seconds, defaults=True)
                checked["settings"] = in_steps(solver.config_class, checked["settings"], step_seconds)
                checked["reward"] = in_steps(RewardConfig, checked["reward"], step_seconds)
            solver_config = solver.config_class(**(defaults | checked["settings"]))
            reward = RewardConfig.from_dict(checked["reward"])
        except (TypeError, ValueError) as error:
            problems.append((at, str(error)))
            continue
        budget = table.budget or build.budget.steps
        if budget is None or (build.budget.steps and table.budget not in (None, build.budget.steps)):
            problems.append(
                (
                    (*at, "budget"),
                    "give each scheme a budget (simulator steps per search)"
                    if budget is None
                    else f"[build.budget] holds every scheme to {build.budget.steps} steps: leave budget out",
                )
            )
            continue
        if build.budget.clip_seconds is not None and step_seconds is not None:
            steps = round(build.budget.clip_seconds / step_seconds)
            try:
                solver_config, reward = solver.held_to_clip(solver_config, reward, steps, checked)
            except ValueError as error:
                problems.append((at, str(error)))
                continue
        schemes[name] = Scheme(
            name=name,
            solver=table.solver,
            budget=budget,
            seed=table.seed,
            top_k=table.top_k,
            select=table.select,
            solver_config=solver_config,
            reward=reward,
            world=checked["world"],
            reels=table.reels,
        )
    return schemes


def _render_options(build: BuildTable, problems: list[Problem]) -> RenderOptions:
    """`[build.render]` as RenderOptions; a bad key or value is a problem at its line like the rest of the table."""
    known = RenderOptions.__dataclass_fields__
    for key in build.render:
        try:
            check_keys([key], known, "render setting")
        except ValueError as error:
            problems.append((("build", "render", key), str(error)))
    try:
        return RenderOptions(**{key: value for key, value in build.render.items() if key in known})  # type: ignore[arg-type]
    except (TypeError, ValueError) as error:
        problems.append((("build", "render"), str(error)))
        return RenderOptions()


def parse_build(text: str, source: str = "study file") -> BuildSpec:
    """The `[build]` table of a study file's text as a BuildSpec, or BuildError listing every problem with its file,
    line and field, as the server lists the survey tables' (the survey tables are left to the server)."""
    data = load_toml(text, source, BuildError)
    if "build" not in data:
        raise BuildError(f"{source}: no [build] table: it says which clips to search for and render (see {DOCS})")
    build = validated(
        BuildTable,
        data["build"],
        text,
        source,
        at=("build",),
        checks=_set_problems,
        error=BuildError,
        unknown_key=f"unknown key (check the spelling; see {DOCS} for the keys a study file takes)",
    )
    problems: list[Problem] = []
    render = _render_options(build, problems)
    domain = _study_domain(build, problems)
    schemes = _schemes(build, domain, problems)
    problems += _scenario_problems(build, domain)
    refuse(text, source, problems, BuildError)
    return BuildSpec(
        seed=build.seed,
        eval_episodes=build.eval.episodes,
        eval_seed=build.eval.seed,
        render=render,
        schemes=schemes,
        sets=tuple(
            ClipSet(
                parts=tuple(s.parts),
                schemes=tuple(s.schemes),
                scenarios=tuple(s.scenarios),
                pairs=s.clip_pairs(),
                agents=s.all_agents(),
            )
            for s in build.sets
        ),
        representativeness=build.representativeness,
        world=build.world,
        clip_seconds=build.budget.clip_seconds,
    )


def load_build(path: str | os.PathLike[str]) -> tuple[BuildSpec, str]:
    """The build spec of a study file, and the file's text (copied into the bundle for the server). The whole file
    is checked first, every survey table, as `foil serve` will check it, then the `[build]` table: a misspelt key
    anywhere fails now, not after the searches; the problems of both are listed together."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"no study file {path}") from None
    problems = []
    try:
        parse_study(text, source=str(path))
    except StudyError as error:
        problems.append(str(error))
    try:
        spec = parse_build(text, source=str(path))
    except BuildError as error:
        problems.append(str(error))
    if problems:  # a file that is not TOML at all is refused alike by both: once is enough
        raise BuildError("\n".join(dict.fromkeys(problems)))
    return spec, text
