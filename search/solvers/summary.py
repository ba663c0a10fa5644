"""Checking summaries (summary.json, defined in `app.formats`) in any domain: ``verify`` builds a summary again
from the file's own inputs (agents, scenario with its full world config, reward parameters, environment actions)
through its domain and compares every number exactly.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from app.formats import load_summary, summary_json

REPLAY_KEYS = ("agents", "scenario", "solver", "reward_parameters", "env_actions")  # what verify needs


def differences(expected: Any, found: Any, where: str = "", limit: int = 10) -> list[str]:
    """Paths at which two JSON values differ (floats compared exactly), at most ``limit``."""
    out: list[str] = []

    def walk(a: Any, b: Any, path: str) -> None:
        if len(out) >= limit:
            return
        if isinstance(a, dict) and isinstance(b, dict):
            for key in sorted(set(a) | set(b)):
                if key not in a or key not in b:
                    out.append(f"{path}.{key}: {'missing' if key not in b else 'unexpected'}")
                else:
                    walk(a[key], b[key], f"{path}.{key}")
        elif isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                out.append(f"{path}: length {len(b)}, re-simulation gives {len(a)}")
            for i, (x, y) in enumerate(zip(a, b, strict=False)):
                walk(x, y, f"{path}[{i}]")
        elif a != b or type(a) is not type(b) and not (isinstance(a, int | float) and isinstance(b, int | float)):
            out.append(f"{path}: file has {b!r}, re-simulation gives {a!r}")

    walk(expected, found, where)
    return out


def verify(path: str | Path) -> list[str]:
    """Re-simulate a summary in its domain; the list of differences is empty when every number is reproduced
    exactly."""
    from search.core.domain import domain_of_summary

    data = load_summary(path)
    missing = [key for key in REPLAY_KEYS if key not in data]
    if missing:
        raise ValueError(f"{path}: summary lacks {missing}; write it again with `foil search`")
    try:
        expected = json.loads(summary_json(domain_of_summary(data).rebuild(data)))
    except (ValueError, KeyError, TypeError) as error:
        return [f"cannot re-simulate: {error}"]
    return differences(expected, data)
