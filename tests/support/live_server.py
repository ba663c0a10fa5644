"""The survey server as a real process (`foil serve` on a free loopback port), for the tests and benchmarks that
need a real server, a real SQLite file and the ability to kill it."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[2]
FOIL = "import sys; from search.cli import main; sys.exit(main())"


# A crowd of bots on one machine all arrive from 127.0.0.1: the per-address arrival limit
# (app.web.security.ArrivalLimit) is for people, so a server for a crowd lifts it.
CROWD_FROM_ONE_ADDRESS = {"FOIL_ARRIVALS_BURST": "1000000"}


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def foil(*args: str, cwd, env_extra: dict | None = None, stdout=subprocess.PIPE, **kwargs) -> subprocess.Popen:
    """`foil ARGS...` as a child process with no FOIL_* variables from the outside, output to `stdout`."""
    env = {key: value for key, value in os.environ.items() if not key.startswith("FOIL_")}
    env |= {"PYTHONPATH": str(REPO), **(env_extra or {})}
    return subprocess.Popen(
        [sys.executable, "-c", FOIL, *args],
        cwd=cwd,
        env=env,
        stdout=stdout,
        stderr=subprocess.STDOUT,
        text=True,
        **kwargs,
    )


class LiveServer:
    """`foil serve --bundle B --study S --db URL` on a free 127.0.0.1 port, its output in `workdir/server.log`.

    `start` waits until it answers HTTP; `kill` is SIGKILL (a crash: no shutdown, nothing flushed); `stop` asks it
    to shut down. As a context manager it is sure to stop."""

    def __init__(
        self,
        *,
        bundle: Path,
        study: Path,
        database_url: str,
        workdir: Path,
        admin_password: str = "",
        env: dict[str, str] | None = None,
    ):
        self.bundle, self.study, self.database_url, self.workdir = bundle, study, database_url, Path(workdir)
        self.admin_password = admin_password
        self.env = env or {}  # FOIL_* settings
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.process: subprocess.Popen | None = None
        self.log = self.workdir / "server.log"

    def start(self, timeout_s: float = 60) -> LiveServer:
        env = {"FOIL_ADMIN_PASSWORD": self.admin_password} if self.admin_password else {}
        env |= self.env
        with self.log.open("a") as log:
            self.process = foil(
                "serve",
                "--bundle",
                str(self.bundle),
                "--study",
                str(self.study),
                "--db",
                self.database_url,
                "--host",
                "127.0.0.1",
                "--port",
                str(self.port),
                cwd=self.workdir,
                env_extra=env,
                stdout=log,
            )
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                httpx.get(f"{self.url}/static/survey.css", timeout=5)
                return self
            except httpx.TransportError:
                if self.process.poll() is not None:
                    raise RuntimeError(
                        f"the server exited with {self.process.returncode}:\n{self.log.read_text()}"
                    ) from None
                if time.monotonic() > deadline:
                    self.kill()
                    raise RuntimeError(
                        f"the server did not answer within {timeout_s} s:\n{self.log.read_text()}"
                    ) from None
                time.sleep(0.1)

    def kill(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
            self.process.wait(timeout=30)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.kill()

    def __enter__(self) -> LiveServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
