"""The Gymnasium and highway worlds build on the world-free core alone: their problems and summaries import in a
process where the crowd's simulator, agents and domain cannot be imported, so neither world depends on the crowd."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CROWD = ("search.crowd", "search.crowd.sim", "search.crowd.agents")
WORLD_FREE = ("search.gym.problem", "search.gym.summary", "search.highway.coupled", "search.solvers.reward")


def test_the_gym_and_highway_problems_import_without_the_crowd():
    code = f"import importlib, sys\nfor name in {CROWD!r}: sys.modules[name] = None\n" + "".join(
        f"importlib.import_module({module!r})\n" for module in WORLD_FREE
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
