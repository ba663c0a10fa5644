"""`foil serve` end to end: migrations applied, server answering; bad input refused before it starts."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests.support.live_server import REPO, foil, free_port
from tests.support.survey import study_text

pytestmark = pytest.mark.slow  # foil serve processes


def test_foil_serve_migrates_and_serves(tmp_path, bundle_dir):
    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    port = free_port()
    server = foil(
        "serve",
        "--bundle",
        str(bundle_dir),
        "--study",
        str(study),
        "--port",
        str(port),
        cwd=tmp_path,
        env_extra={"FOIL_ADMIN_PASSWORD": "a long enough password"},
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                page = httpx.get(f"http://127.0.0.1:{port}/")
                break
            except httpx.ConnectError:
                assert server.poll() is None, server.stdout.read()
                assert time.monotonic() < deadline, "server did not start"
                time.sleep(0.2)
        assert page.status_code == 200 and "I agree to take part" in page.text
        assert httpx.get(f"http://127.0.0.1:{port}/admin", follow_redirects=False).status_code == 303
        assert (tmp_path / "foil.sqlite3").exists()  # the default database, migrated
    finally:
        server.terminate()
        server.wait(timeout=10)
    said = server.stdout.read()
    assert f"the admin pages are at http://127.0.0.1:{port}/admin" in said
    assert "Running upgrade" not in said and "Context impl" not in said  # no migration chatter


def test_foil_serve_refuses_a_bad_study_with_its_line_even_when_its_port_is_taken(tmp_path, bundle_dir):
    """The study's error, not the port's: a `make demo` serving on the same port changes nothing."""
    study = tmp_path / "study.toml"
    study.write_text(study_text().replace("[build]", "[unknown_table]"))
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = str(taken.getsockname()[1])
        server = foil("serve", "--bundle", str(bundle_dir), "--study", str(study), "--port", port, cwd=tmp_path)
        output, _ = server.communicate(timeout=30)
    assert server.returncode == 2
    assert "foil serve: error:" in output and "unknown_table: unknown key" in output and ", line " in output


def test_a_port_in_use_is_one_line_with_the_port_hint_and_changes_no_database(tmp_path, bundle_dir):
    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        server = foil(
            "serve",
            "--bundle",
            str(bundle_dir),
            "--study",
            str(study),
            "--port",
            str(port),
            "--db",
            f"sqlite:///{tmp_path / 'survey.sqlite3'}",
            cwd=tmp_path,
        )
        output, _ = server.communicate(timeout=60)
    assert server.returncode == 2
    assert output.strip().splitlines() == [
        f"foil serve: error: port {port} on 127.0.0.1 is already in use (another "
        "foil serve?): stop that server or choose another port with --port"
    ]
    assert not (tmp_path / "survey.sqlite3").exists()  # nothing migrated


def test_make_demo_prints_a_generated_admin_password_and_serves_with_it(tmp_path):
    """A newcomer's `make demo` says how to open the admin pages: a password generated once, kept beside the bundle
    (readable by its owner only) and printed at every start; FOIL_ADMIN_PASSWORD, when set, wins."""
    demo = tmp_path / "bundles" / "demo"
    env = {key: value for key, value in os.environ.items() if key != "FOIL_ADMIN_PASSWORD"}

    def make(*args: str, **extra: str) -> str:
        return subprocess.run(
            ["make", "-s", *args, f"DEMO_BUNDLE={demo}"],
            cwd=REPO,
            env={**env, **extra},
            capture_output=True,
            text=True,
            check=True,
        ).stdout

    first = make("demo-password")
    saved = Path(f"{demo}.admin-password")
    password = saved.read_text().strip()
    assert len(password) >= 12 and (saved.stat().st_mode & 0o777) == 0o600
    assert f"Admin pages: http://127.0.0.1:8000/admin, password: {password}" in first
    assert make("demo-password") == first  # the same password at every start
    assert "FOIL_ADMIN_PASSWORD" in make("demo-password", FOIL_ADMIN_PASSWORD="chosen by me")
    served = make("-n", "demo", f"VENV={Path(sys.executable).parent.parent}")
    assert f'FOIL_ADMIN_PASSWORD="${{FOIL_ADMIN_PASSWORD:-$(cat {saved})}}"' in served
    assert "foil serve --bundle" in served.split("FOIL_ADMIN_PASSWORD=", 1)[1]
    assert "FOIL_ACCESS_LOG=false" in served  # no line per request to push the address and password off screen


def test_the_server_never_imports_search_torch_or_the_highway_packages():
    """Neither the server nor its commands (app/cli.py, with every command's module)."""
    code = (
        "import sys, app.cli, app.web.main, app.web.serve, app.analysis.export_csv, app.analysis.report, "
        "app.analysis.bots; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('search', 'torch', 'numba', 'highway_env', 'pygame', "
        "'stable_baselines3', 'gymnasium')]; print(bad); "
        "sys.exit(1 if bad else 0)"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_a_server_whose_output_nobody_reads_keeps_answering(tmp_path, bundle_dir):
    """The access log (a line per request, on by default) goes through a pipe that nobody reads, as a paused
    terminal would: once the pipe's buffer is full the writing waits, and no request may wait with it."""
    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    port = free_port()
    server = foil("serve", "--bundle", str(bundle_dir), "--study", str(study), "--port", str(port), cwd=tmp_path)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            deadline = time.monotonic() + 30
            while True:
                try:
                    client.get("/static/favicon.svg")
                    break
                except httpx.ConnectError:
                    assert server.poll() is None and time.monotonic() < deadline, "server did not start"
                    time.sleep(0.2)
            for _ in range(2000):  # about 140 KB of access log, over twice a pipe's 64 KB
                assert client.get("/static/favicon.svg").status_code == 200
    finally:
        server.kill()
        server.wait(timeout=30)


def test_bad_settings_and_a_missing_bundle_are_one_line_each_that_names_what_to_fix(tmp_path, bundle_dir):
    """A too-short admin password is named by its variable, never printed; a bundle folder that is not there says
    how to build one."""
    secret = "shhh-7"
    short = foil("serve", "--bundle", str(bundle_dir), cwd=tmp_path, env_extra={"FOIL_ADMIN_PASSWORD": secret})
    output, _ = short.communicate(timeout=60)
    assert short.returncode == 2 and secret not in output
    assert output.strip() == (
        "foil serve: error: the server's settings: FOIL_ADMIN_PASSWORD must be at least 8 characters long"
    )
    missing = foil("serve", "--bundle", str(tmp_path / "bundles" / "demo"), cwd=tmp_path)
    output, _ = missing.communicate(timeout=60)
    assert missing.returncode == 2 and output.strip().splitlines() == [
        f"foil serve: error: no bundle folder at {tmp_path / 'bundles' / 'demo'}: build one with foil bundle "
        f"STUDY.toml --out {tmp_path / 'bundles' / 'demo'}, or give the folder that holds manifest.json"
    ]
