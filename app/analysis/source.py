"""What `foil export` and `foil report` need besides the answers: an existing survey database to read, and the
study file the server was started with, which the server keeps in that database (`remember_study`) so that the
analysis needs only the database. Apart from the answer table because the server imports it at start-up."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import select
from sqlalchemy.engine import make_url
from sqlalchemy.exc import IntegrityError, OperationalError

from app.store.database import Database, DatabaseError, check_migrated
from app.store.models import ServerSetting
from app.survey.study import Study, parse_study


def analysis_database(url: str) -> Database:
    """An existing, migrated survey database; a clear error for a wrong path or an unmigrated file (opening a
    missing SQLite file would otherwise create an empty one)."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "", ":memory:"):
        if not Path(parsed.database).is_file():
            raise ValueError(f"no database file {parsed.database} (URL {url!r})")
    db = Database(url)
    try:
        check_migrated(db.engine)
    except (DatabaseError, OperationalError) as error:
        db.dispose()
        raise ValueError(f"{url!r} is not a usable survey database: {error}") from None
    return db


STUDY_KEY = "study-file:"  # server_setting key prefix: the text of each study file the server was started with
BUNDLE_KEY = "study-bundle:"  # and the folder of the bundle it served, for the report's per-clip audit


def remember_study(db: Database, study_text: str, study: Study, bundle_root: Path | None = None) -> None:
    """Keep the study file's text and the served bundle's folder in the database, so that `foil export` and
    `foil report` need only the database. The server calls this at start-up; the latest start wins."""
    kept = {STUDY_KEY + study.study.id: study_text}
    if bundle_root is not None:
        kept[BUNDLE_KEY + study.study.id] = str(Path(bundle_root).resolve())
    try:
        with db.writing() as session:
            for key, value in kept.items():
                row = session.get(ServerSetting, key)
                if row is None:
                    session.add(ServerSetting(key=key, value=value))
                else:
                    row.value = value
    except IntegrityError:  # another worker stored it at the same moment
        pass


def served_bundle(db: Database, study_id: str) -> str | None:
    """The folder of the bundle the server last served the study from (`remember_study`), if known."""
    with db.reading() as session:
        row = session.get(ServerSetting, BUNDLE_KEY + study_id)
    return None if row is None else row.value


def analysis_study(db: Database, study: str | Path | None) -> Study:
    """The study definition for a database: a study file, or the id of a study whose file the server stored
    (`remember_study`); without either, the only study stored."""
    return analysis_study_text(db, study)[1]


def analysis_study_text(db: Database, study: str | Path | None) -> tuple[str, Study]:
    """`analysis_study` with the study file's text (`foil report` checks it against a preregistration)."""
    if study is not None and Path(study).is_file():
        text = Path(study).read_text(encoding="utf-8")
        return text, parse_study(text, source=str(study))
    with db.reading() as session:
        stored = dict(
            session.execute(
                select(ServerSetting.key, ServerSetting.value).where(ServerSetting.key.startswith(STUDY_KEY))
            ).all()
        )
    texts = {key.removeprefix(STUDY_KEY): text for key, text in stored.items()}
    if study is None and len(texts) == 1:
        study = next(iter(texts))
    if study is not None and str(study) in texts:
        text = texts[str(study)]
        return text, parse_study(text, source=f"the study file stored in the database for {study!r}")
    if study is not None:
        raise ValueError(
            f"no study file {study} and no study {str(study)!r} stored in the database "
            f"(stored: {sorted(texts) or 'none'})"
        )
    raise ValueError(
        "give the study: --study FILE (the study file the survey was served with) or --study ID of one "
        f"stored in the database (stored: {sorted(texts) or 'none'})"
    )
