"""The `foil` command: one help lists the commands of both sides, the server's from app/cli.py; on a server-only
install (no `search` extra) the offline commands are refused with one line naming the extra, and nothing is
written, while the server's commands still run."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest

from app.cli import COMMANDS as SERVER_COMMANDS
from search.cli import OFFLINE_MODULES, build_parser, main
from tests.support.live_server import free_port
from tests.support.survey import study_text

REPO = Path(__file__).resolve().parents[1]
# The fixed command-line contract, in the order `foil --help` lists it.
COMMANDS = [
    "train",
    "release",
    "worlds",
    "eval",
    "serve",
    "export",
    "report",
    "simulate",
    "power",
    "prereg",
    "render",
    "bundle",
    "search",
    "search-all",
    "verify",
]
OFFLINE_RUNS = {
    "train": ["--config", "train.toml", "--out", "run"],
    "release": ["run"],
    "worlds": [],
    "eval": ["lo", "--episodes", "2"],
    "render": ["summary.json", "--out", "clip.mp4"],
    "bundle": ["study.toml", "--out", "bundle"],
    "search": ["--agents", "lo,hi", "--scenario", "paper-bl-tr", "--out", "out", "--budget", "10"],
    "search-all": ["--agents", "lo,hi", "--scenarios", "paper-bl-tr", "--out", "out", "--budget", "10"],
    "verify": ["summary.json"],
}
# A server-only install, made from this environment: these imports are refused as if not installed.
SERVER_ONLY = (
    "import sys\nfor name in {modules!r}: sys.modules[name] = None\nfrom search.cli import main\nsys.exit(main())"
)


def foil_without(modules: tuple[str, ...], *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {key: value for key, value in os.environ.items() if not key.startswith("FOIL_")}
    code = SERVER_ONLY.format(modules=modules)
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        cwd=cwd,
        env={**env, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_one_help_lists_every_command_of_both_sides(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    assert re.findall(r"^    (\S+)", capsys.readouterr().out, re.MULTILINE) == COMMANDS
    commands = next(action for action in build_parser()._actions if action.dest == "command").choices
    owners = {name: parser.get_default("handler").__module__ for name, parser in commands.items()}
    assert {name for name, owner in owners.items() if owner == "app.cli"} == set(SERVER_COMMANDS)
    assert set(owners) - set(SERVER_COMMANDS) == set(OFFLINE_RUNS)
    assert {owners[name] for name in OFFLINE_RUNS} == {"search.cli"}


@pytest.mark.parametrize("command", sorted(OFFLINE_RUNS))
def test_an_offline_command_on_a_server_only_install_names_the_extra(command, tmp_path):
    done = foil_without(("numba", "torch", "matplotlib"), command, *OFFLINE_RUNS[command], cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.splitlines() == [
        f"foil {command}: error: this install has the survey server only (no numba, torch): install the offline side "
        "with pip install 'foil[search]'"
    ]
    assert list(tmp_path.iterdir()) == []


def test_the_server_commands_run_without_the_offline_side(tmp_path, bundle_dir):
    """`foil serve` goes on to check its study (and refuses this one), not to ask for the offline side."""
    study = tmp_path / "study.toml"
    study.write_text(study_text().replace("[build]", "[unknown_table]"))
    port = str(free_port())
    done = foil_without(
        OFFLINE_MODULES, "serve", "--bundle", str(bundle_dir), "--study", str(study), "--port", port, cwd=tmp_path
    )
    assert done.returncode == 2
    assert "foil serve: error:" in done.stderr and "unknown_table" in done.stderr and "foil[search]" not in done.stderr


def test_the_offline_modules_are_what_the_search_extra_installs():
    """search/cli.py checks for the `search` extra by import name; pyproject.toml lists it by distribution."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extra = {
        re.split(r"[<>=!~;\[ ]", requirement)[0].lower() for requirement in project["optional-dependencies"]["search"]
    }
    installed_by = packages_distributions()
    assert {name.lower() for module in OFFLINE_MODULES for name in installed_by[module]} == extra
    assert not extra & {re.split(r"[<>=!~;\[ ]", requirement)[0].lower() for requirement in project["dependencies"]}
