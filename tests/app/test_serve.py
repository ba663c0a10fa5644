"""`foil serve` end to end: migrations applied, server answering; bad input refused before it starts."""

from __future__ import annotations

import subprocess
import sys
import time

import httpx
import pytest

from tests.support.live_server import REPO, foil, free_port
from tests.support.survey import study_text

pytestmark = pytest.mark.slow  # foil serve processes


def test_foil_serve_migrates_and_serves(tmp_path, bundle_dir):
    study = tmp_path / "study.toml"
    study.write_text(study_text(platform='"none"'))
    port = free_port()
    server = foil("serve", "--bundle", str(bundle_dir), "--study", str(study), "--port", str(port),
                  cwd=tmp_path, env_extra={"FOIL_ADMIN_PASSWORD": "a long enough password"})
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


def test_foil_serve_refuses_a_bad_study_with_its_line(tmp_path, bundle_dir):
    study = tmp_path / "study.toml"
    study.write_text(study_text().replace("[build]", "[unknown_table]"))
    server = foil("serve", "--bundle", str(bundle_dir), "--study", str(study), cwd=tmp_path)
    output, _ = server.communicate(timeout=30)
    assert server.returncode == 2
    assert "foil serve: error:" in output and "unknown_table: unknown key" in output and ", line " in output


def test_the_server_never_imports_search_torch_or_the_highway_packages():
    code = ("import sys, app.main, app.serve; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('search', 'torch', 'highway_env', 'pygame', "
            "'stable_baselines3', 'gymnasium')]; print(bad); "
            "sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
