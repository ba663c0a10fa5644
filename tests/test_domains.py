"""Every world is reached through its domain (`search.core.domain`): the solvers, the bundle builder and the
command line import no world's own modules, so a world can be added without editing them; and a world is found by
the names it ships, a file's ``world`` key and what each world claims, never by the order worlds were installed."""

import ast
import re
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path

import pytest

import search
import search.core.domain
from search.cli import main
from search.core.domain import (
    ENTRY_POINTS,
    Domain,
    domain_for,
    domain_named,
    domain_of_summary,
    domains,
    trainer_for,
)
from search.core.world import Trainer
from search.solvers.solver import OwnSummaries, solvers
from tests.support.imports import imported, package_modules

ROOT = Path(search.__file__).parent
WORLDS = ("search.crowd", "search.gym", "search.highway")
CALLERS = ("search.solvers.", "search.bundle.", "search.cli.")
TRACK = 'adapter = "tests.gym.test_gym_clips:TrackAdapter"\nseed = 3\n'
HIGHWAY = 'adapter = "search.highway.adapter:HighwayAdapter"\nseed = 3\n'
ROBOT = "[robot]\nstart = [-5.0, -5.0]\ngoal = [5.0, 5.0]\n"


def test_the_domain_interface_is_the_only_way_into_a_world():
    found = [
        f"{module} imports {name}"
        for module, path in package_modules(ROOT).items()
        if f"{module}.".startswith(CALLERS)
        for name in imported(path, "search")
        if name.startswith(WORLDS)
    ]
    assert found == []


def test_foils_own_worlds_are_installed_as_entry_points_and_found_by_what_they_ship():
    assert {"crowd", "gym", "highway"} <= {d.name for d in domains()}
    assert domain_named("highway") is domain_for(["highway-lo"]) and domain_for(["lo"]) is domain_named("crowd")
    assert domain_for(["goal", "orca"], "paper-bl-tr").name == domain_for([], "training").name == "crowd"
    assert domain_for(["highway-lo"], "highway-traffic").name == "highway"
    with pytest.raises(ValueError, match="no installed world takes nobody"):
        domain_for(["nobody"])  # a plain name no world ships is not taken for the crowd's


def test_foil_worlds_lists_each_worlds_shipped_scenarios_and_distributions(capsys):
    assert main(["worlds"]) == 0
    listed = dict(re.findall(r"^(\w+): .*\n((?:  .*\n)*)", capsys.readouterr().out, re.MULTILINE))
    assert listed["crowd"] == (
        "  shipped scenarios: paper-bl-tr, paper-code, paper-tl-br\n"
        "  shipped distributions of starting states: training\n"
    )
    assert listed["highway"] == (
        "  shipped scenarios: highway-dense, highway-four-lanes, highway-light\n"
        "  shipped distributions of starting states: highway-traffic\n"
    )
    assert listed["gym"] == ""  # it takes scenario files and ships none


def test_the_world_key_picks_the_world_and_an_ambiguous_file_names_the_key(tmp_path):
    both = tmp_path / "both.toml"
    both.write_text(HIGHWAY + ROBOT)  # a crowd scenario's [robot] and the highway's adapter: either world reads it
    with pytest.raises(ValueError, match='add world = "crowd" or world = "highway" to the scenario file'):
        domain_for([], str(both))
    both.write_text('world = "gym"\n' + HIGHWAY)
    assert domain_for([], str(both)).name == "gym"  # the highway's environment as any Gymnasium environment
    both.write_text(TRACK + ROBOT)  # the Gymnasium world takes any adapter's file, as others may: the crowd owns it
    assert domain_for([], str(both)).name == "crowd"
    robot = tmp_path / "robot.toml"
    robot.write_text('world = "crowd"\n' + ROBOT)
    assert domain_for(["goal", "orca"], str(robot)).name == "crowd"
    assert domain_named("crowd").state(str(robot), {}).robot_start == (-5.0, -5.0)  # the key is no world setting
    both.write_text('world = "gym"\n' + TRACK + ROBOT)
    with pytest.raises(ValueError, match=r"cannot mix worlds: hi \(crowd\), scenario .*both.toml \(gym\)"):
        domain_for(["hi"], str(both))


def test_a_study_names_its_world():
    assert domain_for(["pkg.mod:policy", "pkg.mod:other"], None, "gym").name == "gym"  # not the crowd's reading
    with pytest.raises(ValueError, match=r"cannot mix worlds: hi \(crowd\), the study's world \(gym\)"):
        domain_for(["hi"], None, "gym")


def test_a_summary_goes_to_the_world_that_owns_it():
    highway = {"scenario": {"domain": "gym", "adapter": "search.highway.adapter:HighwayAdapter"}}
    assert domain_of_summary(highway).name == "highway"
    assert domain_of_summary({"scenario": {"domain": "gym", "adapter": "a.b:C"}}).name == "gym"
    assert domain_of_summary({"scenario": {"robot": {}}}).name == "crowd"


def test_training_finds_its_world_by_content_or_key_and_a_world_without_a_trainer_says_so(tmp_path, capsys):
    config = tmp_path / "train.toml"
    config.write_text("total_steps = 64\n[world]\nhuman_num = 2\n")
    assert trainer_for(config) is domain_named("crowd")
    config.write_text('domain = "highway"\ntotal_steps = 64\n')
    assert trainer_for(config) is domain_named("highway")
    config.write_text('world = "gym"\n')
    assert not isinstance(domain_named("gym"), Trainer)
    assert main(["train", "--config", str(config), "--out", str(tmp_path / "run")]) == 2
    assert "the gym world has no trainer of its own" in capsys.readouterr().err
    config.write_text("learning_speed = 3\n")
    assert main(["train", "--config", str(config), "--out", str(tmp_path / "run")]) == 2
    assert "no installed world trains from" in capsys.readouterr().err


class Silent(Domain):
    """A world that writes the abstract methods but plays no test episodes."""

    name = "silent"

    def state(self, name, world): ...
    def step_seconds(self, name, world): ...
    def takes_summary(self, summary): ...
    def coupled(self, agents, state, reward): ...
    def rebuild(self, summary): ...
    def render(self, summary, out, numbers, options): ...


def test_a_world_that_plays_no_test_episodes_is_refused_when_foil_starts(monkeypatch):
    silent = EntryPoint("silent", "tests.test_domains:Silent", ENTRY_POINTS)
    installed = list(entry_points(group=ENTRY_POINTS))
    monkeypatch.setattr(search.core.domain, "entry_points", lambda group: [*installed, silent])
    domains.cache_clear()
    try:
        refused = r"'tests.test_domains:Silent' cannot be made: .*abstract method play: .*docs/worlds.md"
        with pytest.raises(ValueError, match=refused):
            domains()
    finally:
        domains.cache_clear()


@pytest.mark.parametrize(("agent", "scenario"), [("goal", None), ("tests.gym.corridor:dodging", "corridor.toml")])
def test_a_worlds_test_episodes_are_the_ones_its_evaluation_summarises(agent, scenario, tmp_path, monkeypatch):
    """Foil's own worlds evaluate in their own way; their `play` gives the same episodes, so Foil's evaluation from
    them agrees with theirs."""
    monkeypatch.chdir(tmp_path)
    if scenario is not None:
        (tmp_path / scenario).write_text('adapter = "tests.gym.corridor:CorridorAdapter"\nseed = 3\n')
    domain = domain_for([agent], scenario)
    own = domain.evaluate_episodes(agent, 6, 2, {}, scenario)
    played = domain.play(agent, 6, 2, {}, scenario)
    assert [episode.reward for episode in played] == own["episode_rewards"]
    assert sum(e.event == "success" for e in played) / 6 == own["success_rate"]
    assert sum(e.event == "collision" for e in played) / 6 == own["collision_rate"]


def test_no_module_outside_the_solvers_reads_a_solvers_record():
    """A solver's run.json record and a summary's solver entry are the solver's own to read: the runner, the command
    line and the bundle ask it (`Solver.warnings`, `Solver.clip_vote`) and subscript none of its record keys."""
    keys = {solver.record_key for solver in solvers().values() if isinstance(solver, OwnSummaries)}
    found = []
    for module, path in package_modules(ROOT).items():
        if module.startswith("search.solvers."):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            key = None
            if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
                key = node.slice.value
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get":
                key = node.args[0].value if node.args and isinstance(node.args[0], ast.Constant) else None
            if key in keys:
                found.append(f"{module}:{node.lineno} reads {key!r}")
    assert keys and found == []
