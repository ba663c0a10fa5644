"""The study bundle's plan: the [build] table, the clips it asks for and their seeded robot numbers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from search.bundle.build import BuildError, build_bundle, load_build, parse_build, plan, search_inputs, search_job

ROOT = Path(__file__).resolve().parents[2]

BUILD = {
    "seed": 7,
    "eval": {"episodes": 4, "seed": 0},
    "schemes": {"adaptive": {"solver": "mcts", "budget": 300, "seed": 1},
                "nfirst": {"solver": "nfirst", "budget": 300, "seed": 1}},
    "sets": [
        {"parts": ["pairwise", "ranking"], "schemes": ["adaptive", "nfirst"], "scenarios": ["paper-bl-tr"],
         "agents": ["goal", "orca", "social_force"]},
        {"parts": ["example"], "schemes": ["nfirst"], "scenarios": ["paper-code"], "pairs": [["goal", "orca"]]},
    ],
}


def copy(table: dict) -> dict:
    return json.loads(json.dumps(table))


def test_plan_covers_every_pair_scheme_and_scenario():
    jobs = plan(parse_build(BUILD))
    assert len(jobs) == 2 * 3 + 1
    assert len({job.id for job in jobs}) == len(jobs)
    keys = {(job.scheme.name, job.scenario, frozenset(job.pair)) for job in jobs}
    assert ("nfirst", "paper-code", frozenset({"goal", "orca"})) in keys
    assert ("adaptive", "paper-bl-tr", frozenset({"orca", "social_force"})) in keys
    for job in jobs:
        assert all(name not in job.id for name in job.pair)  # ids reach browsers


def test_a_ranking_set_gives_each_agent_one_number_per_scheme_and_scenario():
    jobs = [job for job in plan(parse_build(BUILD)) if "ranking" in job.parts]
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
    table = copy(BUILD)
    table["sets"][0]["scenarios"] = ["paper-bl-tr", "paper-tl-br"]
    table["sets"].append({"parts": ["pairwise"], "schemes": ["adaptive"], "scenarios": ["paper-code"],
                          "agents": ["goal", "orca", "social_force"]})
    jobs = plan(parse_build(table))
    agent_of = {}
    for job in jobs:
        for agent, number in zip(job.pair, job.numbers, strict=True):
            assert agent_of.setdefault(number, agent) == agent
    pairwise = [job for job in jobs if job.parts == ("pairwise",)]
    assert len({n for job in pairwise for n in job.numbers}) == 2 * len(pairwise)  # a fresh pair per clip
    assert sorted(agent_of) == list(range(1, len(agent_of) + 1))


def test_robot_numbers_are_seeded_and_vary_with_the_seed():
    first = [job.numbers for job in plan(parse_build(BUILD))]
    assert first == [job.numbers for job in plan(parse_build(BUILD))]
    mappings = set()
    for seed in range(12):
        table = copy(BUILD) | {"seed": seed}
        mappings.add(tuple(job.numbers for job in plan(parse_build(table))))
    assert len(mappings) > 3
    example = [job for job in plan(parse_build(BUILD)) if job.parts == ("example",)][0]
    assert sorted(example.numbers) == [7, 8]


@pytest.mark.parametrize(("change", "message"), [
    (lambda b: b.pop("schemes"), r"missing key\(s\) \['schemes'\]"),
    (lambda b: b["schemes"]["adaptive"].update(budget=0), r"schemes.adaptive.budget: must be a whole number >= 1"),
    (lambda b: b["schemes"]["nfirst"].update(sovler="x"), r"schemes.nfirst: unknown key\(s\) \['sovler'\]"),
    (lambda b: b["sets"][0].update(schemes=["adaptive", "mcts"]), r"sets\[0\].schemes: no scheme 'mcts'"),
    (lambda b: b["sets"][1].update(parts=["warmup"]), r"sets\[1\].parts: parts are"),
    (lambda b: b["sets"][1].update(parts=["ranking"]), r"sets\[1\]: a set that feeds a ranking part lists its agents"),
    (lambda b: b["sets"][1].update(scenarios=["paper-bl-tr"], schemes=["adaptive"]), r"sets\[1\]: the clip of .*"
                                                                                    r"already in sets\[0\]"),
    (lambda b: b["sets"][0].pop("agents"), "give either agents"),
    (lambda b: b.update(render={"fps": 5}), "fps must be at least 20"),
    (lambda b: b["sets"][0].update(agents=[f"a{i}" for i in range(43)]), r"a ranking shows at most 42 robots"),
])
def test_bad_build_tables_give_clear_errors(change, message):
    table = copy(BUILD)
    change(table)
    with pytest.raises(BuildError, match=message):
        parse_build(table, source="study.toml")


def test_scheme_settings_reach_the_search_as_the_fields_types():
    """A whole number in the study file is a float where the setting is one, as `foil search --set
    exploration=100` gives it, so both make the same search."""
    table = copy(BUILD)
    table["schemes"]["adaptive"] |= {"settings": {"exploration": 100, "mode": "receding"}, "reward": {"alpha": 2},
                                     "world": {"robot_visible": True}}
    job = next(job for job in plan(parse_build(table)) if job.scheme.name == "adaptive")
    search = search_job(job)
    assert search.solver_settings == {"exploration": 100.0, "mode": "receding"}
    assert type(search.solver_settings["exploration"]) is float and type(search.reward_settings["alpha"]) is float
    assert search.reward_settings == {"alpha": 2.0} and search.world_settings == {"robot_visible": True}
    assert (search.agents, search.scenario, search.budget, search.seed) == (job.pair, job.scenario, 300, 1)
    table["schemes"]["adaptive"]["world"] = {"robot_visible": "yes"}
    job = next(job for job in plan(parse_build(table)) if job.scheme.name == "adaptive")
    with pytest.raises(ValueError, match="bad world setting robot_visible = 'yes': robot_visible takes a bool"):
        search_job(job)
    table["schemes"]["adaptive"]["settings"] = {"nested": {"x": 1}}
    with pytest.raises(BuildError, match="schemes.adaptive.settings: must be a table of key = value settings"):
        parse_build(table)


def test_bad_search_settings_are_refused_before_any_work(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text('[build]\nseed = 1\n[build.schemes.a]\nsolver = "mcts"\nbudget = 10\nseed = 0\n'
                     '[build.schemes.a.settings]\nexplorashun = 3\n[[build.sets]]\nparts = ["pairwise"]\n'
                     'schemes = ["a"]\nscenarios = ["paper-bl-tr"]\npairs = [["goal", "orca"]]\n')
    with pytest.raises(BuildError, match="bad solver setting 'explorashun'"):
        build_bundle(study, tmp_path / "out", log=lambda line: None)
    assert not (tmp_path / "out").exists()


def test_a_study_file_without_a_build_table_is_refused(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text('[study]\nid = "x"\n')
    with pytest.raises(BuildError, match="no \\[build\\] table"):
        load_build(study)


@pytest.mark.parametrize("name", ["paper.toml", "demo.toml"])
def test_shipped_study_files_build_and_serve(name):
    from app.study import load_study

    spec, _ = load_build(ROOT / "studies" / name)
    assert plan(spec)
    assert load_study(ROOT / "studies" / name).build is not None  # the server reads the same file


def test_paper_build_reproduces_the_papers_clip_set():
    spec, _ = load_build(ROOT / "studies" / "paper.toml")
    jobs = plan(spec)
    main = [job for job in jobs if "example" not in job.parts]
    assert {job.scheme.solver for job in main} == {"mcts", "nfirst"}
    for scheme in ("adaptive", "nfirst"):
        for scenario in ("paper-bl-tr", "paper-tl-br"):
            pairs = {frozenset(job.pair) for job in main if job.scheme.name == scheme and job.scenario == scenario}
            assert pairs == {frozenset(p) for p in (("lo", "med"), ("med", "hi"), ("lo", "hi"))}
    # the paper's reward as its code sets it, ending at the first robot's end (docs/search.md)
    adaptive = next(search_inputs(search_job(job)) for job in main if job.scheme.name == "adaptive")
    assert {k: adaptive["reward"][k] for k in ("finish", "goal_bonus", "alpha", "beta", "horizon_offset",
                                                 "collision_is_goal")} == {
        "finish": "first", "goal_bonus": 100.0, "alpha": 1.0, "beta": 1e4, "horizon_offset": -1e5,
        "collision_is_goal": False}
    assert all(search_inputs(search_job(job))["reward"]["finish"] == "first"
               for job in main if job.scheme.name == "nfirst")
