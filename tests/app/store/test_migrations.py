"""Alembic: the migrations build exactly the models' schema, and an older database upgrades keeping its data."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine, text
from sqlalchemy.orm import Session

from app.store.database import MIGRATIONS_DIR, DatabaseError, alembic_config, check_migrated, migrate
from app.store.models import Base, Participant
from tests.support.live_server import REPO


def test_migrations_match_the_models(database_url):
    migrate(database_url)
    engine = create_engine(database_url)
    with engine.connect() as connection:
        differences = compare_metadata(MigrationContext.configure(connection), Base.metadata)
    engine.dispose()
    assert differences == []


def test_upgrade_from_the_first_revision_keeps_data(database_url):
    migrate(database_url, "0001")
    engine = create_engine(database_url)
    with engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO participant (id, code, study, platform, external_id, status, step, step_started_at, "
                "user_agent, created_at, \"plan\") VALUES (1, 'abc', 'paper', 'prolific', 'P1', 'started', 0, "
                "'2024-01-01 00:00:00', '', '2024-01-01 00:00:00', '[{\"kind\": \"instructions\"}]')"
            )
        )
        connection.execute(
            text(  # declined: no plan
                "INSERT INTO participant (id, code, study, platform, external_id, status, step, step_started_at, "
                "user_agent, created_at) VALUES (2, 'def', 'paper', 'prolific', 'P2', 'declined', 0, "
                "'2024-01-01 00:00:00', '', '2024-01-01 00:00:00')"
            )
        )
        connection.execute(
            text(
                "INSERT INTO response (participant_id, step, kind, answers, video_events, plays, server_ms, "
                "submitted_at) VALUES (1, 0, 'instructions', '{}', '[]', 0, 10, '2024-01-01 00:00:05')"
            )
        )
    with pytest.raises(DatabaseError, match="revision 0001"):
        check_migrated(engine)
    migrate(database_url)
    check_migrated(engine)
    with engine.connect() as connection:
        rows = connection.execute(
            text("SELECT code, excluded, exclusion_note, attention_failures FROM participant ORDER BY id")
        ).all()
        assert [tuple(row) for row in rows] == [("abc", False, "", 0), ("def", False, "", 0)]
        assert connection.execute(text("SELECT count(*) FROM response")).scalar() == 1
    with Session(engine) as session:
        assert session.get(Participant, 1).plan == [{"kind": "instructions"}]
        assert session.get(Participant, 2).plan is None
    command.downgrade(alembic_config(database_url), "0002")  # and back: the plan returns to the participant's row
    with engine.connect() as connection:
        plans = connection.execute(text('SELECT "plan" FROM participant ORDER BY id')).scalars().all()
        # SQLite hands back the JSON text, psycopg the decoded value
        assert [json.loads(plan) if isinstance(plan, str) else plan for plan in plans] == [
            [{"kind": "instructions"}],
            None,
        ]
    engine.dispose()


def test_an_empty_database_is_refused_with_a_message(tmp_path):
    engine = create_engine(f"sqlite:///{tmp_path / 'empty.sqlite3'}")
    with pytest.raises(DatabaseError, match="foil serve"):
        check_migrated(engine)
    engine.dispose()


def test_migrations_run_from_any_working_directory(tmp_path):
    url = f"sqlite:///{tmp_path / 'elsewhere.sqlite3'}"
    logged = "import logging; logging.basicConfig(level=logging.INFO)"
    code = f"{logged}; from app.store.database import migrate; migrate({url!r})"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, check=True, capture_output=True, text=True
    )
    assert "Running upgrade" not in done.stderr  # no page of migration history before the server's address
    engine = create_engine(url)
    with engine.connect() as connection:
        head = ScriptDirectory(str(MIGRATIONS_DIR)).get_current_head()
        assert connection.execute(text("SELECT version_num FROM alembic_version")).scalar() == head
    engine.dispose()
