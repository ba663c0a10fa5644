"""A throwaway PostgreSQL server for the tests: `initdb` and `pg_ctl` on a free loopback port in a temporary folder,
stopped and deleted at the end of the session. `FOIL_TEST_DATABASE_URL` points the tests at an existing server
instead. Without either (no PostgreSQL binaries installed; `make test` and `make check` install Debian's), the
PostgreSQL variants of the tests fail with a message saying so: they are never skipped."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

from sqlalchemy import create_engine, text

URL_VARIABLE = "FOIL_TEST_DATABASE_URL"


def binaries() -> Path | None:
    """The folder of initdb, pg_ctl and postgres: Debian's /usr/lib/postgresql/N/bin (newest first), or PATH's."""
    for folder in sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda f: int(Path(f).parent.name), reverse=True):
        if (Path(folder) / "initdb").exists() and (Path(folder) / "pg_ctl").exists():
            return Path(folder)
    found = shutil.which("initdb")
    return Path(found).parent if found and shutil.which("pg_ctl") else None


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class ThrowawayServer:
    """A PostgreSQL cluster of its own. PostgreSQL refuses to run as root: as root, it runs as the `postgres` user
    (which Debian's package creates), in a folder that user owns."""

    def __init__(self, bin_dir: Path):
        self.bin_dir = bin_dir
        self.folder = Path(tempfile.mkdtemp(prefix="foil-postgres-"))
        self.data = self.folder / "data"
        self.port = _free_port()
        self.user = None
        if os.geteuid() == 0:
            try:
                pwd.getpwnam("postgres")
            except KeyError:
                raise RuntimeError(
                    "PostgreSQL cannot run as root and there is no `postgres` user to run it as"
                ) from None
            self.user = "postgres"
            shutil.chown(self.folder, "postgres")
        self.url = f"postgresql+psycopg://foil@127.0.0.1:{self.port}/foil"

    def _run(self, *args: str) -> subprocess.CompletedProcess:
        command = [str(self.bin_dir / args[0]), *args[1:]]
        if self.user:
            command = ["runuser", "-u", self.user, "--", *command]
        result = subprocess.run(command, capture_output=True, text=True, cwd=self.folder)
        if result.returncode != 0:
            raise RuntimeError(f"{args[0]} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
        return result

    def start(self, *, durable: bool = False) -> ThrowawayServer:
        """`durable`: commits reach the disk as on a deployed server (for benchmarks). Without it, as in the tests,
        where durability is not under test: no fsync makes creating and dropping tables fast."""
        self._run(
            "initdb", "-D", str(self.data), "-U", "foil", "--auth=trust", "-E", "UTF8", "--locale=C.UTF-8", "--no-sync"
        )
        options = f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.folder} -c max_connections=200" + (
            "" if durable else " -c fsync=off -c synchronous_commit=off -c full_page_writes=off"
        )
        self._run(
            "pg_ctl",
            "-D",
            str(self.data),
            "-o",
            options,
            "-l",
            str(self.folder / "server.log"),
            "-w",
            "-t",
            "60",
            "start",
        )
        deadline = time.monotonic() + 30
        while True:
            try:
                engine = create_engine(self.url.rsplit("/", 1)[0] + "/postgres", isolation_level="AUTOCOMMIT")
                with engine.connect() as connection:
                    connection.execute(text("CREATE DATABASE foil"))
                engine.dispose()
                return self
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)

    def stop(self) -> None:
        try:
            self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")
        finally:
            shutil.rmtree(self.folder, ignore_errors=True)


_SESSION: dict[str, str | None] = {}


def session_url(config) -> str | None:
    """The database of this test session: FOIL_TEST_DATABASE_URL's, else a throwaway server's, started on first
    use and stopped when the session ends (whichever conftest's fixture asks first); None without binaries."""
    if "url" not in _SESSION:
        url = os.environ.get(URL_VARIABLE)
        if not url and (bin_dir := binaries()) is not None:
            server = ThrowawayServer(bin_dir)
            config.add_cleanup(server.stop)
            url = server.start().url
        _SESSION["url"] = url or None
    return _SESSION["url"]


def reset(url: str) -> None:
    """Drop every table and sequence of the database's schema (whatever the migrations made, including tables
    added later), so each test starts from an empty database."""
    engine = create_engine(url)
    with engine.begin() as connection:
        connection.execute(text("SET LOCAL lock_timeout = '20s'"))  # a leaked transaction fails the test, not hangs
        connection.execute(
            text("""
            DO $$ DECLARE r record; BEGIN
              FOR r IN SELECT tablename FROM pg_tables WHERE schemaname = current_schema() LOOP
                EXECUTE 'DROP TABLE IF EXISTS ' || quote_ident(r.tablename) || ' CASCADE';
              END LOOP;
              FOR r IN SELECT sequence_name FROM information_schema.sequences
                       WHERE sequence_schema = current_schema() LOOP
                EXECUTE 'DROP SEQUENCE IF EXISTS ' || quote_ident(r.sequence_name) || ' CASCADE';
              END LOOP;
            END $$""")
        )
    engine.dispose()
