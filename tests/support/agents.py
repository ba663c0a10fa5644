"""Small DS-RNN networks and random observations, for the agent tests and benchmarks."""

from __future__ import annotations

import numpy as np
import torch

from search.crowd.agents.dsrnn import DSRNN, NetworkConfig
from search.crowd.sim.observation import ROBOT_NODE_SIZE, Observation

SMALL = NetworkConfig(max_humans=6, edge_hidden=16, node_hidden=12, embed=8, attention=8, mlp_hidden=16)


def make_net(seed: int = 0, config: NetworkConfig = SMALL) -> DSRNN:
    torch.manual_seed(seed)
    net = DSRNN(config)
    with torch.no_grad():  # the action head starts near zero; spread it so outputs depend visibly on inputs
        net.action_mean.weight.normal_()
    return net


def random_observation(batch: int, humans: int, seed: int = 0) -> Observation:
    rng = np.random.default_rng(seed)
    return Observation(
        robot_node=rng.uniform(-5, 5, (batch, ROBOT_NODE_SIZE)),
        temporal_edges=rng.uniform(-1, 1, (batch, 2)),
        spatial_edges=rng.uniform(-4, 4, (batch, humans, 2)),
        human_velocities=rng.uniform(-0.2, 0.2, (batch, humans, 2)),
        human_radii=np.full((batch, humans), 0.3),
        human_mask=np.ones((batch, humans), dtype=bool),
        done=np.zeros(batch, dtype=bool),
    )
