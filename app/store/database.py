"""Engine, sessions and migrations. SQLite (WAL) by default; any SQLAlchemy URL (PostgreSQL) works the same way.

Writes on SQLite start with BEGIN IMMEDIATE so that two requests never both read, then both try to write (which
SQLite answers with "database is locked" instead of waiting); on PostgreSQL the unique constraints plus a retry
do the same job. Reads start a plain deferred transaction and never block writers under WAL. Within one process,
SQLite writers also queue on a lock: SQLite's own busy handler polls with sleeps of up to 100 ms, which under
hundreds of concurrent participants turned into second-long waits for a write that takes a few milliseconds.

SQLite runs with synchronous=FULL: a commit is on the disk before the reply, so neither a crash of the server nor
one of the operating system (or a power loss) can lose an acknowledged answer. FOIL_SQLITE_SYNCHRONOUS=normal
trades the last commits before an operating-system crash for fewer disk flushes (docs/survey.md).
"""

from __future__ import annotations

import logging
import sqlite3
import threading
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from datetime import UTC, datetime
from pathlib import Path
from typing import cast

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Engine, create_engine, event
from sqlalchemy.orm import Session, sessionmaker

import migrations

MIGRATIONS_DIR = Path(migrations.__file__).resolve().parent
SYNCHRONOUS = {"normal": "NORMAL", "full": "FULL"}


class DatabaseError(RuntimeError):
    """The database cannot be used as it is (for example, it needs migrating)."""


def make_engine(url: str, *, synchronous: str = "full") -> Engine:
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

        @event.listens_for(engine, "connect")
        def _sqlite_setup(dbapi_connection: sqlite3.Connection, _record: object) -> None:
            dbapi_connection.isolation_level = None  # Database emits BEGIN itself
            cursor = dbapi_connection.cursor()
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute(f"PRAGMA synchronous={SYNCHRONOUS[synchronous]}")
            cursor.execute("PRAGMA foreign_keys=ON")
            cursor.execute("PRAGMA busy_timeout=30000")
            cursor.close()

        return engine
    # No pool_pre_ping: its SELECT 1 (and the BEGIN psycopg sends before it) cost two round trips on every request,
    # and each wait gives up the interpreter lock, which under load is not had back for milliseconds (BENCHMARKS.md).
    # A connection that died with a server restart fails one request, and SQLAlchemy then replaces the whole pool.
    return create_engine(url)


class Database:
    """Session factories for reading and for writing, over one connection pool. Their work blocks, so endpoints
    that use them are plain functions, which FastAPI runs in its thread pool."""

    def __init__(self, url: str, *, synchronous: str = "full") -> None:
        self.url = url
        self.engine = make_engine(url, synchronous=synchronous)
        self._sessions = sessionmaker(self.engine, expire_on_commit=False)
        self.sqlite = self.engine.dialect.name == "sqlite"
        # PostgreSQL reads without BEGIN and COMMIT, two round trips to the server of the three a page's read
        # takes. Under READ COMMITTED, its default, a transaction gives each statement its own snapshot anyway.
        self._read_sessions = (
            self._sessions
            if self.sqlite
            else sessionmaker(self.engine.execution_options(isolation_level="AUTOCOMMIT"), expire_on_commit=False)
        )
        self._write_turn = threading.Lock() if self.sqlite else nullcontext()

    @contextmanager
    def reading(self) -> Iterator[Session]:
        with self._read_sessions() as session, session.begin():
            self._begin(session.connection(), "BEGIN")
            yield session

    @contextmanager
    def writing(self) -> Iterator[Session]:
        """A transaction that commits when the block ends without an exception, and rolls back otherwise."""
        with self._write_turn, self._sessions() as session, session.begin():
            self._begin(session.connection(), "BEGIN IMMEDIATE")
            yield session

    def _begin(self, connection: Connection, begin: str) -> None:
        """SQLite: begin the transaction that SQLAlchemy has just opened (the driver is told not to)."""
        if self.sqlite:
            cast(sqlite3.Connection, connection.connection.driver_connection).execute(begin)

    def dispose(self) -> None:
        self.engine.dispose()


def alembic_config(url: str) -> Config:
    """Configured in code, so it works from an installed package and from any working directory."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def migrate(url: str, revision: str = "head") -> None:
    """Bring the database to `revision` (creating it if needed). Alembic's line per migration is left out of the
    log: on a new database they would bury the server's address and admin password under a page of history."""
    alembic_log = logging.getLogger("alembic")
    level = alembic_log.level
    alembic_log.setLevel(logging.WARNING)
    try:
        command.upgrade(alembic_config(url), revision)
    finally:
        alembic_log.setLevel(level)


def check_migrated(engine: Engine) -> None:
    head = ScriptDirectory(str(MIGRATIONS_DIR)).get_current_head()
    with engine.connect() as connection:
        current = MigrationContext.configure(connection).get_current_revision()
    if current != head:
        raise DatabaseError(
            f"the database is at revision {current or 'none (empty)'}, the server needs {head}: "
            "start it with `foil serve`, which applies the migrations"
        )


def as_utc(moment: datetime) -> datetime:
    """SQLite hands back naive datetimes; they were stored in UTC."""
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)
