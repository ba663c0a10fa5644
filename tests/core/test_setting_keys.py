"""Every reader of settings on the offline side refuses a misspelt key the same way (search.core.settings.check_keys):
the key, what it is a setting of, and the keys it could have been."""

from __future__ import annotations

import re

import pytest

from search.bundle.spec import BuildError, parse_build
from search.clips.render import RenderOptions
from search.crowd.agents.train import load_train_config
from search.crowd.sim.scenarios import load_scenario
from search.crowd.sim.world import WorldConfig
from search.highway.train import load_config as load_highway_config
from search.solvers.mcts import MCTSConfig
from search.solvers.reward import RewardConfig
from search.solvers.runner import parse_settings

BUILD = """\
[build]
seed = 1
[build.render]
fsp = 24
[build.schemes.a]
solver = "mcts"
budget = 10
seed = 0
[build.schemes.a.settings]
explorashun = 3
[build.schemes.a.reward]
horizn = 5
[[build.sets]]
parts = ["pairwise"]
schemes = ["a"]
scenarios = ["paper-bl-tr"]
pairs = [["goal", "orca"]]
"""


def _refused(message: str, key: str, what: str, known: list[str]) -> None:
    assert f"unknown {what}(s) ['{key}']; known {what}s: {sorted(known)}" in message, message


def test_every_settings_reader_names_the_unknown_key_and_the_known_ones(tmp_path):
    world_keys = list(WorldConfig.__dataclass_fields__)
    with pytest.raises(ValueError) as error:
        WorldConfig.from_dict({"speed": 2})
    _refused(str(error.value), "speed", "world setting", world_keys)
    with pytest.raises(ValueError) as error:
        parse_settings(MCTSConfig, ["explorashun=3"], "solver")
    _refused(str(error.value), "explorashun", "solver setting", list(MCTSConfig.__dataclass_fields__))
    train = tmp_path / "train.toml"
    train.write_text("lr = 1\n")
    with pytest.raises(ValueError) as error:
        load_train_config(train)
    assert re.search(
        r"unknown training setting\(s\) \['lr'\]; known training settings: \[.*'learning_rate'", str(error.value)
    )
    train.write_text('domain = "highway"\nlearning_rat = 1\n')
    with pytest.raises(ValueError) as error:
        load_highway_config(train)
    assert str(error.value).startswith(f"{train}: unknown highway training setting(s) ['learning_rat']; known ")
    scenario = tmp_path / "scenario.toml"
    scenario.write_text("[robot]\nstart = [0, 0]\ngoal = [1, 1]\nheadin = 1\n")
    with pytest.raises(ValueError) as error:
        load_scenario(scenario)
    _refused(str(error.value), "headin", "key", ["start", "goal", "heading"])
    assert str(error.value).startswith(f"{scenario}: [robot]: ")


def test_the_build_table_refuses_each_unknown_setting_at_its_line():
    with pytest.raises(BuildError) as error:
        parse_build(BUILD, "study.toml")
    render, solver, reward = str(error.value).splitlines()
    assert render.startswith("study.toml, line 4, build.render.fsp: ")
    _refused(render, "fsp", "render setting", list(RenderOptions.__dataclass_fields__))
    assert solver.startswith("study.toml, line 10, build.schemes.a.settings.explorashun: ")
    _refused(solver, "explorashun", "solver setting", list(MCTSConfig.__dataclass_fields__))
    assert reward.startswith("study.toml, line 12, build.schemes.a.reward.horizn: ")
    _refused(reward, "horizn", "reward setting", [*RewardConfig.__dataclass_fields__, "horizon_steps"])
