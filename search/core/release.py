"""What every world's ``foil release`` shares: the error for a run its agents cannot be chosen from, and the
validation table a later release reuses."""

from __future__ import annotations

import csv
from pathlib import Path

# The columns every world's validation table starts with: the snapshot, its training steps and its reward's mean
# with the 95% interval over the validation episodes; a world adds the rates it chooses by.
VALIDATION_COLUMNS = ("checkpoint", "env_steps", "episodes", "reward_mean", "reward_low", "reward_high")


class ReleaseError(ValueError):
    """A run from which a world's shipped agents cannot be chosen; the message says why and what to do."""


def write_rows(path: Path, columns: tuple[str, ...], rows: list[dict[str, object]]) -> None:
    """A validation table as CSV, so a later release reuses the snapshots already validated."""
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, columns)
        writer.writeheader()
        writer.writerows(rows)
