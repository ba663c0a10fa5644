"""Agents trained with CrowdNav_DSRNN: its checkpoints, its DS-RNN network and the world its config describes.

CrowdNav_DSRNN saves a plain ``state_dict`` of its ``Policy`` module (``base.*``: the SRNN network, ``dist.*``: the
Gaussian head). It is recognised by those parameter names. The model folder holds ``checkpoints/N.pt`` and
``configs/config.py``; the config is read without running it (its assignments are parsed) and turned into the
Foil world the agent was trained in. A value Foil cannot reproduce is refused with its line.

The network is rebuilt with the original module names and layers (``nn.GRU`` edge and node RNNs, the attention
score multiplied by ``human_num / sqrt(attention_size)``), so ``load_state_dict`` takes the file as it is and the
deterministic action is the original's mean. The policy feeds it the original observation: the 7-field robot node
(px, py, radius, gx, gy, v_pref, theta, with a holonomic robot's theta fixed at pi/2, as CrowdNav never updates
it), the robot velocity as the temporal edge and each human's position relative to the robot as the spatial
edges. A human outside the robot's field of view is where CrowdNav believes it to be: its last observed position
moved on at its last observed velocity, or (15, 15) if it has not been seen since the episode began.
"""

from __future__ import annotations

import ast
import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from search.crowd.sim.observation import Observation, PolicyState
from search.crowd.sim.world import WorldConfig

UNSEEN_POSITION = (15.0, 15.0)  # CrowdNav's belief about a human not yet seen in an episode
HOLONOMIC_THETA = math.pi / 2  # a holonomic CrowdNav robot keeps the heading it starts with

# Keys of the config that only training, logging or rendering read: parsed, then left alone.
TRAINING_ONLY = {
    "env": {"val_size", "test_size", "seed"},
    "reward": {"gamma"},
    "sim": {"render"},
    "orca": {"time_horizon_obst"},
    "ppo": None,
    "training": None,
}

# config key -> Foil world setting, for keys whose values carry over unchanged
DIRECT = {
    ("env", "time_step"): "dt",
    ("env", "randomize_attributes"): "randomize_attributes",
    ("reward", "success_reward"): "success_reward",
    ("reward", "collision_penalty"): "collision_penalty",
    ("reward", "discomfort_dist_back"): "discomfort_dist",
    ("reward", "discomfort_penalty_factor"): "discomfort_factor",
    ("sim", "circle_radius"): "circle_radius",
    ("sim", "human_num"): "human_num",
    ("humans", "policy"): "human_policy",
    ("humans", "radius"): "human_radius",
    ("humans", "v_pref"): "human_v_pref",
    ("robot", "visible"): "robot_visible",
    ("robot", "radius"): "robot_radius",
    ("robot", "v_pref"): "robot_v_pref",
    ("action_space", "kinematics"): "kinematics",
    ("orca", "neighbor_dist"): "neighbor_dist",
    ("orca", "safety_space"): "safety_space",
    ("orca", "time_horizon"): "time_horizon",
    ("sf", "A"): "sf_a",
    ("sf", "B"): "sf_b",
    ("sf", "KI"): "sf_ki",
}

# config key -> the only value Foil reproduces (the feature it would switch on is not simulated)
FIXED = {
    ("env", "env_name"): "CrowdSimDict-v0",
    ("sim", "group_human"): False,
    ("humans", "visible"): True,
    ("humans", "random_radii"): False,
    ("humans", "random_v_pref"): False,
    ("humans", "random_unobservability"): False,
    ("humans", "random_policy_changing"): False,
    ("robot", "policy"): "srnn",
    ("noise", "add_noise"): False,
}

# keys read together with another one (a chance only counts when its switch is on, ...)
COMPANIONS = {
    ("env", "time_limit"),
    ("reward", "discomfort_dist_front"),
    ("humans", "FOV"),
    ("robot", "FOV"),
    ("humans", "random_goal_changing"),
    ("humans", "goal_change_chance"),
    ("humans", "end_goal_changing"),
    ("humans", "end_goal_change_chance"),
    ("humans", "unobservable_chance"),
    ("noise", "type"),
    ("noise", "magnitude"),
}

# SRNN sizes -> (parameter, axis) that holds them in the state_dict
SIZES = {
    "human_node_rnn_size": ("base.humanNodeRNN.gru.weight_hh_l0", 1),
    "human_human_edge_rnn_size": ("base.humanhumanEdgeRNN_spatial.gru.weight_hh_l0", 1),
    "human_node_input_size": ("base.humanNodeRNN.encoder_linear.weight", 1),
    "human_human_edge_input_size": ("base.humanhumanEdgeRNN_spatial.encoder_linear.weight", 1),
    "human_node_output_size": ("base.humanNodeRNN.output_linear.weight", 0),
    "human_node_embedding_size": ("base.humanNodeRNN.encoder_linear.weight", 0),
    "human_human_edge_embedding_size": ("base.humanhumanEdgeRNN_spatial.encoder_linear.weight", 0),
    "attention_size": ("base.attn.temporal_edge_layer.0.weight", 0),
}


KINDS = {float: "a number", int: "a whole number", bool: "True or False", str: "a string"}


class ConfigError(ValueError):
    """A CrowdNav_DSRNN config that Foil cannot read or reproduce."""


@dataclass(frozen=True)
class CrowdNavConfig:
    """A parsed ``configs/config.py``: every ``section.key = value`` with its line, and what Foil makes of it."""

    path: Path
    values: dict  # (section, key) -> (value, line)
    world: dict  # Foil world settings
    sizes: dict  # SRNN sizes

    def line(self, section: str, key: str) -> int:
        return self.values[section, key][1]


def read_config(path: str | Path) -> CrowdNavConfig:
    """Parse a CrowdNav_DSRNN ``config.py`` (its ``Config`` class body of ``section.key = literal`` lines)
    without executing it, and map it to Foil's world settings; refuse what Foil cannot reproduce."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"no CrowdNav_DSRNN config at {str(path)!r}: a model folder holds "
            "checkpoints/N.pt and configs/config.py (as CrowdNav_DSRNN's training writes it)"
        )
    try:
        tree = ast.parse(path.read_text(), str(path))
    except SyntaxError as error:
        raise ConfigError(f"{path}:{error.lineno}: not valid Python: {error.msg}") from None
    body = next((node.body for node in tree.body if isinstance(node, ast.ClassDef) and node.name == "Config"), None)
    if body is None:
        raise ConfigError(f"{path}: no `class Config` in it; is this a CrowdNav_DSRNN config?")
    values, sections = {}, set()
    for node in body:
        where = f"{path}:{node.lineno}"
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            continue  # a docstring
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1):
            raise ConfigError(f"{where}: expected `section = BaseConfig()` or `section.key = value`")
        target = node.targets[0]
        if isinstance(target, ast.Name):
            if not (isinstance(node.value, ast.Call) and getattr(node.value.func, "id", "") == "BaseConfig"):
                raise ConfigError(f"{where}: expected `{target.id} = BaseConfig()`")
            sections.add(target.id)
            continue
        if not (
            isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id in sections
        ):
            raise ConfigError(f"{where}: expected `section.key = value` for a section made by BaseConfig()")
        try:
            value = ast.literal_eval(node.value)
        except ValueError:
            raise ConfigError(
                f"{where}: {target.value.id}.{target.attr} is not a plain value (number, string, "
                "True/False/None); Foil reads the config without running it"
            ) from None
        values[target.value.id, target.attr] = (value, node.lineno)
    return _interpret(CrowdNavConfig(path, values, {}, {}))


def _interpret(config: CrowdNavConfig) -> CrowdNavConfig:
    values, path = config.values, config.path

    def fail(key: tuple[str, str], message: str):
        raise ConfigError(f"{path}:{values[key][1]}: {key[0]}.{key[1]} = {values[key][0]!r}: {message}")

    def get(section: str, key: str, default=None):
        return values.get((section, key), (default, 0))[0]

    for key in values:
        section, name = key
        known = (
            key in DIRECT
            or key in FIXED
            or key in COMPANIONS
            or (section == "SRNN" and name in SIZES)
            or (section in TRAINING_ONLY and (TRAINING_ONLY[section] is None or name in TRAINING_ONLY[section]))
        )
        if not known:
            fail(key, "Foil does not know this setting, so it cannot reproduce the world it describes")
    for key, wanted in FIXED.items():
        if key in values and values[key][0] != wanted:
            fail(key, f"Foil reproduces only {wanted!r}")
    for key in (("env", "time_limit"), ("env", "time_step"), ("sim", "human_num")):
        if key not in values:
            raise ConfigError(f"{path}: {key[0]}.{key[1]} is missing")

    world, defaults = {}, WorldConfig()
    for key, name in DIRECT.items():
        if key not in values:
            continue
        value, kind = values[key][0], type(getattr(defaults, name))
        if kind is float and isinstance(value, int | float) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not kind:
            fail(key, f"expected {KINDS[kind]} (Foil's world setting {name})")
        try:
            WorldConfig(**{name: value})
        except ValueError as error:
            fail(key, str(error))
        world[name] = value
    if not float(get("env", "time_limit")) > 1:
        fail(("env", "time_limit"), "must be more than 1 s: CrowdNav ends an episode at time_limit - 1")
    # CrowdNav ends an episode once its clock reaches time_limit - 1 (checked before each move)
    world["time_limit"] = float(get("env", "time_limit")) - 1
    front, back = get("reward", "discomfort_dist_front"), get("reward", "discomfort_dist_back")
    if front is not None and back is not None and front != back:
        fail(
            ("reward", "discomfort_dist_front"),
            f"Foil has one discomfort distance; this differs from discomfort_dist_back = {back!r}",
        )
    for section, name in (("humans", "human_fov"), ("robot", "robot_fov")):
        if (section, "FOV") in values:
            fov = get(section, "FOV")
            if isinstance(fov, bool) or not isinstance(fov, int | float) or not 0 < fov <= 2:
                fail((section, "FOV"), "expected a field of view in multiples of pi, above 0 and at most 2")
            world[name] = float(fov) * 180.0
    world["goal_change_chance"] = (
        float(get("humans", "goal_change_chance", 0.0)) if get("humans", "random_goal_changing", False) else 0.0
    )
    world["end_goal_change_chance"] = (
        float(get("humans", "end_goal_change_chance", 0.0)) if get("humans", "end_goal_changing", False) else 0.0
    )
    if world.get("kinematics") == "unicycle":  # its own motion, and CrowdNav's start for a unicycle
        world |= {"unicycle_motion": "arc", "robot_start": "circle"}
    try:
        WorldConfig.from_dict(world)
    except (ValueError, TypeError) as error:
        raise ConfigError(f"{path}: the world it describes is not one Foil can build: {error}") from None
    sizes = {key[1]: value for key, (value, _) in values.items() if key[0] == "SRNN"}
    return CrowdNavConfig(path, values, world, sizes)


def is_crowdnav_state_dict(data) -> bool:
    """Whether ``data`` is a CrowdNav_DSRNN policy's state_dict (by its parameter names)."""
    return isinstance(data, dict) and "base.humanNodeRNN.gru.weight_hh_l0" in data and "dist.fc_mean.weight" in data


def is_crowdnav_file(path: str | Path) -> bool:
    """Whether a file holds a CrowdNav_DSRNN checkpoint (read once per file version)."""
    path = Path(path).resolve()
    return _is_crowdnav_file(path, path.stat().st_mtime_ns)


@functools.cache
def _is_crowdnav_file(path: Path, mtime_ns: int) -> bool:
    try:
        return is_crowdnav_state_dict(torch.load(path, map_location="cpu", weights_only=True))
    except Exception:  # not a plain state_dict (a Foil checkpoint, TorchScript, anything else)
        return False


def config_path(checkpoint: str | Path) -> Path:
    """Where a checkpoint's config lies: MODEL/checkpoints/N.pt -> MODEL/configs/config.py."""
    return Path(checkpoint).absolute().parent.parent / "configs" / "config.py"


class _EdgeRNN(nn.Module):
    def __init__(self, inputs: int, embed: int, hidden: int):
        super().__init__()
        self.encoder_linear = nn.Linear(inputs, embed)
        self.gru = nn.GRU(embed, hidden)

    def forward(self, x: Tensor, h: Tensor) -> Tensor:
        """One step for a batch (N, inputs) from hidden states (N, hidden): the new hidden states."""
        return self.gru(torch.relu(self.encoder_linear(x))[None], h[None])[1][0]


class _NodeRNN(nn.Module):
    def __init__(self, inputs: int, embed: int, edge_hidden: int, hidden: int, outputs: int):
        super().__init__()
        self.encoder_linear = nn.Linear(inputs, embed)
        self.edge_embed = nn.Linear(edge_hidden, embed)  # in the original too, unused
        self.edge_attention_embed = nn.Linear(2 * edge_hidden, embed)
        self.output_linear = nn.Linear(hidden, outputs)
        self.gru = nn.GRU(2 * embed, hidden)


class _Attention(nn.Module):
    def __init__(self, edge_hidden: int, attention: int):
        super().__init__()
        self.temporal_edge_layer = nn.ModuleList([nn.Linear(edge_hidden, attention)])
        self.spatial_edge_layer = nn.ModuleList([nn.Linear(edge_hidden, attention)])


class _SRNN(nn.Module):
    def __init__(self, s: dict):
        super().__init__()
        edge, node, out = s["human_human_edge_rnn_size"], s["human_node_rnn_size"], s["human_node_output_size"]
        self.humanNodeRNN = _NodeRNN(s["human_node_input_size"], s["human_node_embedding_size"], edge, node, out)
        self.humanhumanEdgeRNN_spatial = _EdgeRNN(
            s["human_human_edge_input_size"], s["human_human_edge_embedding_size"], edge
        )
        self.humanhumanEdgeRNN_temporal = _EdgeRNN(
            s["human_human_edge_input_size"], s["human_human_edge_embedding_size"], edge
        )
        self.attn = _Attention(edge, s["attention_size"])
        self.actor = nn.Sequential(nn.Linear(out, out), nn.Tanh(), nn.Linear(out, out), nn.Tanh())
        self.critic = nn.Sequential(nn.Linear(out, out), nn.Tanh(), nn.Linear(out, out), nn.Tanh())
        self.critic_linear = nn.Linear(out, 1)
        self.robot_linear = nn.Linear(7, s["human_node_input_size"])
        self.human_node_final_linear = nn.Linear(out, 2)  # in the original too, unused


class _AddBias(nn.Module):
    def __init__(self, size: int):
        super().__init__()
        self._bias = nn.Parameter(torch.zeros(size, 1))


class _Gaussian(nn.Module):
    def __init__(self, inputs: int):
        super().__init__()
        self.fc_mean = nn.Linear(inputs, 2)
        self.logstd = _AddBias(2)


class CrowdNavNetwork(nn.Module):
    """CrowdNav_DSRNN's ``Policy`` (SRNN base and Gaussian head) for acting: one step, deterministic."""

    def __init__(self, sizes: dict, human_num: int):
        super().__init__()
        self.sizes, self.human_num = dict(sizes), human_num
        self.base = _SRNN(sizes)
        self.dist = _Gaussian(sizes["human_node_output_size"])

    def initial_state(self, batch: int) -> tuple[Tensor, Tensor]:
        """Zero hidden states: edges (B, 1 + human_num, edge size; the temporal edge first), node (B, node)."""
        return (
            torch.zeros(batch, 1 + self.human_num, self.sizes["human_human_edge_rnn_size"]),
            torch.zeros(batch, self.sizes["human_node_rnn_size"]),
        )

    def forward(
        self,
        robot_node: Tensor,
        temporal_edges: Tensor,
        spatial_edges: Tensor,
        edge_hidden: Tensor,
        node_hidden: Tensor,
    ) -> tuple[Tensor, Tensor, Tensor]:
        """(B, 7), (B, 2), (B, human_num, 2) and hidden states -> action means (B, 2) and new hidden states."""
        base, (b, n) = self.base, spatial_edges.shape[:2]
        temporal = base.humanhumanEdgeRNN_temporal(temporal_edges, edge_hidden[:, 0])
        spatial = base.humanhumanEdgeRNN_spatial(
            spatial_edges.reshape(b * n, -1), edge_hidden[:, 1:].reshape(b * n, -1)
        ).reshape(b, n, -1)
        query = base.attn.temporal_edge_layer[0](temporal)
        keys = base.attn.spatial_edge_layer[0](spatial)
        scores = (query[:, None, :] * keys).sum(-1) * (n / np.sqrt(self.sizes["attention_size"]))
        attended = torch.bmm(spatial.permute(0, 2, 1), torch.softmax(scores, dim=-1)[..., None])[..., 0]
        node = base.humanNodeRNN
        encoded = torch.relu(node.encoder_linear(base.robot_linear(robot_node)))
        edges = torch.relu(node.edge_attention_embed(torch.cat([temporal, attended], -1)))
        node_hidden = node.gru(torch.cat([encoded, edges], -1)[None], node_hidden[None])[1][0]
        action = self.dist.fc_mean(base.actor(node.output_linear(node_hidden)))
        return action, torch.cat([temporal[:, None], spatial], 1), node_hidden


class CrowdNavPolicy:
    """A CrowdNav_DSRNN agent behind Foil's Policy interface, observing as CrowdNav_DSRNN does."""

    def __init__(self, net: CrowdNavNetwork, config: CrowdNavConfig, name: str, checkpoint: Path):
        net.eval()
        self.net, self.config, self.name, self.checkpoint = net, config, name, checkpoint
        self.world = dict(config.world)
        self.human_num, self.dt = net.human_num, config.world["dt"]
        self.holonomic = config.world.get("kinematics", "holonomic") == "holonomic"

    def initial_state(self, batch: int) -> PolicyState:
        edges, node = self.net.initial_state(batch)
        return {
            "edges": edges.numpy(),
            "node": node.numpy(),
            "believed": np.zeros((batch, self.human_num, 4)),
            "started": np.zeros(batch, bool),
        }

    def act(self, observation: Observation, state: PolicyState) -> tuple[np.ndarray, PolicyState]:
        n = observation.human_mask.shape[1]
        if n != self.human_num:
            raise ValueError(
                f"agent {self.name} was trained by CrowdNav_DSRNN with exactly {self.human_num} humans (sim.human_num "
                f"at {self.config.path}:{self.config.line('sim', 'human_num')}), and its network takes that many; "
                f"this world has {n}: use a scenario with {self.human_num} humans"
            )
        robot = observation.robot_node[:, :7].copy()
        if self.holonomic:
            robot[:, 6] = HOLONOMIC_THETA
        position = observation.robot_node[:, None, :2]
        observed = np.concatenate([position + observation.spatial_edges, observation.human_velocities], axis=-1)
        believed = state["believed"]
        moved_on = np.concatenate([believed[..., :2] + believed[..., 2:] * self.dt, believed[..., 2:]], axis=-1)
        unseen = np.where(state["started"][:, None, None], moved_on, [*UNSEEN_POSITION, 0.0, 0.0])
        believed = np.where(observation.human_mask[..., None], observed, unseen)
        with torch.no_grad():
            action, edges, node = self.net(
                torch.from_numpy(robot.astype(np.float32)),
                torch.from_numpy(observation.temporal_edges.astype(np.float32)),
                torch.from_numpy((believed[..., :2] - position).astype(np.float32)),
                torch.from_numpy(state["edges"]),
                torch.from_numpy(state["node"]),
            )
        return action.numpy().astype(np.float64), {
            "edges": edges.numpy(),
            "node": node.numpy(),
            "believed": believed,
            "started": np.ones_like(state["started"]),
        }


def network_sizes(state_dict: dict, config: CrowdNavConfig) -> dict:
    """The SRNN sizes the weights have, checked against the config's."""
    sizes = {name: int(state_dict[key].shape[axis]) for name, (key, axis) in SIZES.items() if key in state_dict}
    for name, size in sizes.items():
        written = config.sizes.get(name)
        if written is not None and written != size:
            raise ConfigError(
                f"{config.path}:{config.line('SRNN', name)}: SRNN.{name} = {written!r}, but the "
                f"checkpoint's weights have {size}: the config is not this checkpoint's"
            )
    return sizes


def load_crowdnav(path: str | Path, state_dict: dict, name: str) -> CrowdNavPolicy:
    """The policy of a CrowdNav_DSRNN checkpoint whose state_dict is already read, with its model folder's config."""
    path = Path(path)
    config = read_crowdnav_config(path)
    try:
        sizes = network_sizes(state_dict, config)
        net = CrowdNavNetwork(sizes, int(config.world["human_num"]))
        net.load_state_dict(state_dict)
    except (KeyError, RuntimeError) as error:
        raise ValueError(
            f"{path}: looks like a CrowdNav_DSRNN checkpoint but its weights do not fit the DS-RNN network: {error}"
        ) from None
    return CrowdNavPolicy(net, config, name, path)


def read_crowdnav_config(checkpoint: str | Path) -> CrowdNavConfig:
    """The config of the model folder a checkpoint lies in."""
    where = config_path(checkpoint)
    if not where.is_file():
        raise FileNotFoundError(
            f"{checkpoint} is a CrowdNav_DSRNN checkpoint, but its model folder has no "
            f"configs/config.py (looked for {where}); Foil needs it to rebuild the world the "
            "agent was trained in: keep the folder as CrowdNav_DSRNN writes it (MODEL/"
            "checkpoints/N.pt beside MODEL/configs/config.py)"
        )
    return _cached_config(where, where.stat().st_mtime_ns)


@functools.cache
def _cached_config(path: Path, mtime_ns: int) -> CrowdNavConfig:
    return read_config(path)
