"""PPO training on a tiny world: it learns, it resumes exactly, and its config is checked."""

from __future__ import annotations

import csv

import pytest
import torch

from search.crowd.agents.dsrnn import DSRNN, DSRNNPolicy, load_checkpoint_policy, read_checkpoint
from search.crowd.agents.evaluate import evaluate
from search.crowd.agents.train import PROGRESS_COLUMNS, TrainConfig, load_train_config, train
from search.crowd.sim.world import WorldConfig

pytestmark = pytest.mark.slow  # PPO updates

TINY_WORLD = WorldConfig(human_num=0, circle_radius=2.0, min_start_goal_distance=1.5, time_limit=5.0)
TINY = TrainConfig.from_dict(
    {
        "seed": 0,
        "total_steps": 16 * 20 * 14,
        "num_envs": 16,
        "num_steps": 20,
        "learning_rate": 3e-3,
        "save_every": 5,
        "network": {"max_humans": 1, "edge_hidden": 8, "node_hidden": 16, "embed": 8, "attention": 8, "mlp_hidden": 32},
        "world": TINY_WORLD.to_dict(),
    }
)


def rows(out) -> list[dict]:
    with (out / "progress.csv").open() as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_a_few_updates_improve_the_deterministic_return(tmp_path, precision):
    torch.manual_seed(TINY.seed)
    before = evaluate(DSRNNPolicy(DSRNN(TINY.network)), 100, seed=0, config=TINY_WORLD)
    last = train(TrainConfig.from_dict(TINY.to_dict() | {"precision": precision}), tmp_path, show_progress=False)
    after = evaluate(load_checkpoint_policy(last), 100, seed=0, config=TINY_WORLD)
    assert after["reward_mean"] > before["reward_mean"] + 1.0
    progress = rows(tmp_path)
    assert list(progress[0]) == list(PROGRESS_COLUMNS) and len(progress) == 14
    assert read_checkpoint(last)["env_steps"] == 14 * 16 * 20
    assert sorted(p.name for p in (tmp_path / "checkpoints").glob("*.pt")) == ["000005.pt", "000010.pt", "000014.pt"]


def test_a_resumed_run_matches_an_uninterrupted_one(tmp_path):
    config = TrainConfig.from_dict(TINY.to_dict() | {"total_steps": 16 * 20 * 4, "save_every": 100})
    whole = train(config, tmp_path / "whole", show_progress=False)
    train(config, tmp_path / "parts", show_progress=False, stop_after_updates=2)
    parts = train(config, tmp_path / "parts", show_progress=False)
    a, b = read_checkpoint(whole)["model"], read_checkpoint(parts)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    drop = ("seconds", "steps_per_s")
    assert [{k: v for k, v in r.items() if k not in drop} for r in rows(tmp_path / "whole")] == [
        {k: v for k, v in r.items() if k not in drop} for r in rows(tmp_path / "parts")
    ]


def test_minibatches_split_across_threads_give_the_same_run_up_to_rounding(tmp_path):
    config = TrainConfig.from_dict(TINY.to_dict() | {"total_steps": 16 * 20 * 3, "precision": "float32"})
    one = read_checkpoint(train(config, tmp_path / "one", show_progress=False))["model"]
    split = TrainConfig.from_dict(config.to_dict() | {"threads": 2})
    two = read_checkpoint(train(split, tmp_path / "two", show_progress=False))["model"]
    again = read_checkpoint(train(split, tmp_path / "again", show_progress=False))["model"]
    assert all(torch.equal(two[k], again[k]) for k in two)  # threads add up their gradients in a fixed order
    for k in one:
        torch.testing.assert_close(two[k], one[k], rtol=1e-4, atol=1e-5)
    assert not all(torch.equal(two[k], one[k]) for k in one)  # really another summation order


def test_a_run_can_go_longer_but_not_change_its_config(tmp_path):
    config = TrainConfig.from_dict(TINY.to_dict() | {"total_steps": 16 * 20})
    train(config, tmp_path, show_progress=False)
    with pytest.raises(ValueError, match="different config"):
        train(TrainConfig.from_dict(config.to_dict() | {"learning_rate": 1e-4}), tmp_path, show_progress=False)
    longer = train(
        TrainConfig.from_dict(config.to_dict() | {"total_steps": 16 * 20 * 2}), tmp_path, show_progress=False
    )
    assert read_checkpoint(longer)["update"] == 2 and len(rows(tmp_path)) == 2


def test_config_files_are_checked(tmp_path):
    path = tmp_path / "train.toml"
    path.write_text("num_envs = 8\nlearning_rate = 1e-4\n[network]\nedge_hidden = 32\n[world]\nhuman_num = 5\n")
    config = load_train_config(path)
    assert (config.num_envs, config.network.edge_hidden, config.world.human_num) == (8, 32, 5)
    assert config.network.node_hidden == 128 and config.epochs == 5  # the rest keeps the paper's defaults
    for text, message in [
        ("lr = 1\n", "unknown training setting"),
        ("[network]\nwidth = 3\n", "unknown network"),
        ("num_envs = 3\n", "multiple of minibatches"),
        ("[world]\nhuman_num = 11\n", "max_humans"),
        ("num_envs = \n", "not valid TOML"),
        ("precision = 'half'\n", "precision must be"),
    ]:
        path.write_text(text)
        with pytest.raises(ValueError, match=message):
            load_train_config(path)
    with pytest.raises(FileNotFoundError):
        load_train_config(tmp_path / "missing.toml")


def test_foil_train_command_writes_a_run(tmp_path, capsys):
    from search.cli import main

    config = tmp_path / "train.toml"
    config.write_text(
        "total_steps = 64\nnum_envs = 4\nnum_steps = 16\n"
        "[network]\nmax_humans = 2\nedge_hidden = 8\nnode_hidden = 8\nembed = 4\nattention = 4\n"
        "mlp_hidden = 8\n[world]\nhuman_num = 2\n"
    )
    assert main(["train", "--config", str(config), "--out", str(tmp_path / "run")]) == 0
    assert "000001.pt" in capsys.readouterr().out
    assert len(rows(tmp_path / "run")) == 1
    assert main(["train", "--config", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "run")]) == 2
