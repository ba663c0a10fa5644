"""Lengths of time in seconds where seconds are meant: a disagreement's clip (horizon), a HIGHLIGHTS moment
(context) and the gap between moments are given in seconds in a study file and on the command line, converted by
the world's step length, and in steps where asked (NAME_steps). The crowd's defaults (2.5 s, 10 steps of 0.25 s)
are what they were in steps; a world of 0.5 s steps gets 5."""

from __future__ import annotations

import json
import warnings

import pytest

from search.bundle.spec import BuildError, parse_build
from search.cli import main
from search.core.settings import FEWEST_STEPS, ShortLength, in_steps
from search.solvers.disagreements import DisagreementsConfig
from search.solvers.highlights import HighlightsConfig, HighlightsDivConfig

FAST, SLOW = "tests.gym.test_gym_clips:fast", "tests.gym.test_gym_clips:slow"  # a track of 0.5 s steps


@pytest.fixture
def track(tmp_path, monkeypatch):
    (tmp_path / "track.toml").write_text('adapter = "tests.gym.test_gym_clips:TrackAdapter"\nseed = 3\n')
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_seconds_become_steps_by_the_worlds_step_length():
    assert in_steps(DisagreementsConfig, {"horizon": 4.0}, 0.5) == {"horizon": 8}
    assert in_steps(DisagreementsConfig, {"horizon_steps": 3, "episodes": 2}, 0.5) == {"horizon": 3, "episodes": 2}
    assert in_steps(HighlightsConfig, {}, 0.05, defaults=True) == {"context": 50, "gap": 50}  # 2.5 s at 20 Hz
    assert in_steps(HighlightsConfig, {}, 0.25, defaults=True) == {"context": 10, "gap": 10}  # the crowd's
    with pytest.raises(ValueError, match="horizon in seconds or horizon_steps in steps, not both"):
        in_steps(DisagreementsConfig, {"horizon": 2.0, "horizon_steps": 4}, 0.5)
    with pytest.raises(ValueError, match=r"context = 0.1 s is less than one step of 0.25 s .* context_steps"):
        in_steps(HighlightsConfig, {"context": 0.1}, 0.25)


def test_a_default_length_is_never_too_few_steps_and_a_short_given_one_warns():
    """2.5 s is 2 steps of a world of 1-s steps: the default is then the fewest steps a moment reads in, and a
    length given in seconds that short warns, naming the setting and how to keep it."""
    assert in_steps(HighlightsConfig, {}, 1.0, defaults=True) == {"context": FEWEST_STEPS, "gap": FEWEST_STEPS}
    assert in_steps(DisagreementsConfig, {}, 1.0, defaults=True) == {"horizon": FEWEST_STEPS}
    with pytest.warns(ShortLength, match=r"context = 2.0 s is only 2 steps of 1 s in this world.*context_steps = 2"):
        assert in_steps(HighlightsConfig, {"context": 2.0}, 1.0) == {"context": 2}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # given in steps: taken as it is
        assert in_steps(HighlightsConfig, {"context_steps": 2}, 1.0) == {"context": 2}


def search(solver: str, *settings: str) -> dict:
    """The solver's parameters as run.json records them, after `foil search` on the track."""
    args = ["--budget", "200", "--top-k", "1", "--reward", "horizon_steps=6", "--out", "out", "--quiet", *settings]
    assert main(["search", "--agents", f"{FAST},{SLOW}", "--scenario", "track.toml", "--solver", solver, *args]) == 0
    with open("out/run.json") as file:
        return json.load(file)["solver"]["parameters"]


def test_the_command_line_takes_seconds_and_steps_where_asked(track, capsys):
    assert search("disagreements")["horizon"] == 5  # the default 2.5 s
    assert search("disagreements", "--set", "horizon=4")["horizon"] == 8
    assert search("disagreements", "--set", "horizon_steps=3")["horizon"] == 3
    found = search("highlights", "--set", "context=1.5", "--set", "gap_steps=4", "--set", "lookahead=2")
    assert (found["context"], found["gap"], found["lookahead"]) == (3, 4, 2)  # lookahead is a number of steps
    assert "foil search: warning: context = 1.5 s is only 3 steps of 0.5 s" in capsys.readouterr().err


def test_the_reward_horizon_is_seconds_on_the_command_line_and_in_a_study(track):
    def horizon(*reward: str) -> int:
        args = ["--budget", "200", "--top-k", "1", "--solver", "nfirst", "--out", "out", "--quiet", *reward]
        assert main(["search", "--agents", f"{FAST},{SLOW}", "--scenario", "track.toml", *args]) == 0
        with open("out/run.json") as file:
            return json.load(file)["reward_parameters"]["horizon"]

    assert horizon("--reward", "horizon=3") == 6 and horizon("--reward", "horizon_steps=3") == 3  # 0.5 s a step
    assert horizon() == 100  # the default, in steps
    scheme = build("track.toml", [FAST, SLOW], "", "nfirst").replace(
        "seed = 0\n", "seed = 0\nreward = {{ horizon = 4 }}\n"
    )
    assert parse_build(scheme.replace("{{", "{").replace("}}", "}")).schemes["method"].reward.horizon == 8


def test_a_horizon_longer_than_an_episode_names_the_change_to_seconds(tmp_path, monkeypatch, capsys):
    """`--reward horizon=250`, meant as steps before lengths became seconds, asks for 250 s of a crowd whose episodes
    end at 50 s: refused before any work, naming the change and horizon_steps."""
    monkeypatch.chdir(tmp_path)
    args = ["--agents", "goal,orca", "--scenario", "paper-bl-tr", "--solver", "nfirst", "--budget", "50"]
    assert main(["search", *args, "--reward", "horizon=250", "--out", "out", "--quiet"]) == 2
    error = capsys.readouterr().err
    assert "the reward's horizon is 1000 steps (250 s), longer than an episode here (50 s)" in error
    assert "horizon_steps = N" in error and not (tmp_path / "out").exists()
    assert main(["search", *args, "--reward", "horizon_steps=150", "--out", "out", "--quiet"]) == 0  # 37.5 s


def test_a_representative_vote_may_not_choose_a_clip_longer_than_an_episode(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["--agents", "goal,orca", "--scenario", "training", "--solver", "representative", "--budget", "500"]
    assert main(["search", *args, "--reward", "horizon=10", "--set", "longest=60", "--out", "out", "--quiet"]) == 2
    error = capsys.readouterr().err
    assert "the representative solver's longest clip is 240 steps (60 s), longer than an episode here (50 s)" in error
    assert not (tmp_path / "out").exists()


def test_the_command_line_refuses_steps_of_what_is_no_length_of_time(track, capsys):
    assert main(["search", "--agents", f"{FAST},{SLOW}", "--scenario", "track.toml", "--solver", "highlights",
                 "--set", "lookahead_steps=2", "--out", "out", "--quiet"]) == 2  # fmt: skip
    assert "bad solver setting 'lookahead_steps=2'" in capsys.readouterr().err


def build(scenario: str, agents: list[str], settings: str, solver: str = "disagreements", budget: str = "") -> str:
    return f"""
[build]
seed = 1
{budget}
[build.schemes.method]
solver = "{solver}"
budget = 100
seed = 0
settings = {{ {settings} }}

[[build.sets]]
parts = ["pairwise"]
schemes = ["method"]
scenarios = ["{scenario}"]
agents = {json.dumps(agents)}
"""


def test_a_study_gives_seconds_and_the_crowd_keeps_its_defaults(track):
    def config(settings: str, solver: str = "disagreements", scenario: str = "track.toml", agents=(FAST, SLOW)):
        return parse_build(build(scenario, list(agents), settings, solver)).schemes["method"].solver_config

    assert config("").horizon == 5 and config("horizon = 4").horizon == 8 and config("horizon_steps = 4").horizon == 4
    assert (config("context = 1", "highlights-div").context, config("", "highlights-div").gap) == (2, 5)
    crowd = {"scenario": "training", "agents": ("lo", "hi")}
    assert config("", **crowd) == DisagreementsConfig()  # 2.5 s of 0.25 s steps: the 10 steps of before
    assert config("", "highlights-div", **crowd) == HighlightsDivConfig()


def test_a_study_is_refused_a_length_shorter_than_a_step_or_given_twice(track):
    with pytest.raises(BuildError, match=r"horizon = 0.2 s is less than one step of 0.5 s"):
        parse_build(build("track.toml", [FAST, SLOW], "horizon = 0.2"))
    with pytest.raises(BuildError, match="not both"):
        parse_build(build("track.toml", [FAST, SLOW], "context = 2, context_steps = 4", "highlights"))


def test_a_clip_length_holds_a_moment_given_in_steps_too(track):
    """[build.budget] clip_seconds fixes a disagreement's horizon: one given in steps that differs is refused."""
    held = "[build.budget]\nclip_seconds = 4"
    spec = parse_build(build("track.toml", [FAST, SLOW], "", budget=held))
    assert spec.schemes["method"].solver_config.horizon == 8
    with pytest.raises(BuildError, match="clip_seconds makes horizon 8 steps here"):
        parse_build(build("track.toml", [FAST, SLOW], "horizon_steps = 6", budget=held))
