"""Engine, sessions and migrations. SQLite (WAL) by default; any SQLAlchemy URL (PostgreSQL) works the same way.

Writes on SQLite start with BEGIN IMMEDIATE so that two requests never both read, then both try to write (which
SQLite answers with "database is locked" instead of waiting); on PostgreSQL the unique constraints plus a retry
do the same job. Reads start a plain deferred transaction and never block writers under WAL. Within one process,
SQLite writers also queue on a lock: SQLite's own busy handler polls with sleeps of up to 100 ms, which under
hundreds of concurrent participants turned into second-long waits for a write that takes a few milliseconds.

SQLite runs with synchronous=NORMAL unless FOIL_SQLITE_SYNCHRONOUS=full: in WAL mode a commit is then written to
the WAL (the operating system's file cache) before the reply, which a crash of the server process cannot undo;
only an operating-system crash or power loss can lose the last commits (docs/survey.md explains the choice). Such
a transaction never waits for the disk, so `Database.run` runs it right on the event loop: a thread-pool hop costs
more CPU than the transaction itself.
"""

from __future__ import annotations

import threading
from collections import namedtuple
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from datetime import UTC, datetime
from pathlib import Path
from typing import TypeVar

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Dialect, Engine, Executable, create_engine, event
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

import migrations

MIGRATIONS_DIR = Path(migrations.__file__).resolve().parent
T = TypeVar("T")
SYNCHRONOUS = {"normal": "NORMAL", "full": "FULL"}


class DatabaseError(RuntimeError):
    """The database cannot be used as it is (for example, it needs migrating)."""


def make_engine(url: str, *, synchronous: str = "normal") -> Engine:
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

        @event.listens_for(engine, "connect")
        def _sqlite_setup(dbapi_connection, _record):
            dbapi_connection.isolation_level = None  # Database emits BEGIN itself
            cursor = dbapi_connection.cursor()
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute(f"PRAGMA synchronous={SYNCHRONOUS[synchronous]}")
            cursor.execute("PRAGMA foreign_keys=ON")
            cursor.execute("PRAGMA busy_timeout=30000")
            cursor.close()

        return engine
    return create_engine(url, pool_pre_ping=True)


class Database:
    """Session factories for reading and for writing, over one connection pool."""

    def __init__(self, url: str, *, synchronous: str = "normal"):
        self.url = url
        self.engine = make_engine(url, synchronous=synchronous)
        self._sessions = sessionmaker(self.engine, expire_on_commit=False)
        sqlite = self.sqlite = self.engine.dialect.name == "sqlite"
        self._write_turn = threading.Lock() if sqlite else nullcontext()
        # Work that never waits on a disk or a network runs on the event loop; the rest in the thread pool.
        self.inline = sqlite and synchronous == "normal"
        self._kept = threading.local()  # the event loop thread's connection for `statements()` (see _checked_out)
        self._loop_thread: int | None = None  # the thread whose work `run` runs inline
        self._prepared: dict[Executable, Prepared] = {}

    async def run(self, work: Callable[..., T], *args) -> T:
        """`work(*args)`, a function that reads or writes through this database, from an async endpoint."""
        if self.inline:
            self._loop_thread = threading.get_ident()
            return work(*args)
        return await run_in_threadpool(work, *args)

    @contextmanager
    def statements(self, *, write: bool = False) -> Iterator[Statements]:
        """Core statements run straight on the driver (`Statements`) in one transaction, which commits when the
        block ends without an exception and rolls back otherwise: for a participant's request, whose few
        statements cost SQLAlchemy's execution machinery several times what they cost the database.

        Without `write`, the block must run a single statement: on SQLite no transaction is begun for it, since
        one statement always reads one consistent snapshot (use `reading()` for several)."""
        with self._write_turn if write else nullcontext(), self._checked_out() as connection:
            driver = connection.connection  # the pool's DBAPI connection
            cursor = driver.cursor()
            try:
                if write and self.sqlite:
                    cursor.execute("BEGIN IMMEDIATE")
                yield Statements(cursor, self._prepared, self.engine.dialect)
                driver.commit()
            except BaseException:
                driver.rollback()
                raise
            finally:
                cursor.close()

    @contextmanager
    def _checked_out(self) -> Iterator[Connection]:
        """A connection from the pool for the block; or, for work run on the event loop (one request at a time),
        the loop thread's own connection, kept checked out between requests: taking it from the pool and giving
        it back costs more than a participant's read."""
        if threading.get_ident() != self._loop_thread:
            with self.engine.connect() as connection:
                yield connection
            return
        connection = getattr(self._kept, "connection", None)
        if connection is None or connection.closed or connection.invalidated:
            connection = self._kept.connection = self.engine.connect()
        yield connection

    @contextmanager
    def reading(self) -> Iterator[Session]:
        with self._sessions() as session, session.begin():
            self._begin(session.connection(), "BEGIN")
            yield session

    @contextmanager
    def writing(self) -> Iterator[Session]:
        """A transaction that commits when the block ends without an exception, and rolls back otherwise."""
        with self._write_turn, self._sessions() as session, session.begin():
            self._begin(session.connection(), "BEGIN IMMEDIATE")
            yield session

    def _begin(self, connection: Connection, begin: str) -> None:
        """SQLite: begin the transaction that SQLAlchemy has just opened (the driver is told not to). Straight to
        the driver, not through an SQLAlchemy event and statement, which cost more than SQLite's work here."""
        if self.sqlite:
            connection.connection.driver_connection.execute(begin)

    def dispose(self) -> None:
        kept = getattr(self._kept, "connection", None)
        if kept is not None:
            kept.close()
        self.engine.dispose()


class Prepared:
    """A Core statement compiled once for a dialect, with the dialect's own conversions of the values it takes and
    the columns it returns: run on a driver cursor, it stores and reads rows exactly as SQLAlchemy does. It does
    not apply Python-side column defaults: an INSERT must be given every column it names."""

    def __init__(self, statement: Executable, dialect: Dialect):
        compiled = statement.compile(dialect=dialect)
        self.sql = str(compiled)
        self.order = compiled.positiontup if compiled.positional else None  # the values' order, for "?" styles
        self.fixed = {name: bind.effective_value for bind, name in compiled.bind_names.items() if not bind.required}
        self.convert_in = [(name, convert) for bind, name in compiled.bind_names.items()
                           if (convert := bind.type.dialect_impl(dialect).bind_processor(dialect)) is not None]
        columns = list(getattr(statement, "exported_columns", ()))
        self.row = namedtuple("Row", [str(column.key) for column in columns], rename=True)
        self.convert_out = [column.type.dialect_impl(dialect).result_processor(dialect, None) for column in columns]

    def parameters(self, values: dict) -> tuple | dict:
        values = {**self.fixed, **values}
        for name, convert in self.convert_in:
            values[name] = convert(values[name])
        return values if self.order is None else tuple(values[name] for name in self.order)

    def row_from(self, raw: Sequence) -> tuple:
        return self.row._make(value if convert is None else convert(value)
                              for convert, value in zip(self.convert_out, raw, strict=True))


class Statements:
    """Runs Core statements on a driver cursor (see `Database.statements`), with the calls of a Session that the
    participant's pages use. The driver's IntegrityError comes out as SQLAlchemy's, as from a Session."""

    def __init__(self, cursor, prepared: dict[Executable, Prepared], dialect: Dialect):
        self.cursor, self._prepared, self._dialect = cursor, prepared, dialect

    @property
    def dialect(self) -> Dialect:
        return self._dialect

    def execute(self, statement: Executable, values: dict) -> Prepared:
        prepared = self._prepared.get(statement)
        if prepared is None:
            prepared = self._prepared[statement] = Prepared(statement, self._dialect)
        parameters = prepared.parameters(values)
        try:
            self.cursor.execute(prepared.sql, parameters)
        except self._dialect.dbapi.IntegrityError as error:
            raise IntegrityError(prepared.sql, parameters, error) from error
        return prepared

    def first(self, statement: Executable, values: dict) -> tuple | None:
        """The first row the statement returns (a named tuple), or None."""
        prepared = self.execute(statement, values)
        raw = self.cursor.fetchone()
        return None if raw is None else prepared.row_from(raw)

    def scalar(self, statement: Executable, values: dict):
        row = self.first(statement, values)
        return None if row is None else row[0]


def alembic_config(url: str) -> Config:
    """Configured in code, so it works from an installed package and from any working directory."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def migrate(url: str, revision: str = "head") -> None:
    """Bring the database to `revision` (creating it if needed)."""
    command.upgrade(alembic_config(url), revision)


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
