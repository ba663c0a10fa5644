"""What `foil export` and `foil report` need besides the answers: an existing survey database to read, and the
study file the server was started with, which the server keeps in that database (`remember_study`) so that the
analysis needs only the database. Apart from the answer table because the server imports it at start-up."""

from __future__ import annotations

import hashlib
import json
import sys
import time
import uuid
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.engine import make_url
from sqlalchemy.exc import IntegrityError, OperationalError

from app.formats import Manifest
from app.store.database import Database, DatabaseError, check_migrated
from app.store.models import ServerSetting
from app.survey.study import Study, parse_study
from app.visible import World


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
START_KEY = "study-start:"  # and one row per start (JSON): what it served, by hash, and when; never overwritten


def sha256(data: bytes) -> str:
    """A file's hash as prereg.json and the stored starts name it: of its raw bytes, so `sha256sum` agrees."""
    return "sha256:" + hashlib.sha256(data).hexdigest()


def remember_study(db: Database, study_file: bytes | str, study: Study, bundle_root: Path | None = None) -> None:
    """Keep the study file (its bytes as read, or text) and the served bundle's folder in the database, so that
    `foil export` and `foil report` need only the database; the latest start wins. Every start also adds a row of
    its own with the hashes of the study file and the bundle's manifest, so that an edit made during collection
    and reverted later is still seen by `foil report --prereg`."""
    raw = study_file.encode("utf-8") if isinstance(study_file, str) else study_file
    manifest = None if bundle_root is None else Path(bundle_root) / "manifest.json"
    start = {
        "study": study.study.id,
        "at": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "study_file": sha256(raw),
        "bundle_manifest": sha256(manifest.read_bytes()) if manifest is not None and manifest.is_file() else None,
    }
    with db.writing() as session:  # a key of its own (time, then random), so workers starting at once all add one
        session.add(
            ServerSetting(key=f"{START_KEY}{time.time_ns():020d}-{uuid.uuid4().hex[:8]}", value=json.dumps(start))
        )
    kept = {STUDY_KEY + study.study.id: raw.decode("utf-8")}
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


def study_starts(db: Database, study_id: str) -> list[dict[str, Any]]:
    """Every recorded server start of the study, oldest first (`remember_study`); none in older databases."""
    with db.reading() as session:
        values = session.scalars(
            select(ServerSetting.value).where(ServerSetting.key.startswith(START_KEY)).order_by(ServerSetting.key)
        ).all()
    starts = [json.loads(value) for value in values]
    return [start for start in starts if start.get("study") == study_id]


def served_bundle(db: Database, study_id: str) -> str | None:
    """The folder of the bundle the server last served the study from (`remember_study`), if known."""
    with db.reading() as session:
        row = session.get(ServerSetting, BUNDLE_KEY + study_id)
    return None if row is None else row.value


def bundle_world(bundle: str | Path | None) -> World:
    """The world a bundle's clips show, in whose words the export and the report speak of its agents: its
    manifest's `world` (the crowd's, where the manifest has none); the world in general (`World()`) where the
    bundle is not known or its manifest cannot be read."""
    manifest = None if bundle is None else Path(bundle) / "manifest.json"
    if manifest is None or not manifest.is_file():
        return World()
    try:
        return Manifest.model_validate_json(manifest.read_text(encoding="utf-8")).shown_world()
    except ValueError:
        return World()


@dataclass(frozen=True)
class StudySource:
    """The study a database's answers belong to, and where its text came from."""

    text: str  # the study file's text: as the server stored it, else (older databases) the --study file's
    study: Study
    starts: list[dict[str, Any]] = field(default_factory=list)  # what each server start served (`study_starts`)
    differs: str | None = None  # a --study file that differs from the stored text, said in words


def analysis_study(db: Database, study: str | Path | None) -> Study:
    """The study definition for a database: a study file, or the id of a study whose file the server stored
    (`remember_study`); without either, the only study stored. A file that differs from the stored one is
    named on stderr."""
    source = analysis_study_text(db, study)
    if source.differs:
        print(f"warning: {source.differs}", file=sys.stderr)
    return source.study


def analysis_study_text(db: Database, study: str | Path | None) -> StudySource:
    """`analysis_study` with the study file's text (`foil report` checks it against a preregistration). The text
    the server stored is the authority: a --study file is only compared with it, so an edited file cannot pass
    for the one served; where the database holds none for the file's study (older databases) the file is used."""
    with db.reading() as session:
        stored = session.execute(
            select(ServerSetting.key, ServerSetting.value).where(ServerSetting.key.startswith(STUDY_KEY))
        ).all()
    texts = {key.removeprefix(STUDY_KEY): text for key, text in stored}
    if study is not None and Path(study).is_file():
        raw = Path(study).read_bytes()
        given = parse_study(raw.decode("utf-8"), source=str(study))
        if given.study.id not in texts:
            return StudySource(raw.decode("utf-8"), given)
        kept = _stored(db, texts, given.study.id)
        if kept.text.encode("utf-8") == raw:
            return kept
        return replace(
            kept,
            differs=f"the study file {study} ({sha256(raw)}) differs from the one the server stored for study "
            f"{given.study.id!r} ({sha256(kept.text.encode('utf-8'))}); the stored one is analysed",
        )
    if study is None and len(texts) == 1:
        study = next(iter(texts))
    if study is not None and str(study) in texts:
        return _stored(db, texts, str(study))
    if study is not None:
        raise ValueError(
            f"no study file {study} and no study {str(study)!r} stored in the database "
            f"(stored: {sorted(texts) or 'none'})"
        )
    raise ValueError(
        "give the study: --study FILE (the study file the survey was served with) or --study ID of one "
        f"stored in the database (stored: {sorted(texts) or 'none'})"
    )


def _stored(db: Database, texts: dict[str, str], study_id: str) -> StudySource:
    text = texts[study_id]
    study = parse_study(text, source=f"the study file stored in the database for {study_id!r}")
    return StudySource(text, study, study_starts(db, study_id))
