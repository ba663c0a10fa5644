"""The project as a wheel installed into a fresh virtual environment serves the survey: its templates, static files
and migrations ship inside the package, and nothing is read from the source tree. Offline: the wheel is built
without build isolation, and the dependencies come from the interpreter running the tests."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import time
import tomllib
from pathlib import Path

import httpx
import pytest

from tests.support.live_server import free_port
from tests.support.survey import study_text

REPO = Path(__file__).resolve().parents[2]
SOURCES = ["app", "search", "migrations", "pyproject.toml", "README.md"]


def run(*command, cwd: Path, env: dict) -> str:
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{' '.join(map(str, command))}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.mark.slow
def test_an_installed_wheel_serves_pages_and_static_files(tmp_path, bundle_dir):
    source = tmp_path / "source"  # a copy, so that building leaves the checkout as it is
    for name in SOURCES:
        copy = shutil.copytree if (REPO / name).is_dir() else shutil.copyfile
        kwargs = {"ignore": shutil.ignore_patterns("__pycache__")} if (REPO / name).is_dir() else {}
        copy(REPO / name, source / name, **kwargs)
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH" and not key.startswith("FOIL_")}
    run(
        sys.executable,
        "-m",
        "pip",
        "wheel",
        "--no-deps",
        "--no-build-isolation",
        "--wheel-dir",
        tmp_path / "dist",
        ".",
        cwd=source,
        env=env,
    )
    (wheel,) = (tmp_path / "dist").glob("foil-*.whl")

    venv = tmp_path / "venv"
    run(sys.executable, "-m", "venv", "--without-pip", venv, cwd=tmp_path, env=env)
    python = venv / "bin" / "python"
    site = Path(
        run(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])", cwd=tmp_path, env=env).strip()
    )
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")  # after the venv's own
    run(python, "-m", "pip", "install", "--no-deps", "--no-index", wheel, cwd=tmp_path, env=env)
    shutil.rmtree(source)
    installed = run(python, "-c", "import app; print(app.__file__)", cwd=tmp_path, env=env)
    assert installed.startswith(str(site)), installed

    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    port = free_port()
    with (tmp_path / "server.log").open("w") as log:
        server = subprocess.Popen(
            [
                venv / "bin" / "foil",
                "serve",
                "--bundle",
                bundle_dir,
                "--study",
                study,
                "--db",
                f"sqlite:///{tmp_path / 'survey.sqlite3'}",
                "--port",
                str(port),
            ],
            cwd=tmp_path,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    try:
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 60
        while True:
            try:
                page = httpx.get(f"{url}/", timeout=5)
                break
            except httpx.TransportError:
                assert server.poll() is None and time.monotonic() < deadline, (tmp_path / "server.log").read_text()
                time.sleep(0.2)
        assert page.status_code == 200 and 'name="csrf_token"' in page.text and "consent" in page.text.lower()
        style = httpx.get(f"{url}/static/survey.css", timeout=5)
        assert style.status_code == 200 and style.headers["content-type"].startswith("text/css")
        assert style.content == (REPO / "static" / "survey.css").read_bytes()
    finally:
        server.terminate()
        server.wait(timeout=30)


def test_the_wheel_lists_every_package():
    """pyproject.toml names the packages one by one (to map templates/ and static/ into app/): a new package left
    out of the list would be missing from the wheel."""
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["packages"])
    packages = {
        ".".join(init.parent.relative_to(REPO).parts)
        for top in ("app", "search", "migrations")
        for init in (REPO / top).rglob("__init__.py")
    }
    assert packages - listed == set()
    assert listed - packages == {"app.templates", "app.static"}
