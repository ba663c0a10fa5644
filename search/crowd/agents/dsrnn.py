"""DS-RNN (Liu et al. 2021, as in CrowdNav_DSRNN) with masked humans, and the policy that wraps it.

The network: the robot node (``ROBOT_NODE_FIELDS``: CrowdNav_DSRNN's seven fields plus the goal relative to the
robot) goes through a linear to 3 and a 3->embed encoder; the temporal edge (robot
velocity) and every spatial edge (human minus robot position) go through their own linear + GRU; one attention
head weighs the spatial edges against the temporal edge; a node GRU takes the robot and edge features; actor and
critic MLPs (tanh) sit on the node output; the action is a diagonal Gaussian with a learned, state-independent
log-std, and its mean is the deterministic action.

Unlike the original, every human shares one spatial-edge GRU and absent humans are masked out of the attention
(and their hidden state held at zero), so one checkpoint works for any crowd of up to ``max_humans``. The
attention score is divided by sqrt(attention size) rather than multiplied by the number of humans (the
original's scaling would change the policy with the crowd size).

Checkpoints are ``torch.save`` dicts with ``format`` = ``foil.dsrnn/2``, the ``network`` sizes, the
``observation`` layout the network reads (its robot-node fields) and the ``model`` weights (training checkpoints
add optimiser and run state). Format 1 networks read an older observation and are refused with what to do.
"""

from __future__ import annotations

import functools
import math
import warnings
import zipfile
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from search.core.settings import ConfigTable
from search.crowd.sim.observation import ROBOT_NODE_FIELDS, ROBOT_NODE_SIZE, Observation, PolicyState

CHECKPOINT_FORMAT = "foil.dsrnn/2"
OBSERVATION_LAYOUT = {"robot_node": list(ROBOT_NODE_FIELDS)}


@dataclass(frozen=True)
class NetworkConfig(ConfigTable):
    """Layer sizes. Defaults: the paper's full-size DS-RNN."""

    what = "network"

    max_humans: int = 10
    edge_hidden: int = 256
    node_hidden: int = 128
    embed: int = 64
    attention: int = 64
    mlp_hidden: int = 256

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"network setting {f.name} must be a positive integer, got {value!r}")


def _init(layer: nn.Linear, gain: float = math.sqrt(2)) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


def _gru(inputs: int, hidden: int) -> nn.GRUCell:
    cell = nn.GRUCell(inputs, hidden)
    for name, param in cell.named_parameters():
        (nn.init.orthogonal_ if "weight" in name else nn.init.zeros_)(param)
    return cell


def _mlp(inputs: int, hidden: int) -> nn.Sequential:
    return nn.Sequential(_init(nn.Linear(inputs, hidden)), nn.Tanh(), _init(nn.Linear(hidden, hidden)), nn.Tanh())


def _gru_forward_steps(
    gates_in: Tensor,
    h0: Tensor,
    weight_t: Tensor,
    bias_hh: Tensor,
    keep: Tensor,
    out_mask: Tensor | None,
    previous: Tensor,
    outputs: Tensor,
    rz: Tensor,
    n: Tensor,
    gh_n: Tensor,
) -> None:
    """The forward recurrence of ``_GRUSequence``, filling the (T, R, ...) buffers it is given."""
    hidden = h0.shape[1]
    h = h0
    for t in range(gates_in.shape[0]):
        h_prev = previous[t]
        torch.mul(h, keep[t, :, None], out=h_prev)
        gh = torch.mm(h_prev.to(weight_t.dtype), weight_t).float().add_(bias_hh)
        torch.sigmoid(gates_in[t, :, : 2 * hidden] + gh[:, : 2 * hidden], out=rz[t])
        torch.tanh(torch.addcmul(gates_in[t, :, 2 * hidden :], rz[t, :, :hidden], gh[:, 2 * hidden :]), out=n[t])
        h = torch.lerp(n[t], h_prev, rz[t, :, hidden:], out=outputs[t])  # (1 - z) n + z h_prev
        if out_mask is not None:
            h.mul_(out_mask[t, :, None])
        gh_n[t] = gh[:, 2 * hidden :]


def _gru_backward_steps(
    grad_outputs: Tensor,
    dn_dh: Tensor,
    dz_dh: Tensor,
    dr_dn: Tensor,
    r: Tensor,
    z_masked: Tensor,
    keep: Tensor,
    weight: Tensor,
    grad_gh: Tensor,
    grad_n: Tensor,
) -> Tensor:
    """The backward recurrence of ``_GRUSequence``: fills ``grad_gh`` and ``grad_n``, returns the gradient at h0."""
    steps, rows, hidden = grad_n.shape
    carry = torch.zeros_like(grad_n[0])
    for i in range(steps):
        t = steps - 1 - i
        dh = grad_outputs[t] + carry
        torch.mul(dh, dn_dh[t], out=grad_n[t])
        torch.mul(grad_n[t], dr_dn[t], out=grad_gh[t, :, :hidden])
        torch.mul(dh, dz_dh[t], out=grad_gh[t, :, hidden : 2 * hidden])
        torch.mul(grad_n[t], r[t], out=grad_gh[t, :, 2 * hidden :])
        carry = torch.mm(grad_gh[t].to(weight.dtype), weight).float().addcmul_(dh, z_masked[t])
        carry.mul_(keep[t, :, None])
    return carry


@functools.cache
def _scripted(function):
    """``function`` compiled by TorchScript, once: its loop runs without the Python interpreter's overhead per
    operation (about a fifth of these small recurrences)."""
    with warnings.catch_warnings():  # torch marks TorchScript deprecated
        warnings.simplefilter("ignore", DeprecationWarning)
        return torch.jit.script(function)


class _GRUSequence(torch.autograd.Function):
    """The recurrent half of a GRU cell (same equations as ``nn.GRUCell``) over a whole sequence.

    ``gates_in`` (T, R, 3H) are the input projections, computed outside as one product for all steps. Before
    each step the previous hidden state is multiplied by ``keep`` (T, R), 0 at an episode start, and each new
    state by ``out_mask`` (T, R) when given (absent humans keep a zero state). Per step, forward and backward
    do one product with W_hh each and a few elementwise operations; the weight gradient and the gates'
    derivatives are whole-sequence operations. ``dtype`` is the products' precision; the state and the gate
    arithmetic stay float32."""

    @staticmethod
    def forward(ctx, gates_in, h0, weight_hh, bias_hh, keep, out_mask, dtype):
        steps, (rows, hidden) = gates_in.shape[0], h0.shape
        ctx.dtype, ctx.input_dtype = dtype, gates_in.dtype
        gates_in = gates_in.float()
        previous = gates_in.new_empty(steps, rows, hidden)  # each step's h_prev, for the weight gradient
        outputs = torch.empty_like(previous)
        rz = gates_in.new_empty(steps, rows, 2 * hidden)  # reset and update gates
        n = torch.empty_like(previous)  # candidate state
        gh_n = torch.empty_like(previous)  # W_hn h_prev + b_hn, which the reset gate multiplies
        _scripted(_gru_forward_steps)(
            gates_in, h0.float(), weight_hh.t().to(dtype), bias_hh, keep, out_mask, previous, outputs, rz, n, gh_n
        )
        ctx.save_for_backward(weight_hh, keep, out_mask, previous, rz, n, gh_n)
        return outputs

    @staticmethod
    def backward(ctx, grad_outputs):
        weight_hh, keep, out_mask, previous, rz, n, gh_n = ctx.saved_tensors
        steps, rows, hidden = previous.shape
        r, z = rz[..., :hidden], rz[..., hidden:]
        # d(pre-activation)/dh for the candidate, update and reset gates, with the mask folded in
        mask = 1.0 if out_mask is None else out_mask[..., None]
        dn_dh = (1 - z) * (1 - n * n) * mask
        dz_dh = (previous - n) * z * (1 - z) * mask
        dr_dn = gh_n * r * (1 - r)
        grad_gh = previous.new_empty(steps, rows, 3 * hidden)  # gradient at W_hh h_prev + b_hh
        grad_n = torch.empty_like(previous)  # gradient at the candidate's input pre-activation
        carry = _scripted(_gru_backward_steps)(
            grad_outputs.contiguous(), dn_dh, dz_dh, dr_dn, r, z * mask, keep, weight_hh.to(ctx.dtype), grad_gh, grad_n
        )
        flat = grad_gh.reshape(steps * rows, 3 * hidden)
        grad_weight = torch.mm(flat.t().to(ctx.dtype), previous.reshape(steps * rows, hidden).to(ctx.dtype))
        grad_gates_in = torch.cat([grad_gh[..., : 2 * hidden], grad_n], dim=-1)
        return grad_gates_in.to(ctx.input_dtype), carry, grad_weight.float(), flat.sum(0), None, None, None


def gru_sequence(cell: nn.GRUCell, inputs: Tensor, h0: Tensor, keep: Tensor, out_mask: Tensor | None = None) -> Tensor:
    """``cell`` run over ``inputs`` (T, R, I) from ``h0`` (R, H), as described in ``_GRUSequence``: (T, R, H)."""
    autocast = torch.is_autocast_enabled("cpu")
    dtype = torch.get_autocast_dtype("cpu") if autocast else torch.float32
    gates_in = nn.functional.linear(inputs, cell.weight_ih, cell.bias_ih)
    with torch.autocast("cpu", enabled=False):
        return _GRUSequence.apply(gates_in, h0, cell.weight_hh, cell.bias_hh, keep, out_mask, dtype)


class DSRNN(nn.Module):
    """One step at a time (``step``) for acting, or a sequence with episode starts (``forward``) for PPO."""

    def __init__(self, config: NetworkConfig | None = None):
        super().__init__()
        self.config = c = config or NetworkConfig()
        self.max_humans = c.max_humans
        self.robot_linear = _init(nn.Linear(ROBOT_NODE_SIZE, 3))
        self.robot_encoder = _init(nn.Linear(3, c.embed))
        self.temporal_embed = _init(nn.Linear(2, c.embed))
        self.temporal_gru = _gru(c.embed, c.edge_hidden)
        self.spatial_embed = _init(nn.Linear(2, c.embed))
        self.spatial_gru = _gru(c.embed, c.edge_hidden)
        self.attention_temporal = _init(nn.Linear(c.edge_hidden, c.attention))
        self.attention_spatial = _init(nn.Linear(c.edge_hidden, c.attention))
        self.edge_features = _init(nn.Linear(2 * c.edge_hidden, c.embed))
        self.node_gru = _gru(2 * c.embed, c.node_hidden)
        self.output_linear = _init(nn.Linear(c.node_hidden, c.mlp_hidden))
        self.actor = _mlp(c.mlp_hidden, c.mlp_hidden)
        self.critic = _mlp(c.mlp_hidden, c.mlp_hidden)
        self.critic_linear = _init(nn.Linear(c.mlp_hidden, 1), 1.0)
        self.action_mean = _init(nn.Linear(c.mlp_hidden, 2), 0.01)
        self.action_logstd = nn.Parameter(torch.zeros(2))
        self.attention_scale = 1.0 / math.sqrt(c.attention)

    @torch.jit.export
    def initial_state(self, batch: int) -> list[Tensor]:
        """Zero hidden states: temporal edge (B, He), spatial edges (B, max_humans, He), node (B, Hn)."""
        edge, node = self.temporal_gru.hidden_size, self.node_gru.hidden_size
        return [torch.zeros(batch, edge), torch.zeros(batch, self.max_humans, edge), torch.zeros(batch, node)]

    def step(
        self,
        robot_node: Tensor,
        temporal_edges: Tensor,
        spatial_edges: Tensor,
        human_mask: Tensor,
        hidden: list[Tensor],
    ) -> tuple[Tensor, list[Tensor]]:
        """One time step for B robots with humans padded to max_humans: the (B, mlp_hidden) features and the
        new hidden states. ``human_mask`` (B, n) is 1 for a present human, 0 for padding."""
        b, n = human_mask.shape
        temporal_h = self.temporal_gru(torch.relu(self.temporal_embed(temporal_edges)), hidden[0])
        spatial_in = torch.relu(self.spatial_embed(spatial_edges)).reshape(b * n, -1)
        spatial_h = self.spatial_gru(spatial_in, hidden[1].reshape(b * n, -1)).reshape(b, n, -1)
        spatial_h = spatial_h * human_mask.unsqueeze(-1)

        query = self.attention_temporal(temporal_h).unsqueeze(1)  # (B, 1, A)
        keys = self.attention_spatial(spatial_h)  # (B, n, A)
        scores = (query * keys).sum(-1) * self.attention_scale
        weights = torch.softmax(scores.masked_fill(human_mask == 0, -1e9), dim=1) * human_mask
        attended = (weights.unsqueeze(-1) * spatial_h).sum(1)  # (B, He); zero when nobody is there

        edges = torch.relu(self.edge_features(torch.cat([temporal_h, attended], dim=1)))
        robot = torch.relu(self.robot_encoder(self.robot_linear(robot_node)))
        node_h = self.node_gru(torch.cat([robot, edges], dim=1), hidden[2])
        return self.output_linear(node_h), [temporal_h, spatial_h, node_h]

    @torch.jit.unused  # training only; a TorchScript agent file holds the acting step
    def forward(
        self,
        robot_node: Tensor,
        temporal_edges: Tensor,
        spatial_edges: Tensor,
        human_mask: Tensor,
        episode_start: Tensor,
        hidden: list[Tensor],
    ) -> tuple[Tensor, Tensor, list[Tensor]]:
        """A (T, B, ...) sequence; hidden states are zeroed where ``episode_start`` (T, B) is 1.
        Returns action means (T, B, 2), values (T, B) and the final hidden states.

        The same function as ``step`` applied T times, arranged for training speed: everything but the GRUs'
        recurrences (none of which feeds back into the edges or the attention) runs once over all T steps.
        Inside a CPU ``torch.autocast`` region the matrix products run in its lower precision (bfloat16) while
        hidden states, gate arithmetic and outputs stay float32."""
        t, b, n = human_mask.shape
        keep = 1.0 - episode_start
        if t == 1:  # a rollout step: the acting step costs less than the sequence machinery
            hidden = [h * keep[0].reshape((-1,) + (1,) * (h.dim() - 1)) for h in hidden]
            x, hidden = self.step(robot_node[0], temporal_edges[0], spatial_edges[0], human_mask[0], hidden)
            return self._heads(x[None]) + (hidden,)
        temporal_h = gru_sequence(self.temporal_gru, torch.relu(self.temporal_embed(temporal_edges)), hidden[0], keep)
        spatial_in = torch.relu(self.spatial_embed(spatial_edges)).reshape(t, b * n, -1)
        spatial_h = gru_sequence(
            self.spatial_gru,
            spatial_in,
            hidden[1].reshape(b * n, -1),
            keep.repeat_interleave(n, dim=1),
            human_mask.reshape(t, b * n),
        ).reshape(t, b, n, -1)

        query = self.attention_temporal(temporal_h).unsqueeze(2)  # (T, B, 1, A)
        keys = self.attention_spatial(spatial_h)  # (T, B, n, A)
        scores = (query * keys).sum(-1).float() * self.attention_scale
        weights = torch.softmax(scores.masked_fill(human_mask == 0, -1e9), dim=2) * human_mask
        attended = (weights.unsqueeze(-1) * spatial_h).sum(2)  # (T, B, He)

        edges = torch.relu(self.edge_features(torch.cat([temporal_h, attended], dim=2)))
        robot = torch.relu(self.robot_encoder(self.robot_linear(robot_node)))
        node_h = gru_sequence(self.node_gru, torch.cat([robot, edges.to(robot.dtype)], dim=2), hidden[2], keep)
        return self._heads(self.output_linear(node_h)) + ([temporal_h[-1], spatial_h[-1], node_h[-1]],)

    def _heads(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """Action means and values from node features, in float32 whatever the products' precision."""
        return self.action_mean(self.actor(x)).float(), self.critic_linear(self.critic(x)).squeeze(-1).float()

    def act_mean(
        self,
        robot_node: Tensor,
        temporal_edges: Tensor,
        spatial_edges: Tensor,
        human_mask: Tensor,
        hidden: list[Tensor],
    ) -> tuple[Tensor, list[Tensor]]:
        """The deterministic action (B, 2) and new hidden states: what evaluation and search use."""
        x, hidden = self.step(robot_node, temporal_edges, spatial_edges, human_mask, hidden)
        return self.action_mean(self.actor(x)), hidden


class _TorchScriptEntry(nn.Module):
    """What a TorchScript agent file holds: ``forward`` = the deterministic step, plus ``initial_state``."""

    def __init__(self, net: DSRNN):
        super().__init__()
        self.net = net
        self.max_humans = net.max_humans

    @torch.jit.export
    def initial_state(self, batch: int) -> list[Tensor]:
        return self.net.initial_state(batch)

    def forward(
        self,
        robot_node: Tensor,
        temporal_edges: Tensor,
        spatial_edges: Tensor,
        human_mask: Tensor,
        hidden: list[Tensor],
    ) -> tuple[Tensor, list[Tensor]]:
        return self.net.act_mean(robot_node, temporal_edges, spatial_edges, human_mask, hidden)


def observation_tensors(observation: Observation, max_humans: int | None) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """The observation as float32 tensors, humans padded (and masked) up to ``max_humans`` when given."""
    b, n = observation.human_mask.shape
    max_humans = n if max_humans is None else max_humans
    if n > max_humans:
        raise ValueError(f"this agent handles at most {max_humans} humans, the observation has {n}")
    spatial = np.asarray(observation.spatial_edges, np.float32)
    mask = np.asarray(observation.human_mask, np.float32)
    if n < max_humans:
        spatial = np.concatenate([spatial, np.zeros((b, max_humans - n, 2), np.float32)], axis=1)
        mask = np.concatenate([mask, np.zeros((b, max_humans - n), np.float32)], axis=1)
    return (
        torch.from_numpy(np.asarray(observation.robot_node, np.float32)),
        torch.from_numpy(np.asarray(observation.temporal_edges, np.float32)),
        torch.from_numpy(np.ascontiguousarray(spatial)),
        torch.from_numpy(np.ascontiguousarray(mask)),
    )


class TorchPolicy:
    """A recurrent torch module behind the Policy interface: the module's ``forward(robot_node, temporal_edges,
    spatial_edges, human_mask, hidden) -> (action, hidden)`` and ``initial_state(batch) -> hidden`` (hidden: a
    list of tensors with the batch axis first). Humans are padded up to ``max_humans`` when the module has a
    fixed maximum. The state dict holds the hidden tensors as numpy arrays (h0, h1, ...), so a snapshot is an
    array copy."""

    def __init__(self, module, name: str, max_humans: int | None):
        self.module, self.name, self.max_humans = module, name, max_humans
        self.forward = module  # DSRNNPolicy calls the network's method directly, skipping one module call

    def initial_state(self, batch: int) -> PolicyState:
        with torch.no_grad():
            return {f"h{i}": h.numpy().copy() for i, h in enumerate(self.module.initial_state(batch))}

    def act(self, observation: Observation, state: PolicyState) -> tuple[np.ndarray, PolicyState]:
        inputs = observation_tensors(observation, self.max_humans)
        hidden = [torch.from_numpy(state[f"h{i}"]) for i in range(len(state))]
        with torch.no_grad():
            action, hidden = self.forward(*inputs, hidden)
        return action.numpy().astype(np.float64), {f"h{i}": h.numpy() for i, h in enumerate(hidden)}


class DSRNNPolicy(TorchPolicy):
    """A DS-RNN network acting deterministically (its Gaussian's mean)."""

    def __init__(self, net: DSRNN, name: str = "dsrnn"):
        net.eval()
        super().__init__(net, name, net.max_humans)
        self.forward = net.act_mean
        self.net = net

    def value(self, observation: Observation, state: PolicyState) -> np.ndarray:
        """(B,) the critic's value of the state the observation shows, after the memory ``state`` holds (the
        state is left as it was)."""
        inputs = observation_tensors(observation, self.max_humans)
        hidden = [torch.from_numpy(state[f"h{i}"]) for i in range(len(state))]
        with torch.no_grad():
            x, _ = self.net.step(*inputs, hidden)
            return self.net._heads(x)[1].numpy().astype(np.float64)


def save_checkpoint(path: str | Path, net: DSRNN, **extra) -> None:
    """Write a checkpoint that ``load_dsrnn`` reads; ``extra`` holds training state (steps, optimiser, ...)."""
    path = Path(path)
    partial = path.with_name(path.name + ".partial")  # a run killed while saving keeps its last good checkpoint
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "network": asdict(net.config),
            "observation": OBSERVATION_LAYOUT,
            "model": net.state_dict(),
            **extra,
        },
        partial,
    )
    partial.replace(path)


def _torch_file(path: str | Path):
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {str(path)!r}")
    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except Exception as error:  # torch raises many kinds for a file that is not a checkpoint
        raise ValueError(f"{path} is not a readable torch checkpoint: {error}") from None


def read_checkpoint(path: str | Path, data=None) -> dict:
    """A checkpoint's contents (``data``, when already loaded from ``path``), after checking it is one."""
    data = _torch_file(path) if data is None else data
    if isinstance(data, dict) and data and all(isinstance(v, torch.Tensor) for v in data.values()):
        names = ", ".join(list(data)[:3])
        raise ValueError(
            f"{path} is not a Foil DS-RNN checkpoint (format {CHECKPOINT_FORMAT!r}) nor CrowdNav_DSRNN's "
            f"DS-RNN policy (parameters base.humanNodeRNN..., dist.fc_mean...): it is the state_dict of "
            f"another network (parameters {names}, ...)"
        )
    if not isinstance(data, dict) or not str(data.get("format", "")).startswith("foil.dsrnn/"):
        raise ValueError(f"{path} is not a Foil DS-RNN checkpoint (expected format {CHECKPOINT_FORMAT!r})")
    if data["format"] != CHECKPOINT_FORMAT or data.get("observation") != OBSERVATION_LAYOUT:
        fields_read = (data.get("observation") or {}).get("robot_node") or ROBOT_NODE_FIELDS[:7]  # format 1's
        raise ValueError(
            f"{path} is a {data['format']} checkpoint whose network reads an older observation (robot node "
            f"{' '.join(map(str, fields_read))}); this version of "
            f"Foil observes the goal relative to the robot as well ({' '.join(ROBOT_NODE_FIELDS)}). Retrain it with "
            "`foil train` (the shipped agents lo, med and hi are already of this version)"
        )
    return data


def load_dsrnn(path: str | Path, data=None) -> DSRNN:
    """The network stored in a checkpoint, with clear errors for wrong sizes."""
    data = read_checkpoint(path, data)
    net = DSRNN(NetworkConfig.from_dict(data["network"]))
    try:
        net.load_state_dict(data["model"])
    except RuntimeError as error:
        raise ValueError(f"{path}: weights do not fit the network sizes {data['network']}: {error}") from None
    return net


def is_torchscript(path: str | Path) -> bool:
    """TorchScript archives carry compiled code next to their constants; torch.save files do not."""
    try:
        with zipfile.ZipFile(path) as archive:
            return any(name.endswith("/constants.pkl") for name in archive.namelist())
    except (zipfile.BadZipFile, OSError):
        return False


def export_torchscript(net: DSRNN, path: str | Path) -> None:
    """Save the deterministic policy as a TorchScript file that loads without Foil's code."""
    net.eval()
    with warnings.catch_warnings():  # torch marks TorchScript deprecated; it is still the portable format here
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.jit.save(torch.jit.script(_TorchScriptEntry(net)), str(path))


def load_torchscript(path: str | Path, name: str) -> TorchPolicy:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        module = torch.jit.load(str(path), map_location="cpu")
    if not hasattr(module, "initial_state"):
        raise ValueError(f"{path}: a TorchScript agent needs an exported initial_state(batch) method")
    return TorchPolicy(module, name, getattr(module, "max_humans", None))


def load_checkpoint_policy(path: str | Path, name: str | None = None):
    """A policy from a Foil checkpoint, a TorchScript file or a CrowdNav_DSRNN checkpoint (recognised by its
    parameter names; see ``search.crowd.agents.crowdnav``)."""
    from search.crowd.agents.crowdnav import is_crowdnav_state_dict, load_crowdnav

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no agent file at {str(path)!r}")
    name = name or path.stem
    if is_torchscript(path):
        return load_torchscript(path, name)
    data = _torch_file(path)
    if is_crowdnav_state_dict(data):
        return load_crowdnav(path, data, name)
    return DSRNNPolicy(load_dsrnn(path, data), name)
