"""The study bundle's plan: the [build] table, the clips it asks for and their seeded robot numbers."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from app.survey.bundle import BundleError
from search.bundle.build import build_bundle
from search.bundle.searches import plan_clips, search_inputs, search_job
from search.bundle.spec import BuildError, load_build, parse_build
from search.solvers.mcts import MCTSConfig
from search.solvers.reward import RewardConfig
from tests.support.survey import planned_bundle

ROOT = Path(__file__).resolve().parents[2]

BUILD = """\
[build]
seed = 7

[build.eval]
episodes = 4
seed = 0

[build.schemes.adaptive]
solver = "mcts"
budget = 300
seed = 1

[build.schemes.nfirst]
solver = "nfirst"
budget = 300
seed = 1

[[build.sets]]
parts = ["pairwise", "ranking"]
schemes = ["adaptive", "nfirst"]
scenarios = ["paper-bl-tr"]
agents = ["goal", "orca", "social_force"]

[[build.sets]]
parts = ["example"]
schemes = ["nfirst"]
scenarios = ["paper-code"]
pairs = [["goal", "orca"]]
"""


def line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


def test_plan_covers_every_pair_scheme_and_scenario():
    jobs = plan_clips(parse_build(BUILD))
    assert len(jobs) == 2 * 3 + 1
    assert len({job.id for job in jobs}) == len(jobs)
    keys = {(job.scheme.name, job.scenario, frozenset(job.pair)) for job in jobs}
    assert ("nfirst", "paper-code", frozenset({"goal", "orca"})) in keys
    assert ("adaptive", "paper-bl-tr", frozenset({"orca", "social_force"})) in keys
    for job in jobs:
        assert all(name not in job.id for name in job.pair)  # ids reach browsers


def test_a_ranking_set_gives_each_agent_one_number_per_scheme_and_scenario():
    jobs = [job for job in plan_clips(parse_build(BUILD)) if "ranking" in job.parts]
    blocks = []
    for scheme in ("adaptive", "nfirst"):
        numbers = {}
        for job in (j for j in jobs if j.scheme.name == scheme):
            for agent, number in zip(job.pair, job.numbers, strict=True):
                numbers.setdefault(agent, set()).add(number)
        assert all(len(found) == 1 for found in numbers.values())
        blocks.append(sorted(n for found in numbers.values() for n in found))
    assert blocks == [[1, 2, 3], [4, 5, 6]]  # each round (scheme and scenario) its own numbers


def test_no_robot_number_names_two_agents_anywhere_in_a_bundle():
    text = BUILD.replace('scenarios = ["paper-bl-tr"]', 'scenarios = ["paper-bl-tr", "paper-tl-br"]') + (
        '\n[[build.sets]]\nparts = ["pairwise"]\nschemes = ["adaptive"]\nscenarios = ["paper-code"]\n'
        'agents = ["goal", "orca", "social_force"]\n'
    )
    jobs = plan_clips(parse_build(text))
    agent_of = {}
    for job in jobs:
        for agent, number in zip(job.pair, job.numbers, strict=True):
            assert agent_of.setdefault(number, agent) == agent
    pairwise = [job for job in jobs if job.parts == ("pairwise",)]
    assert len({n for job in pairwise for n in job.numbers}) == 2 * len(pairwise)  # a fresh pair per clip
    assert sorted(agent_of) == list(range(1, len(agent_of) + 1))


def test_robot_numbers_are_seeded_and_vary_with_the_seed():
    first = [job.numbers for job in plan_clips(parse_build(BUILD))]
    assert first == [job.numbers for job in plan_clips(parse_build(BUILD))]
    mappings = set()
    for seed in range(12):
        text = BUILD.replace("seed = 7", f"seed = {seed}")
        mappings.add(tuple(job.numbers for job in plan_clips(parse_build(text))))
    assert len(mappings) > 3
    example = [job for job in plan_clips(parse_build(BUILD)) if job.parts == ("example",)][0]
    assert sorted(example.numbers) == [7, 8]


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("seed = 7\n", "", r"line 1, build\.seed: Field required"),
        (
            "[build.schemes.adaptive]",
            "[build.scheme.adaptive]",
            r"line 8, build\.scheme: unknown key \(check the spelling; see docs/clips\.md",
        ),
        (
            "budget = 300\nseed = 1\n\n[build.schemes.nfirst]",
            "budget = 0\nseed = 1\n\n[build.schemes.nfirst]",
            r"line 10, build\.schemes\.adaptive\.budget: Input should be greater than or equal to 1",
        ),
        (
            "budget = 300\nseed = 1\n\n[build.schemes.nfirst]",
            'budget = "300"\nseed = 1\n\n[build.schemes.nfirst]',
            r"line 10, build\.schemes\.adaptive\.budget: Input should be a valid integer",
        ),
        (
            'solver = "nfirst"',
            'sovler = "nfirst"',
            r"line 13, build\.schemes\.nfirst\.solver: Field required\n"
            r".*line 14, build\.schemes\.nfirst\.sovler: unknown key",
        ),
        ("episodes = 4", "episodes = 1", r"build\.eval\.episodes: Input should be greater than or equal to 2"),
        (
            'schemes = ["adaptive", "nfirst"]',
            'schemes = ["adaptive", "mcts"]',
            r"line 20, build\.sets\[0\]\.schemes\[1\]: no scheme 'mcts'; defined: \['adaptive', 'nfirst'\]",
        ),
        (
            'parts = ["example"]',
            'parts = ["warmup"]',
            r"build\.sets\[1\]\.parts\[0\]: Input should be 'pairwise', 'ranking' or 'example'",
        ),
        (
            'parts = ["example"]',
            'parts = ["ranking"]',
            r"line 24, build\.sets\[1\]: a set that feeds a ranking part lists its agents",
        ),
        (
            'scenarios = ["paper-code"]',
            'scenarios = ["paper-bl-tr", "paper-bl-tr"]',
            r"build\.sets\[1\]\.scenarios: names must not repeat",
        ),
        (
            'pairs = [["goal", "orca"]]',
            'pairs = [["goal", "goal"]]',
            r"build\.sets\[1\]\.pairs\[0\]: a pair needs two different agents",
        ),
        (
            'agents = ["goal", "orca", "social_force"]',
            'agents = ["goal"]',
            r"line 22, build\.sets\[0\]\.agents: Value should have at least 2 items",
        ),
        (
            'schemes = ["nfirst"]\nscenarios = ["paper-code"]',
            'schemes = ["adaptive"]\nscenarios = ["paper-bl-tr"]',
            r"line 24, build\.sets\[1\]: the clip of adaptive, paper-bl-tr, goal and orca is already in sets\[0\]",
        ),
        ('agents = ["goal", "orca", "social_force"]', "", r"line 18, build\.sets\[0\]: give either agents"),
        ("[build.eval]", "[build.render]\nfps = 5\n[build.eval]", r"line 4, build\.render: .*fps must be at least 20"),
        (
            "[build.eval]",
            "[build.render]\nfsp = 24\n[build.eval]",
            r"line 5, build\.render\.fsp: unknown render setting\(s\) \['fsp'\]; known render settings: \[.*'fps'",
        ),
        (
            'agents = ["goal", "orca", "social_force"]',
            f"agents = {[f'a{i}' for i in range(43)]}",
            r"line 22, build\.sets\[0\]\.agents: a ranking shows at most 42 agents",
        ),
    ],
)
def test_bad_build_tables_give_clear_errors_with_their_line(old, new, message):
    assert old in BUILD
    with pytest.raises(BuildError, match=f"^study.toml, (.|\n)*{message}"):
        parse_build(BUILD.replace(old, new), source="study.toml")


def test_the_paper_build_table_is_parsed_and_a_second_set_is_found_at_its_line():
    paper = (ROOT / "studies" / "paper.toml").read_text()
    spec = parse_build(paper)
    assert spec.schemes["adaptive"].budget == 1_000_000 and spec.sets[1].pairs == (("lo", "hi"),)
    text = paper.replace('scenarios = ["paper-code"]', 'scenarios = ["paper-code"]\nagents = ["lo", "hi"]')
    with pytest.raises(BuildError) as error:
        parse_build(text, "paper.toml")
    line = line_of(text, "[[build.sets]]               # the instructions page")
    assert str(error.value) == (
        f"paper.toml, line {line}, build.sets[1]: give either agents = [...] (every pair of "
        "them) or pairs = [[a, b], ...]"
    )


def test_the_bundle_builder_owns_the_build_table_and_reports_like_the_server(tmp_path):
    """The server leaves `[build]` alone; `foil bundle` refuses a bad line of it in the server's form (file, line,
    field), and lists the survey tables' problems, found by the server's own check, with it."""
    from app.survey.study import StudyError, load_study

    study = tmp_path / "study.toml"
    text = (ROOT / "studies" / "demo.toml").read_text().replace("budget = 5_000   ", "budget = -5   ")
    study.write_text(text)
    assert load_study(study).build["schemes"]["adaptive"]["budget"] == -5
    with pytest.raises(BuildError) as bundled:
        load_build(study)
    line = line_of(study.read_text(), "budget = -5")
    assert str(bundled.value) == (
        f"{study}, line {line}, build.schemes.adaptive.budget: Input should be greater than or equal to 1"
    )
    study.write_text(text.replace("seed = 1\nrequire_full_view", "sead = 1\nrequire_full_view"))
    with pytest.raises(StudyError) as served:
        load_study(study)
    with pytest.raises(BuildError) as bundled:
        load_build(study)
    assert str(bundled.value) == f"{served.value}\n{study}, line {line}, build.schemes.adaptive.budget: " + (
        "Input should be greater than or equal to 1"
    )


def test_scheme_settings_reach_the_search_as_the_fields_types():
    """A whole number in the study file is a float where the setting is one, as `foil search --set
    exploration=100` gives it, so both make the same search."""
    text = BUILD + (
        '[build.schemes.adaptive.settings]\nexploration = 100\nmode = "receding"\n'
        "[build.schemes.adaptive.reward]\nalpha = 2\n[build.schemes.adaptive.world]\n"
    )
    job = next(job for job in plan_clips(parse_build(text + "robot_visible = true\n")) if job.scheme.name == "adaptive")
    assert job.scheme.solver_config == MCTSConfig(exploration=100.0, mode="receding")
    assert job.scheme.reward == RewardConfig(alpha=2.0)
    search = search_job(job)
    assert search.solver_config == MCTSConfig(exploration=100.0, mode="receding")
    assert type(search.solver_config.exploration) is float and type(search.reward_settings["alpha"]) is float
    assert search.reward_settings == RewardConfig(alpha=2.0).to_dict()
    assert search.world_settings == {"robot_visible": True}
    assert (search.agents, search.scenario, search.budget, search.seed) == (job.pair, job.scenario, 300, 1)
    with pytest.raises(
        BuildError,
        match=r"build\.schemes\.adaptive\.world\.robot_visible: bad world setting "
        "robot_visible = 'yes': robot_visible takes a bool",
    ):
        parse_build(text + 'robot_visible = "yes"\n')
    with pytest.raises(
        BuildError,
        match=r"build\.schemes\.adaptive\.settings: must be a table of key = value "
        "settings",
    ):
        parse_build(text.replace("exploration = 100", "nested = {x = 1}") + "robot_visible = true\n")


def test_bad_search_settings_are_refused_before_any_work(tmp_path):
    """Settings the solver, reward or world do not have, and scenarios that do not exist, are refused at their lines
    before anything runs."""
    study = tmp_path / "study.toml"
    study.write_text(
        '[build]\nseed = 1\n[build.schemes.a]\nsolver = "mcts"\nbudget = 10\nseed = 0\n'
        '[build.schemes.a.settings]\nexplorashun = 3\n[build.schemes.a.world]\nrobot_visible = "yes"\n'
        '[[build.sets]]\nparts = ["pairwise"]\nschemes = ["a"]\nscenarios = ["paper-bl-tr", "nowhere"]\n'
        'pairs = [["goal", "orca"]]\n'
    )
    with pytest.raises(BuildError) as refused:
        build_bundle(study, tmp_path / "out", log=lambda line: None)
    lines = [line for line in str(refused.value).splitlines() if ", build." in line]  # after the survey tables'
    assert lines[0].startswith(
        f"{study}, line 8, build.schemes.a.settings.explorashun: unknown solver setting(s) ['explorashun']; known "
        "solver settings: ["
    )
    assert lines[1].startswith(
        f"{study}, line 10, build.schemes.a.world.robot_visible: bad world setting "
        "robot_visible = 'yes': robot_visible takes a bool"
    )
    assert lines[2].startswith(f"{study}, line 14, build.sets[0].scenarios[1]: ") and "nowhere" in lines[2]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "old, new, field",
    [
        ("seed = 1\nrequire_full_view", "sead = 1\nrequire_full_view", r"study\.sead: unknown key"),
        ("[[comprehension]]", "[[comprehensionn]]", r"comprehensionn: unknown key"),
    ],
)
def test_foil_bundle_checks_every_table_before_any_search(tmp_path, capsys, old, new, field):
    """A misspelt key anywhere in the study file stops `foil bundle` at once with its line, as `foil serve` would
    after the whole build; nothing is searched or written."""
    from search.cli import main

    text = (ROOT / "studies" / "demo.toml").read_text()
    assert old in text
    study = tmp_path / "study.toml"
    study.write_text(text.replace(old, new, 1))
    assert main(["bundle", str(study), "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    line = line_of(study.read_text(), new.split("\n")[0])
    assert error.startswith("foil bundle: error: ")
    assert re.search(rf"{re.escape(str(study))}, line {line}, {field}", error), error
    assert not (tmp_path / "out").exists()


def test_a_study_file_without_a_build_table_is_refused(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text('[study]\nid = "x"\n')
    with pytest.raises(BuildError, match="no \\[build\\] table"):
        load_build(study)


@pytest.mark.parametrize("name", ["paper.toml", "demo.toml", "methods.toml", "methods-highway.toml"])
def test_shipped_study_files_build_and_serve(name):
    """Every search of the shipped study files is valid (settings, scenarios), and the clips they plan are what
    the server asks for: a manifest of them passes the server's start-up check, one label per robot in a round."""
    from app.survey.bundle import Bundle, check_study_against_bundle
    from app.survey.study import load_study

    spec, _ = load_build(ROOT / "studies" / name)
    jobs = plan_clips(spec)
    assert all(search_inputs(search_job(job)) for job in jobs)
    bundle = planned_bundle(jobs, ROOT)
    study = load_study(ROOT / "studies" / name)  # the server reads the same file
    check_study_against_bundle(study, bundle)
    without_one = dict(list(bundle.clips.items())[1:])
    with pytest.raises(BundleError, match="needs a clip of"):
        check_study_against_bundle(study, Bundle(root=ROOT, clips=without_one, paths={}))


def test_each_part_draws_its_own_representative_clips():
    """The demo's representative scheme votes once per pair for both parts (one seed: one pool of rollouts), and
    the ranking round's clip comes from another state of that vote (earlier = 1), so every plan shows each part its
    own clips and the round does not replay part one's three clips."""
    import random

    from app.survey.assignment import conditions
    from app.survey.plan import build_plan
    from app.survey.screens import Pairwise, Watch
    from app.survey.study import load_study

    spec, _ = load_build(ROOT / "studies" / "demo.toml")
    jobs = [job for job in plan_clips(spec) if job.scheme.name == "representative"]
    assert sorted(job.parts for job in jobs) == [("pairwise",)] * 3 + [("ranking",)] * 3
    assert {job.scheme.seed for job in jobs} == {0}
    assert sorted(job.scheme.solver_config.earlier for job in jobs) == [0, 0, 0, 1, 1, 1]
    assert all(job.scheme.solver_config.earlier == (job.parts == ("ranking",)) for job in jobs)
    assert len({json.dumps(search_inputs(search_job(job)), sort_keys=True) for job in jobs}) == 6
    study = load_study(ROOT / "studies" / "demo.toml")
    bundle = planned_bundle(plan_clips(spec), ROOT)
    for condition in conditions(study):
        plan = build_plan(study, bundle, condition, random.Random(condition.index))
        shown = {
            kind: {s.clip for s in plan if isinstance(s, kind) and s.scheme == "representative"}
            for kind in (Pairwise, Watch)
        }
        assert len(shown[Pairwise]) == len(shown[Watch]) == 3 and not shown[Pairwise] & shown[Watch]


def test_paper_build_reproduces_the_papers_clip_set():
    spec, _ = load_build(ROOT / "studies" / "paper.toml")
    jobs = plan_clips(spec)
    main = [job for job in jobs if "example" not in job.parts]
    assert {job.scheme.solver for job in main} == {"mcts", "nfirst"}
    for scheme in ("adaptive", "nfirst"):
        for scenario in ("paper-bl-tr", "paper-tl-br"):
            pairs = {frozenset(job.pair) for job in main if job.scheme.name == scheme and job.scenario == scenario}
            assert pairs == {frozenset(p) for p in (("lo", "med"), ("med", "hi"), ("lo", "hi"))}
    # the paper's reward as its code sets it, ending at the first robot's end (docs/search.md)
    adaptive = next(search_inputs(search_job(job)) for job in main if job.scheme.name == "adaptive")
    assert {
        k: adaptive["reward"][k]
        for k in ("finish", "goal_bonus", "alpha", "beta", "horizon_offset", "collision_is_goal")
    } == {
        "finish": "first",
        "goal_bonus": 100.0,
        "alpha": 1.0,
        "beta": 1e4,
        "horizon_offset": -1e5,
        "collision_is_goal": False,
    }
    assert all(
        search_inputs(search_job(job))["reward"]["finish"] == "first" for job in main if job.scheme.name == "nfirst"
    )


@pytest.mark.parametrize(
    "majority, disagrees, decided, start, end",
    [
        (
            1,
            False,
            False,
            "representativeness paper-bl-tr, lo vs hi:",
            "(percentile 40; near 0: unusual for the pair)",
        ),
        (
            -1,
            True,
            True,
            "warning: unrepresentative scenario paper-bl-tr, lo vs hi:",
            "its clips tend to show the other agent as better than most starting states do",
        ),
        (
            0,
            True,
            True,
            "warning: unrepresentative scenario paper-bl-tr, lo vs hi:",
            "its clips tend to show no difference where most starting states show one",
        ),
        (  # a few rollouts that disagree: no warning, the line says it is undecided and what would decide it
            -1,
            True,
            False,
            "representativeness paper-bl-tr, lo vs hi:",
            "undecided, its 33 rollouts cannot tell whether it shows less than the vote (binomial test p = 0.3); "
            "raise [build.representativeness] pushes to decide it",
        ),
    ],
)
def test_the_representativeness_line_warns_when_the_scenario_decidedly_disagrees_with_the_distribution(
    majority, disagrees, decided, start, end
):
    from search.bundle.representativeness import describe_representativeness

    report = {
        "agents": ["lo", "hi"],
        "scenario": "paper-bl-tr",
        "distribution": "training",
        "rollouts": 33,
        "first_looks_better": 0.1,
        "second_looks_better": 0.7,
        "no_difference": 0.2,
        "majority": majority,
        "percentile": 40.0,
        "disagrees": disagrees,
        "agreeing_p": 0.001 if decided else 0.3,
        "decided": decided,
        "distribution_vote": {
            "direction": 1,
            "states": 64,
            "for_first": 50,
            "for_second": 4,
            "p": 0.0001,
            "alpha": 0.05,
            "decided": True,
        },
    }
    line = describe_representativeness(report)
    assert line.startswith(start) and line.endswith(end)
    assert "lo looks better in 10% of 33 nominal rollouts, hi in 70%" in line
    assert "training's 64 states vote lo (50 for lo, 4 for hi, weighed by how plainly)" in line
    assert "agrees with that vote as often as or more often than 40% of the distribution's states do" in line
