"""`foil serve`: apply the migrations, check the study and bundle, then run the server with uvicorn."""

from __future__ import annotations

import errno
import logging
import queue
import socket
from logging.handlers import QueueHandler, QueueListener
from pathlib import Path
from typing import Any

from pydantic import ValidationError
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError, NoSuchModuleError, OperationalError

from app.store.database import migrate
from app.survey.study import load_study
from app.web.settings import ServerSettings, TransportLimits
from app.web.transport import survey_protocol


def serve(*, bundle: Path, study: Path | None, database_url: str | None, host: str, port: int) -> int:
    import uvicorn

    from app.web.main import create_app

    # Options not given are left to the FOIL_* variables and the defaults.
    given: dict[str, Any] = {"bundle_dir": bundle, "study_file": study, "database_url": database_url}
    settings = checked_settings({key: value for key, value in given.items() if value is not None})
    if not settings.bundle_dir.is_dir():
        raise ValueError(
            f"no bundle folder at {settings.bundle_dir}: build one with foil bundle STUDY.toml --out "
            f"{settings.bundle_dir}, or give the folder that holds manifest.json"
        )
    logging.basicConfig(level=logging.INFO, format="%(levelname)s: %(message)s")
    logging.getLogger("alembic").setLevel(logging.WARNING)  # the migrations' chatter: a failed one still says why
    load_study(settings.study_path())  # a bad study file is named first, whatever listens on the port
    listening = _bind(host, port)  # before anything is changed: a port in use touches no database
    try:
        migrate(settings.database_url)
    except (ArgumentError, OperationalError, NoSuchModuleError) as error:
        raise ValueError(f"cannot use the database {_shown(settings.database_url)}: {error}") from None
    app = create_app(settings)
    logging.getLogger("foil.server").info(
        "study %r from %s, bundle %s, database %s; participants start at http://%s:%d/%s",
        app.state.context.study.study.id,
        settings.study_path(),
        settings.bundle_dir,
        _shown(settings.database_url),
        host,
        port,
        f", the admin pages are at http://{host}:{port}/admin" if settings.admin_password is not None else "",
    )
    limits = TransportLimits()
    config = uvicorn.Config(
        app,
        host=host,
        port=port,
        proxy_headers=True,
        server_header=False,
        access_log=settings.access_log,
        http=survey_protocol(limits),
        timeout_keep_alive=limits.keep_alive_s,
    )
    listeners = _log_off_the_loop()  # after uvicorn.Config has set up its loggers
    try:
        uvicorn.Server(config).run(sockets=[listening])
    finally:
        for listener in listeners:
            listener.stop()  # writes what is still queued
    return 0


def checked_settings(given: dict[str, Any]) -> ServerSettings:
    """The server's settings from the options given and the FOIL_* variables, or one ValueError that says what is
    wrong with each, in the variables' names and without the values (a password's start is never printed)."""
    try:
        return ServerSettings(**given)
    except ValidationError as error:
        problems = []
        for found in error.errors():
            message = str(found["msg"]).removeprefix("Value error, ")
            field = ".".join(str(part) for part in found["loc"])
            problems.append(f"FOIL_{field.upper()}: {message}" if field else message)
        raise ValueError(f"the server's settings: {'; '.join(problems)}") from None


class _Queued(QueueHandler):
    """Hands the record itself to the writing thread: uvicorn's access formatter needs its arguments."""

    def prepare(self, record: logging.LogRecord) -> logging.LogRecord:
        return record


def _log_off_the_loop() -> list[QueueListener]:
    """Every logger's lines (uvicorn's access log above all, a line per request) are written by a thread of its own:
    the event loop only queues them. Written on the loop, a terminal or pipe that stops reading for a while (a
    paused terminal, a stalled SSH session) held up every request once its buffer was full."""
    listeners = []
    for name in ("", "uvicorn", "uvicorn.error", "uvicorn.access"):
        logger = logging.getLogger(name)
        if logger.handlers:
            records: queue.SimpleQueue[logging.LogRecord] = queue.SimpleQueue()
            listeners.append(QueueListener(records, *logger.handlers, respect_handler_level=True))
            logger.handlers = [_Queued(records)]
    for listener in listeners:
        listener.start()
    return listeners


def _bind(host: str, port: int) -> socket.socket:
    """The server's listening socket, bound now, as uvicorn would bind it; a clear error when it cannot be."""
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
    except socket.gaierror as error:
        raise ValueError(f"cannot listen on {host}: {error.strerror}; check --host") from None
    listening = socket.socket(family, socket.SOCK_STREAM)
    listening.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        listening.bind((host, port))
    except OSError as error:
        listening.close()
        if error.errno == errno.EADDRINUSE:
            raise ValueError(
                f"port {port} on {host} is already in use (another foil serve?): stop that server or "
                f"choose another port with --port"
            ) from None
        raise ValueError(f"cannot listen on {host}:{port}: {error.strerror}; choose another --host or --port") from None
    listening.listen(2048)  # uvicorn's backlog
    return listening


def _shown(url: str) -> str:
    """The database URL without its password, and SQLite files as absolute paths."""
    try:
        parsed = make_url(url)
    except ArgumentError:
        return repr(url)
    if parsed.get_backend_name() == "sqlite" and parsed.database:
        return f"sqlite file {Path(parsed.database).resolve()}"
    return parsed.render_as_string(hide_password=True)
