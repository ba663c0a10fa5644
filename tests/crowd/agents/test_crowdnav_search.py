"""An imported CrowdNav_DSRNN agent through `foil search` and `foil verify`, compared with a shipped one in the
world its config describes."""

import json

from search.cli import main
from tests.support.crowdnav import HUMANS, SCENARIO, write_model


def test_search_and_verify_with_an_imported_agent(tmp_path, capsys):
    checkpoint = str(write_model(tmp_path / "model"))
    (tmp_path / "three.toml").write_text(SCENARIO)
    out = tmp_path / "out"
    assert (
        main(
            [
                "search",
                "--agents",
                f"{checkpoint},hi",
                "--scenario",
                str(tmp_path / "three.toml"),
                "--budget",
                "300",
                "--top-k",
                "2",
                "--reward",
                "horizon_steps=40",
                "--world",
                "time_limit=10",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((out / "summary-001.json").read_text())
    world = summary["scenario"]["world"]
    assert world["human_num"] == HUMANS and world["goal_change_chance"] == 0.25 and world["randomize_attributes"]
    assert world["human_v_pref"] == 1.0 and world["time_limit"] == 10.0  # its config's world; the command line wins
    assert [a["name"] for a in summary["agents"]] == [checkpoint, "hi"]
    capsys.readouterr()
    assert main(["verify", *(str(p) for p in sorted(out.glob("summary-*.json")))]) == 0
    assert capsys.readouterr().out.count("reproduced exactly") == 2


def test_a_scenario_with_another_crowd_size_is_refused(tmp_path, capsys):
    checkpoint = str(write_model(tmp_path / "model"))
    assert (
        main(
            [
                "search",
                "--agents",
                f"{checkpoint},hi",
                "--scenario",
                "paper-bl-tr",
                "--budget",
                "50",
                "--out",
                str(tmp_path / "out"),
                "--quiet",
            ]
        )
        == 2
    )
    assert f"exactly {HUMANS} humans" in capsys.readouterr().err


def test_the_representative_solver_draws_states_in_the_imported_agents_world(tmp_path):
    checkpoint = str(write_model(tmp_path / "model"))
    out = tmp_path / "out"
    assert (
        main(
            [
                "search",
                "--agents",
                f"{checkpoint},goal",
                "--scenario",
                "training",
                "--solver",
                "representative",
                "--set",
                "states=2",
                "--set",
                "pushes=2",
                "--set",
                "batch_states=2",
                "--budget",
                "400",
                "--top-k",
                "1",
                "--reward",
                "horizon_steps=20",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    summary = json.loads((out / "summary-001.json").read_text())
    assert len(summary["scenario"]["humans"]) == HUMANS  # drawn with the agent's crowd size, not the default 10
    assert summary["scenario"]["world"]["goal_change_chance"] == 0.25
    assert main(["verify", str(out / "summary-001.json")]) == 0
