"""Scenario files of a Gymnasium world: one starting state (an adapter, its settings and a seed), or a distribution
of starting states (a family of seeds and settings) that the representative solver draws from.

```toml
# a scenario                              # a distribution
adapter = "mypackage.adapters:Push"        adapter = "mypackage.adapters:Push"
seed = 7                                   [distribution]
[settings]                                 seeds = [1000, 2000]        # drawn from 1000 up to 1999
size = 10                                  [distribution.choices]      # optional: settings drawn per state
                                           size = [8, 10, 12]
                                           [settings]                  # settings every state shares
```

A path is read relative to the working directory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.toml_errors import load_toml
from search.core.settings import check_keys
from search.gym.problem import GymScenario

# world = "<name>" names the world a file is for, where its adapter alone leaves it open (search.core.domain)
SCENARIO_KEYS = {"name", "world", "adapter", "seed", "settings", "description"}
DISTRIBUTION_KEYS = {"name", "world", "adapter", "distribution", "settings", "description"}


@dataclass(frozen=True)
class GymDistribution:
    """Starting states drawn from ``seeds`` (first, last + 1), with each ``choices`` setting drawn from its list."""

    name: str
    adapter: str
    seeds: tuple[int, int]
    settings: dict = field(default_factory=dict)
    choices: dict = field(default_factory=dict)
    description: str = ""

    def to_dict(self) -> dict:
        sampled = GymScenario(self.name, self.adapter, self.seeds[0], self.settings, self.description).to_dict()
        del sampled["seed"]
        return sampled | {
            "distribution": {"seeds": list(self.seeds), "choices": {k: list(v) for k, v in self.choices.items()}}
        }

    def with_settings(self, settings: dict) -> GymDistribution:
        return GymDistribution(
            self.name, self.adapter, self.seeds, self.settings | settings, self.choices, self.description
        )

    def sample(self, rng: np.random.Generator, count: int) -> list[GymScenario]:
        """``count`` starting states, each a scenario named after its draw (``traffic#3``)."""
        first, end = self.seeds
        seeds = rng.integers(first, end, count)
        drawn = {key: rng.integers(0, len(values), count) for key, values in sorted(self.choices.items())}
        return [
            GymScenario(
                f"{self.name}#{i}",
                self.adapter,
                int(seeds[i]),
                {key: self.choices[key][int(index[i])] for key, index in drawn.items()} | self.settings,
                f"starting state {i} drawn from {self.name}",
            )
            for i in range(count)
        ]

    @classmethod
    def from_dict(cls, data: dict, source: str) -> GymDistribution:
        try:
            check_keys(data, DISTRIBUTION_KEYS, "key")
            table = data["distribution"]
            check_keys(table, {"seeds", "choices"}, "[distribution] key")
            first, end = (int(s) for s in table["seeds"])
            choices = {str(k): list(v) for k, v in table.get("choices", {}).items()}
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(
                f"{source}: a distribution needs adapter and [distribution] seeds = [first, last + 1] (and may give "
                f"[distribution.choices] of settings, each a list): {error}"
            ) from None
        if end <= first or any(not values for values in choices.values()):
            raise ValueError(f"{source}: seeds = [first, last + 1] with last >= first, and no empty choice list")
        return cls(
            name=str(data.get("name", Path(source).stem)),
            adapter=str(data["adapter"]),
            seeds=(first, end),
            settings=dict(data.get("settings", {})),
            choices=choices,
            description=str(data.get("description", "")),
        )


def gym_file(name: str) -> dict | None:
    """A TOML file's table when it names an adapter (a Gymnasium scenario or distribution), else None."""
    path = Path(name)
    if path.suffix != ".toml" or not path.is_file():
        return None
    data = load_toml(path.read_text(), name)
    return data if "adapter" in data else None


def load_gym_file(name: str) -> GymScenario | GymDistribution:
    """A scenario or distribution file (see the module docstring)."""
    data = gym_file(name)
    if data is None:
        raise ValueError(
            f"{name!r} is not a Gymnasium scenario file: give the path of a .toml file that names its adapter "
            "(adapter = 'module:Class'), read relative to the working directory"
        )
    if "distribution" in data:
        return GymDistribution.from_dict(data, name)
    try:
        check_keys(data, SCENARIO_KEYS, "key")
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None
    return GymScenario.from_dict({"name": Path(name).stem} | data)
