"""A summary written before `foil.summary/2` (the crowd's words for the same keys) is still a summary: it verifies,
renders byte for byte the clip of its `foil.summary/2` form and reads as that form wherever a summary is read, so
every bundle built before the rename still verifies, renders and serves."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from app.formats import SUMMARY_FORMAT, load_summary, summary_json, summary_of
from app.visible import VisibleClip
from search.cli import main
from search.crowd.sim.scenarios import load_scenario
from tests.support.summaries import summary_from_simulation


def first_version(summary: dict) -> dict:
    """``summary`` as `foil.summary/1` wrote it, key for key in the same places, spelt out here on its own."""
    step_keys = {"other_positions": "humans", "agent_positions": "robots", "agent_actions": "robot_actions"}
    return dict(
        summary,
        format="foil.summary/1",
        steps=[{step_keys.get(key, key): value for key, value in step.items()} for step in summary["steps"]],
        outcomes=[
            {"min_human_distance" if key == "min_other_distance" else key: value for key, value in outcome.items()}
            for outcome in summary["outcomes"]
        ],
    )


def digests(folder: Path) -> dict[str, str]:
    return {path.name: hashlib.sha256(path.read_bytes()).hexdigest() for path in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def shared_summary() -> dict:
    """A summary of agents that `foil verify` can load by name (the renderer tests' own hide theirs)."""
    return summary_from_simulation(["goal", "orca"], load_scenario("paper-bl-tr"))


@pytest.fixture
def both_versions(tmp_path, shared_summary) -> tuple[Path, Path]:
    old, new = tmp_path / "old" / "summary.json", tmp_path / "new" / "summary.json"
    for path, summary in ((old, first_version(shared_summary)), (new, shared_summary)):
        path.parent.mkdir()
        path.write_text(json.dumps(summary, indent=1))
    return old, new


def test_new_summaries_name_agents_and_other_movers(shared_summary):
    assert shared_summary["format"] == SUMMARY_FORMAT == "foil.summary/2"
    assert list(shared_summary["steps"][0]) == ["t", "other_positions", "agent_positions", "agent_actions"]
    assert list(shared_summary["outcomes"][0]) == ["event", "time", "path_length", "min_other_distance"]


def test_a_first_version_file_reads_as_the_summary_it_stands_for(both_versions, shared_summary):
    old, _ = both_versions
    assert json.loads(old.read_text())["steps"][0].keys() == {"t", "humans", "robots", "robot_actions"}
    # the same values under the same keys, in the same order: the file a search writes now
    assert summary_json(load_summary(old)) == summary_json(shared_summary)


def test_a_first_version_file_verifies(both_versions, capsys):
    old, _ = both_versions
    assert main(["verify", str(old)]) == 0
    assert capsys.readouterr().out == f"{old}: reproduced exactly\n"


def test_a_first_version_file_renders_the_same_clip_poster_and_sheet(both_versions):
    small = ["--speed", "4", "--width", "320"]
    for path in both_versions:
        assert main(["render", str(path), "--out", str(path.parent / "clip.mp4"), *small]) == 0
    old, new = (digests(path.parent) for path in both_versions)
    assert old.keys() == new.keys() >= {"clip.mp4", "clip.poster.png", "clip.sheet.png"}
    assert {name: old[name] for name in old if name != "summary.json"} == {
        name: new[name] for name in new if name != "summary.json"
    }


def test_a_first_version_clip_is_judged_as_its_new_form(shared_summary):
    """The audit, the bots and the server's ranking outcomes see what the clip shows, from either version."""
    agents, labels = [a["name"] for a in shared_summary["agents"]], ["Robot 1", "Robot 2"]
    old = VisibleClip.of_summary(summary_of(first_version(shared_summary)), agents, labels)
    assert old == VisibleClip.of_summary(shared_summary, agents, labels)
    assert old.to_goal[0] is not None and "min_other_distance" in old.outcomes[0]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"format": "foil.summary/0"}, r"bad\.json: not a summary \(format 'foil\.summary/0', expected"),
        ([], r"bad\.json: not a summary \(format 'list'"),
        ({"format": "foil.summary/1", "steps": {}}, r"bad\.json: steps must be a list of objects"),
        ({"format": "foil.summary/1", "outcomes": [None]}, r"bad\.json: outcomes must be a list of objects"),
    ],
)
def test_what_is_not_a_summary_of_either_version_is_refused_by_name(data, message):
    with pytest.raises(ValueError, match=message):
        summary_of(data, "bad.json")
