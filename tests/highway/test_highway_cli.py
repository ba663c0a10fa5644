"""The CLI infers the world from agents and scenario; highway training, release choice and evaluation."""

from __future__ import annotations

import json

import pytest

from search.cli import main
from search.core.domain import domain_for
from search.highway.release import apart, checkpoints, choose, is_highway_run

DRIVERS = "tests.highway.drivers:idle,tests.highway.drivers:slower"


def test_the_world_is_inferred_and_mixing_is_refused(tmp_path, capsys):
    assert domain_for(["highway-hi"]).name == "highway" and domain_for(["model.zip"]).name == "gym"
    assert domain_for(["hi"]).name == domain_for(["runs/x.pt"]).name == domain_for(["pkg.mod:policy"]).name == "crowd"
    assert domain_for(["pkg.mod:policy"], "highway-dense").name == "highway"
    assert domain_for(["highway-lo", "model.zip"], "highway-dense").name == "highway"
    assert domain_for(["lo", "pkg.mod:policy"], "paper-code").name == "crowd"
    code = main(["search", "--agents", "highway-lo,hi", "--scenario", "highway-dense", "--out", str(tmp_path)])
    error = capsys.readouterr().err
    assert code == 2 and "cannot mix worlds" in error and "hi (crowd)" in error and "highway-dense (highway)" in error
    assert main(["eval", "highway-nobody"]) == 2
    assert "unknown highway agent 'highway-nobody'" in capsys.readouterr().err


def test_foil_search_and_verify_on_a_highway_scenario(tmp_path, capsys):
    out = tmp_path / "out"
    assert (
        main(
            [
                "search",
                "--agents",
                DRIVERS,
                "--scenario",
                "highway-light",
                "--out",
                str(out),
                "--budget",
                "100",
                "--top-k",
                "1",
                "--solver",
                "random",
                "--set",
                "batch=1",
                "--world",
                "vehicles_density=1.2",
                "--quiet",
            ]
        )
        == 0
    )
    summary = out / "summary-001.json"
    data = json.loads(summary.read_text())
    assert data["scenario"]["settings"]["vehicles_density"] == 1.2
    assert main(["verify", str(summary)]) == 0 and "reproduced exactly" in capsys.readouterr().out
    data["reward"] += 1.0
    summary.write_text(json.dumps(data))
    assert main(["verify", str(summary)]) == 1 and "DIFFERS" in capsys.readouterr().out


def test_foil_eval_reads_any_stable_baselines3_file(tmp_path, capsys):
    from stable_baselines3 import PPO

    from search.highway.adapter import HighwayAdapter

    PPO("MlpPolicy", HighwayAdapter().make(), seed=0, device="cpu").save(tmp_path / "agent.zip")
    assert main(["eval", str(tmp_path / "agent.zip"), "--episodes", "2", "--json"]) == 2
    assert "give --scenario FILE" in capsys.readouterr().err  # a Gymnasium agent needs its world
    assert main(["eval", str(tmp_path / "agent.zip"), "--scenario", "highway-light", "--episodes", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["episodes"] == 2 and 0 <= result["collision_rate"] <= 1
    assert result["reward_ci95"][0] <= result["reward_mean"] <= result["reward_ci95"][1]


def _row(name, steps, reward, collision, width=0.5):
    return {
        "checkpoint": name,
        "env_steps": steps,
        "episodes": 30,
        "reward_mean": reward,
        "reward_low": reward - width,
        "reward_high": reward + width,
        "collision_rate": collision,
        "collision_low": max(0.0, collision - 0.1),
        "collision_high": min(1.0, collision + 0.1),
    }


def test_release_picks_three_clearly_separated_snapshots():
    rows = [
        _row("a", 0, 5.0, 1.0),
        _row("b", 10, 12.0, 0.6),
        _row("c", 20, 14.5, 0.45),
        _row("d", 30, 20.0, 0.1),
        _row("e", 40, 21.0, 0.0),
        _row("f", 50, 20.8, 0.0),
    ]
    chosen = choose(rows)
    assert [chosen[k]["checkpoint"] for k in ("lo", "med", "hi")] == ["a", "b", "e"]  # b: nearest the middle 13
    assert apart(chosen["lo"], chosen["med"]) and apart(chosen["med"], chosen["hi"])
    assert not apart(rows[4], rows[5])
    with pytest.raises(ValueError, match="clearly apart"):
        choose([_row("a", 0, 5.0, 1.0), _row("e", 40, 21.0, 0.0)])


def test_foil_train_writes_a_highway_run_that_release_recognises(tmp_path, capsys):
    config = tmp_path / "tiny.toml"
    config.write_text(
        'world = "highway"\ntotal_steps = 96\nlearning_starts = 16\nbatch_size = 8\nhidden = 16\nsave_every = 32\n'
    )
    run = tmp_path / "run"
    assert main(["train", "--config", str(config), "--out", str(run)]) == 0
    assert is_highway_run(run) and [p.name for p in checkpoints(run)] == [
        f"model_{steps}_steps.zip" for steps in (32, 64, 96)
    ]  # no untrained network: it is no driver
    config.write_text('domain = "highway"\nlearning_rat = 1\n')
    assert main(["train", "--config", str(config), "--out", str(run)]) == 2
    assert "unknown highway training setting(s) ['learning_rat']" in capsys.readouterr().err


def test_the_shipped_highway_agents_search_verify_and_evaluate(tmp_path, capsys):
    out = tmp_path / "out"
    assert (
        main(
            [
                "search",
                "--agents",
                "highway-lo,highway-hi",
                "--scenario",
                "highway-dense",
                "--out",
                str(out),
                "--budget",
                "100",
                "--top-k",
                "1",
                "--solver",
                "mcts",
                "--set",
                "batch=2",
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((out / "summary-001.json").read_text())
    assert [a["name"] for a in summary["agents"]] == ["highway-lo", "highway-hi"]
    assert summary["agents"][1]["source"].endswith("search/highway/agents/hi.zip")
    assert main(["verify", str(out / "summary-001.json")]) == 0
    capsys.readouterr()
    assert main(["eval", "highway-lo", "--episodes", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["collision_rate"] == 1.0  # the untrained snapshot always crashes


def test_foil_search_all_runs_highway_pairs(tmp_path):
    out = tmp_path / "all"
    assert (
        main(
            [
                "search-all",
                "--agents",
                DRIVERS,
                "--scenarios",
                "highway-light",
                "--solvers",
                "random",
                "--budget",
                "100",
                "--top-k",
                "1",
                "--set",
                "batch=1",
                "--jobs",
                "1",
                "--quiet",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    study = json.loads((out / "study.json").read_text())
    assert len(study["jobs"]) == 1
    assert main(["verify", str(out / study["jobs"][0]["dir"] / "summary-001.json")]) == 0
