"""The project as a wheel, installed with its base dependencies only into a fresh virtual environment, is the
survey server: it serves pages and static files (templates, static files and migrations ship inside the package;
nothing is read from the source tree), exports and reports, without torch, numba or matplotlib; the offline
commands say which extra to install. The install is real: pip fetches the dependencies from the package index (or
its cache)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import httpx
import pytest

from tests.support.live_server import free_port
from tests.support.survey import ADMIN_PASSWORD, log_in, start, study_text

REPO = Path(__file__).resolve().parents[2]
SOURCES = ["app", "search", "migrations", "templates", "static", "pyproject.toml", "README.md"]
LEFT_OUT = ("torch", "numba", "matplotlib")  # what the server-only install must not bring


def run(*command, cwd: Path, env: dict, check: bool = True) -> subprocess.CompletedProcess:
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert not check or done.returncode == 0, f"{' '.join(map(str, command))}:\n{done.stdout}\n{done.stderr}"
    return done


def build_wheel(folder: Path, env: dict) -> Path:
    """The wheel of a copy of the sources, so that building leaves the checkout as it is."""
    source = folder / "source"
    for name in SOURCES:
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copyfile(REPO / name, source / name)
    dist = folder / "dist"
    run(
        sys.executable,
        "-m",
        "pip",
        "wheel",
        "--no-deps",
        "--no-build-isolation",
        "--wheel-dir",
        dist,
        ".",
        cwd=source,
        env=env,
    )
    shutil.rmtree(source)
    (wheel,) = dist.glob("foil-*.whl")
    return wheel


@pytest.mark.slow
def test_the_server_only_install_serves_exports_and_reports(tmp_path, bundle_dir):
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH" and not key.startswith("FOIL_")}
    wheel = build_wheel(tmp_path, env)
    venv = tmp_path / "venv"
    run(sys.executable, "-m", "venv", venv, cwd=tmp_path, env=env)
    python, foil = venv / "bin" / "python", venv / "bin" / "foil"
    run(python, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", wheel, cwd=tmp_path, env=env)

    site = run(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])", cwd=tmp_path, env=env)
    installed = run(python, "-c", "import app; print(app.__file__)", cwd=tmp_path, env=env).stdout
    assert installed.startswith(site.stdout.strip()), installed
    found = run(
        python,
        "-c",
        f"import importlib.util as u; print([m for m in {LEFT_OUT!r} if u.find_spec(m)])",
        cwd=tmp_path,
        env=env,
    )
    assert found.stdout.strip() == "[]"

    listed = run(foil, "--help", cwd=tmp_path, env=env).stdout
    assert all(
        f"    {name} " in listed for name in ("train", "eval", "serve", "export", "report", "simulate", "search")
    )
    refused = run(
        foil,
        "search",
        "--agents",
        "lo,hi",
        "--scenario",
        "paper-bl-tr",
        "--out",
        "out",
        cwd=tmp_path,
        env=env,
        check=False,
    )
    assert refused.returncode == 2 and not (tmp_path / "out").exists()
    (line,) = refused.stderr.splitlines()
    assert (
        line.startswith("foil search: error: this install has the survey server only")
        and "pip install 'foil[search]'" in line
    )

    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    database = f"sqlite:///{tmp_path / 'survey.sqlite3'}"
    port = free_port()
    with (tmp_path / "server.log").open("w") as log:
        server = subprocess.Popen(
            [foil, "serve", "--bundle", bundle_dir, "--study", study, "--db", database, "--port", str(port)],
            cwd=tmp_path,
            env={**env, "FOIL_ADMIN_PASSWORD": ADMIN_PASSWORD},
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
        with httpx.Client(base_url=url, follow_redirects=True, timeout=30) as client:
            start(client)  # one participant, to report on
            assert log_in(client).status_code == 200
            report = client.get("/admin/report")
        assert report.status_code == 200 and "Table 1" in report.text and "<svg" not in report.text
        assert "pip install &#39;foil[figures]&#39;" in report.text
    finally:
        server.terminate()
        server.wait(timeout=30)

    exported = run(foil, "export", "--db", database, "--out", "export", cwd=tmp_path, env=env)
    assert (tmp_path / "export" / "long.csv").is_file() and (tmp_path / "export" / "codebook.md").is_file(), (
        exported.stdout
    )
    reported = run(foil, "report", "--db", database, "--out", "report", cwd=tmp_path, env=env)
    assert "1 participant," in reported.stdout and "pip install 'foil[figures]'" in reported.stderr
    html = (tmp_path / "report" / "report.html").read_text()
    assert "pip install &#39;foil[figures]&#39;" in html and (tmp_path / "report" / "table1.csv").is_file()
    assert not list((tmp_path / "report").glob("*.png"))


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
    mapped = {"app.templates": "templates", "app.static": "static"}  # the package-dir table
    for data in listed - packages:  # folders of data alone, each one real
        top = next((name for name in mapped if data == name or data.startswith(name + ".")), None)
        parts = data.removeprefix(top).split(".")[1:] if top else data.split(".")
        folder = (REPO / mapped[top] if top else REPO) / Path(*parts)
        assert folder.is_dir() and not (folder / "__init__.py").exists(), data
