"""Offline side of Foil: crowd world, coupled simulator, agents, search, rendering and bundles.

Attributes are imported on first use so that `foil --help` and the survey server start without numba or torch.
"""

from importlib import import_module

_EXPORTS = {
    "orca_step": "search.sim.orca",
    "orca_velocities": "search.sim.orca",
}


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'search' has no attribute {name!r}")
