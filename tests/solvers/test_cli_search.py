"""foil search / verify / search-all through the real command line, on small budgets."""

import json

import pytest

from search.cli import main
from search.solvers.baselines import CEMConfig
from search.solvers.runner import SearchJob, parse_settings, run_all, run_search, study_jobs

SMALL = ["--budget", "600", "--top-k", "3", "--reward", "horizon_steps=30", "--quiet"]


def search(out, *extra, agents="goal,orca", solver="mcts", seed="0"):
    return main(
        [
            "search",
            "--agents",
            agents,
            "--scenario",
            "paper-bl-tr",
            "--solver",
            solver,
            "--seed",
            seed,
            "--out",
            str(out),
            *SMALL,
            *extra,
        ]
    )


@pytest.fixture(scope="module")
def searched(tmp_path_factory):
    out = tmp_path_factory.mktemp("search")
    assert search(out, "--set", "batch=8") == 0
    return out


def test_search_writes_ranked_summaries_and_a_run_record(searched):
    files = sorted(p.name for p in searched.iterdir())
    assert files == ["run.json", "summary-001.json", "summary-002.json", "summary-003.json"]
    summaries = [json.loads((searched / f"summary-00{i}.json").read_text()) for i in (1, 2, 3)]
    rewards = [s["reward"] for s in summaries]
    assert rewards == sorted(rewards, reverse=True)
    first = summaries[0]
    assert first["format"] == "foil.summary/2"
    assert [a["name"] for a in first["agents"]] == ["goal", "orca"]
    assert len(first["env_actions"]) <= len(first["steps"]) <= 30  # a coda may follow the searched steps
    assert all(len(a) == 20 for a in first["env_actions"])
    assert set(first["steps"][0]) == {"t", "other_positions", "agent_positions", "agent_actions"}
    assert {o["event"] for o in first["outcomes"]} <= {"success", "collision", "timeout", "running"}
    assert first["reward"] == pytest.approx(sum(first["reward_terms"].values()))
    assert first["scenario"]["world"]["human_num"] == 10  # the full world config, not just the file's settings
    run = json.loads((searched / "run.json").read_text())
    assert run["solver"]["budget"] == 600 and run["sim_steps"] >= 600
    steps = [point[0] for point in run["curve"]]
    best = [point[1] for point in run["curve"]]
    assert steps == sorted(steps) and best == sorted(best) and best[-1] == rewards[0]


def test_verify_passes_on_fresh_output_and_fails_on_a_tampered_file(searched, tmp_path, capsys):
    assert main(["verify", *(str(p) for p in sorted(searched.glob("summary-*.json")))]) == 0
    assert "reproduced exactly" in capsys.readouterr().out
    data = json.loads((searched / "summary-002.json").read_text())
    data["steps"][5]["agent_positions"][1][0] += 1e-12
    tampered = tmp_path / "tampered.json"
    tampered.write_text(json.dumps(data))
    assert main(["verify", str(tampered)]) == 1
    assert "steps[5].agent_positions[1][0]" in capsys.readouterr().out
    data = json.loads((searched / "summary-001.json").read_text())
    data["env_actions"][0][3] = -data["env_actions"][0][3]
    tampered.write_text(json.dumps(data))
    assert main(["verify", str(tampered)]) == 1


def test_same_seed_same_summaries(searched, tmp_path):
    assert search(tmp_path, "--set", "batch=8") == 0
    for path in searched.glob("summary-*.json"):
        assert (tmp_path / path.name).read_bytes() == path.read_bytes()


@pytest.mark.parametrize("solver", ["nfirst", "random", "cem"])
def test_every_solver_writes_verifiable_summaries(tmp_path, solver):
    extra = ["--set", "population=8"] if solver == "cem" else []
    assert search(tmp_path, *extra, solver=solver) == 0
    assert main(["verify", str(tmp_path / "summary-001.json")]) == 0
    run = json.loads((tmp_path / "run.json").read_text())
    if solver == "nfirst":
        assert run["trajectories"] == 3  # exactly N, whatever the budget


def test_joint_search_of_three_agents(tmp_path):
    assert search(tmp_path, agents="goal,orca,social_force", solver="random") == 0
    summary = json.loads((tmp_path / "summary-001.json").read_text())
    assert len(summary["agents"]) == 3 and len(summary["steps"][0]["agent_positions"]) == 3
    assert main(["verify", str(tmp_path / "summary-001.json")]) == 0


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--solver", "annealing"], "unknown solver 'annealing'"),
        (["--set", "exploraton=3"], "bad solver setting 'exploraton=3'"),
        (["--set", "batch=many"], "batch takes a int"),
        (["--reward", "norm=cubed"], "norm must be 'plain' or 'squared'"),
        (["--world", "env_action_mode=shove"], "env_action_mode must be one of"),
        (["--agents", "goal"], "at least two agents"),
        (["--agents", "goal,nobody"], "unknown agent 'nobody'"),
        (["--scenario", "nowhere"], "no scenario 'nowhere'"),
    ],
)
def test_bad_input_is_a_clear_error(tmp_path, capsys, extra, message):
    flag, value = extra
    options = {"--agents": "goal,orca", "--scenario": "paper-bl-tr", "--solver": "mcts"}
    settings = [flag, value] if flag in ("--set", "--reward", "--world") else []
    if not settings:
        options[flag] = value
    command = ["search", *(x for option in options.items() for x in option), "--out", str(tmp_path), *SMALL]
    assert main(command + settings) == 2
    assert message in capsys.readouterr().err


def test_verify_rejects_a_file_that_is_not_a_summary(tmp_path, capsys):
    path = tmp_path / "other.json"
    path.write_text('{"format": "foil.bundle/1"}')
    assert main(["verify", str(path)]) == 2
    assert "not a summary" in capsys.readouterr().err


def test_parse_settings_converts_types():
    assert parse_settings(CEMConfig, ["population=16", "smoothing=0.5"], "solver") == {
        "population": 16,
        "smoothing": 0.5,
    }


def test_study_jobs_cover_every_pair_and_scenario():
    jobs = study_jobs(["lo", "med", "hi"], ["paper-bl-tr", "paper-tl-br"], ["mcts", "nfirst"], budget=10)
    assert len(jobs) == 2 * 3 * 2
    assert {job.agents for job in jobs} == {("lo", "med"), ("lo", "hi"), ("med", "hi")}
    joint = study_jobs(["lo", "med", "hi"], ["paper-bl-tr"], ["mcts"], joint=True)
    assert [job.agents for job in joint] == [("lo", "med", "hi")]


def test_search_all_in_parallel_processes_reproduces_single_searches(tmp_path):
    common = {"budget": 300, "top_k": 2, "reward_settings": {"horizon": 20}}
    jobs = study_jobs(["goal", "orca", "social_force"], ["paper-bl-tr"], ["random"], **common)
    study = run_all(jobs, tmp_path, workers=2, progress=False)
    assert len(study["jobs"]) == 3
    alone = run_search(SearchJob(agents=("orca", "social_force"), scenario="paper-bl-tr", solver="random", **common))
    folder = tmp_path / "random" / "orca-vs-social_force" / "paper-bl-tr"
    assert (folder / "summary-001.json").read_text() == alone["summary-001.json"]
    assert json.loads((tmp_path / "study.json").read_text())["workers"] == 2


@pytest.mark.slow
def test_search_all_on_a_local_ray_instance(tmp_path):
    """The engine users move to when one machine is not enough: `foil search-all --backend ray` starts a local
    Ray instance (no address given) and reproduces a single search exactly."""
    common = {"budget": 300, "top_k": 2, "reward_settings": {"horizon": 20}}
    jobs = study_jobs(["goal", "orca"], ["paper-bl-tr", "paper-tl-br"], ["random"], **common)
    study = run_all(jobs, tmp_path, workers=2, backend="ray", progress=False)
    assert study["backend"] == "ray" and len(study["jobs"]) == 2
    alone = run_search(jobs[1])
    folder = tmp_path / "random" / "goal-vs-orca" / "paper-tl-br"
    assert (folder / "summary-001.json").read_text() == alone["summary-001.json"]


def test_first_finish_ends_every_trajectory_at_the_first_robots_end(tmp_path):
    """With --reward finish=first a summary's searched steps end on the step the first robot collides or arrives,
    a collision earns no goal term; the clip plays on without pushes (its coda) until the other robot's episode
    ends too or the horizon is reached, and replay reproduces every summary, coda included, exactly."""
    reward = ["--reward", "finish=first", "--reward", "horizon_steps=60"]
    assert search(tmp_path, *reward, "--budget", "6000", "--top-k", "5") == 0
    ends, codas = set(), 0
    for path in sorted(tmp_path.glob("summary-*.json")):
        summary = json.loads(path.read_text())
        assert summary["reward_parameters"]["finish"] == "first"
        searched, steps = len(summary["env_actions"]), summary["steps"]
        first = min(summary["outcomes"], key=lambda o: o["time"] if o["time"] is not None else float("inf"))
        assert first["event"] in ("collision", "success") and steps[searched - 1]["t"] == first["time"]
        others = [o for o in summary["outcomes"] if o is not first]
        # the coda: no pushes, until every robot's episode has ended or the 60-step horizon is reached
        assert len(steps) == 60 or all(o["event"] != "running" for o in others)
        assert all(o["event"] == "running" or o["time"] <= steps[-1]["t"] for o in others)
        codas += len(steps) > searched
        if first["event"] == "collision":
            assert summary["reward_terms"]["goal"] == 0.0 and summary["reward_terms"]["horizon"] > 0
        ends.add(first["event"])
        assert main(["verify", str(path)]) == 0
    assert ends == {"collision", "success"}  # both kinds of end occur among the goal robot's summaries
    assert codas == 5  # the other robot was still on its way in every one
