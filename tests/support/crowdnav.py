"""CrowdNav_DSRNN model folders written the way its training writes them (MODEL/checkpoints/N.pt, a plain
state_dict with the original parameter names, and MODEL/configs/config.py), with small networks."""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import torch

# SRNN sizes of the small test networks (the published model: 128, 256, 3, 2, 256, 64, 64, 64)
SIZES = {
    "human_node_rnn_size": 6,
    "human_human_edge_rnn_size": 8,
    "human_node_input_size": 3,
    "human_human_edge_input_size": 2,
    "human_node_output_size": 7,
    "human_node_embedding_size": 4,
    "human_human_edge_embedding_size": 4,
    "attention_size": 5,
}
HUMANS = 3

# Every section and key of CrowdNav_DSRNN's example config, with its values (human_num and SRNN sizes aside).
CONFIG = {
    "env": {
        "env_name": "CrowdSimDict-v0",
        "time_limit": 50,
        "time_step": 0.25,
        "val_size": 100,
        "test_size": 500,
        "randomize_attributes": True,
        "seed": 0,
    },
    "reward": {
        "success_reward": 10,
        "collision_penalty": -20,
        "discomfort_dist_front": 0.25,
        "discomfort_dist_back": 0.25,
        "discomfort_penalty_factor": 10,
        "gamma": 0.99,
    },
    "sim": {"render": False, "circle_radius": 6, "human_num": HUMANS, "group_human": False},
    "humans": {
        "visible": True,
        "policy": "orca",
        "radius": 0.3,
        "v_pref": 1,
        "FOV": 2.0,
        "random_goal_changing": True,
        "goal_change_chance": 0.25,
        "end_goal_changing": True,
        "end_goal_change_chance": 1.0,
        "random_radii": False,
        "random_v_pref": False,
        "random_unobservability": False,
        "unobservable_chance": 0.3,
        "random_policy_changing": False,
    },
    "robot": {"visible": False, "policy": "srnn", "radius": 0.3, "v_pref": 1, "FOV": 2.0},
    "noise": {"add_noise": False, "type": "uniform", "magnitude": 0.1},
    "action_space": {"kinematics": "holonomic"},
    "orca": {"neighbor_dist": 10, "safety_space": 0.15, "time_horizon": 5, "time_horizon_obst": 5},
    "sf": {"A": 2.0, "B": 1, "KI": 1},
    "ppo": {
        "num_mini_batch": 2,
        "num_steps": 30,
        "recurrent_policy": True,
        "epoch": 5,
        "clip_param": 0.2,
        "value_loss_coef": 0.5,
        "entropy_coef": 0.0,
        "use_gae": True,
        "gae_lambda": 0.95,
    },
    "SRNN": dict(SIZES),
    "training": {
        "lr": 4e-5,
        "eps": 1e-5,
        "alpha": 0.99,
        "max_grad_norm": 0.5,
        "num_env_steps": 10e6,
        "use_linear_lr_decay": False,
        "save_interval": 200,
        "log_interval": 20,
        "use_proper_time_limits": False,
        "cuda_deterministic": False,
        "cuda": True,
        "num_processes": 12,
        "output_dir": "data/dummy",
        "resume": False,
        "load_path": None,
        "overwrite": True,
        "num_threads": 1,
    },
}


def config_text(config: dict = CONFIG) -> str:
    """A config.py as CrowdNav_DSRNN writes it: a Config class of sections with one assignment per line."""
    lines = [
        "import numpy as np",
        "",
        "",
        "class BaseConfig(object):",
        "    def __init__(self):",
        "        pass",
        "",
        "",
        "class Config(object):",
    ]
    for section, values in config.items():
        lines.append(f"    {section} = BaseConfig()")
        lines += [f"    {section}.{key} = {value!r}  # comment" for key, value in values.items()]
        lines.append("")
    return "\n".join(lines) + "\n"


def parameter_shapes(s: dict = SIZES) -> dict[str, tuple[int, ...]]:
    """The original Policy's parameters (SRNN base and Gaussian head), by name, in its state_dict order."""
    node, edge, out = s["human_node_rnn_size"], s["human_human_edge_rnn_size"], s["human_node_output_size"]
    embed, edge_embed, att = s["human_node_embedding_size"], s["human_human_edge_embedding_size"], s["attention_size"]
    shapes = {
        "base.humanNodeRNN.gru.weight_ih_l0": (3 * node, 2 * embed),
        "base.humanNodeRNN.gru.weight_hh_l0": (3 * node, node),
        "base.humanNodeRNN.gru.bias_ih_l0": (3 * node,),
        "base.humanNodeRNN.gru.bias_hh_l0": (3 * node,),
        "base.humanNodeRNN.encoder_linear.weight": (embed, s["human_node_input_size"]),
        "base.humanNodeRNN.encoder_linear.bias": (embed,),
        "base.humanNodeRNN.edge_embed.weight": (embed, edge),
        "base.humanNodeRNN.edge_embed.bias": (embed,),
        "base.humanNodeRNN.edge_attention_embed.weight": (embed, 2 * edge),
        "base.humanNodeRNN.edge_attention_embed.bias": (embed,),
        "base.humanNodeRNN.output_linear.weight": (out, node),
        "base.humanNodeRNN.output_linear.bias": (out,),
    }
    for kind in ("spatial", "temporal"):
        prefix = f"base.humanhumanEdgeRNN_{kind}."
        shapes |= {
            prefix + "gru.weight_ih_l0": (3 * edge, edge_embed),
            prefix + "gru.weight_hh_l0": (3 * edge, edge),
            prefix + "gru.bias_ih_l0": (3 * edge,),
            prefix + "gru.bias_hh_l0": (3 * edge,),
            prefix + "encoder_linear.weight": (edge_embed, s["human_human_edge_input_size"]),
            prefix + "encoder_linear.bias": (edge_embed,),
        }
    for layer in ("temporal_edge_layer", "spatial_edge_layer"):
        shapes |= {f"base.attn.{layer}.0.weight": (att, edge), f"base.attn.{layer}.0.bias": (att,)}
    for mlp in ("actor", "critic"):
        for i in (0, 2):
            shapes |= {f"base.{mlp}.{i}.weight": (out, out), f"base.{mlp}.{i}.bias": (out,)}
    shapes |= {
        "base.critic_linear.weight": (1, out),
        "base.critic_linear.bias": (1,),
        "base.robot_linear.weight": (s["human_node_input_size"], 7),
        "base.robot_linear.bias": (s["human_node_input_size"],),
        "base.human_node_final_linear.weight": (2, out),
        "base.human_node_final_linear.bias": (2,),
        "dist.fc_mean.weight": (2, out),
        "dist.fc_mean.bias": (2,),
        "dist.logstd._bias": (2, 1),
    }
    return shapes


def random_state_dict(seed: int = 0, sizes: dict = SIZES) -> OrderedDict:
    generator = torch.Generator().manual_seed(seed)
    return OrderedDict(
        (name, torch.randn(shape, generator=generator) * 0.7) for name, shape in parameter_shapes(sizes).items()
    )


def write_model(
    folder: Path, seed: int = 0, legacy: bool = True, config: dict = CONFIG, state_dict: OrderedDict | None = None
) -> Path:
    """MODEL/checkpoints/100.pt (PyTorch's legacy serialisation, as the published model, or the zip one) and
    MODEL/configs/config.py; returns the checkpoint's path."""
    (folder / "checkpoints").mkdir(parents=True, exist_ok=True)
    (folder / "configs").mkdir(exist_ok=True)
    (folder / "configs" / "config.py").write_text(config_text(config))
    checkpoint = folder / "checkpoints" / "100.pt"
    torch.save(
        random_state_dict(seed) if state_dict is None else state_dict,
        checkpoint,
        _use_new_zipfile_serialization=not legacy,
    )
    return checkpoint


# A three-human scenario for the imported agents' searches and bundles.
SCENARIO = """name = "three"
[robot]
start = [-4.0, -4.0]
goal = [4.0, 4.0]
[[humans]]
position = [6.0, 0.0]
[[humans]]
position = [-3.0, 5.2]
[[humans]]
position = [0.0, -6.0]
"""
