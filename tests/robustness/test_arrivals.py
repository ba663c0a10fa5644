"""A launch: 500 participants consent within about a second against a real `foil serve` process, each on its own
connection and thread, on a SQLite file and on a real PostgreSQL server. Every one of them gets a plan and their
first screen (no 5xx, no retry exhausted), the arrival slots are 0..499 without a gap or a repeat, and the
balanced assignment is exact: every condition 500 / 4 times."""

from __future__ import annotations

import threading
from collections import Counter
from datetime import UTC, datetime

import pytest
from sqlalchemy import insert, select

from app.store.database import Database
from app.store.models import Participant
from app.survey.assignment import condition_for_slot, conditions, next_slot
from app.survey.study import parse_study
from tests.support.crowd import LoopbackClient
from tests.support.live_server import CROWD_FROM_ONE_ADDRESS, LiveServer
from tests.support.survey import FormReader, study_text

ARRIVALS = 500


def participant_row(code: str, slot: int) -> dict:
    """A participant's row with every column the table needs: its scalar defaults and the given values."""
    row = {
        column.name: column.default.arg
        for column in Participant.__table__.c
        if column.default is not None and column.default.is_scalar
    }
    now = datetime.now(UTC)
    return {
        **row,
        "code": code,
        "study": "paper",
        "platform": "none",
        "slot": slot,
        "step_started_at": now,
        "created_at": now,
        "user_agent": "",
    }


@pytest.mark.slow
def test_500_arrivals_at_once_all_get_a_plan_and_balance_is_exact(tmp_path, bundle_dir, database_url):
    study_file = tmp_path / "study.toml"
    study_file.write_text(study_text(platform='"none"', assignment='"balanced"'))
    study = parse_study(study_file.read_text())
    n_conditions = len(conditions(study))
    replies: list[tuple[int, str] | BaseException] = [None] * ARRIVALS
    ready = threading.Barrier(ARRIVALS)

    def arrive(n: int, url: str) -> None:
        client = LoopbackClient(url)
        try:
            landing = client.get("/")
            token = FormReader(landing.text).hidden.get("csrf_token", "")
            ready.wait(timeout=120)  # everybody has the consent page: now all agree at once
            reply = client.post("/consent", {"csrf_token": token, "choice": "agree"})
            replies[n] = (reply.status_code, reply.text)
        except BaseException as error:  # noqa: BLE001  (reported below)
            replies[n] = error
            ready.abort()
        finally:
            client.close()

    with LiveServer(
        bundle=bundle_dir,
        study=study_file,
        database_url=database_url,
        workdir=tmp_path,
        env={"FOIL_ACCESS_LOG": "0", **CROWD_FROM_ONE_ADDRESS},
    ) as server:
        threads = [threading.Thread(target=arrive, args=(n, server.url)) for n in range(ARRIVALS)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=300)
    errors = [reply for reply in replies if isinstance(reply, BaseException) or reply is None]
    assert not errors, errors[:3]
    statuses = Counter(status for status, _ in replies)
    assert statuses == {200: ARRIVALS}, (statuses, [text[:300] for status, text in replies if status != 200][:3])
    assert all('name="step" value="0"' in text for _, text in replies)  # the instructions: a plan was made

    db = Database(database_url)
    try:
        with db.reading() as session:
            people = list(session.scalars(select(Participant)))
            plans = [len(person.plan or []) for person in people]
    finally:
        db.dispose()
    assert len(people) == ARRIVALS and all(plans)
    assert sorted(person.slot for person in people) == list(range(ARRIVALS))
    for person in people:
        assert person.condition == condition_for_slot(
            seed=study.study.seed, n_conditions=n_conditions, slot=person.slot
        )
    assert Counter(person.condition for person in people) == {c: ARRIVALS // n_conditions for c in range(n_conditions)}


def test_a_second_arrival_waits_for_the_first_and_takes_the_next_slot(make_client):
    """Two arrivals interleaved by hand: while the first holds its slot uncommitted, the second must not be handed
    the same slot (which only a failed commit and a retry would then sort out); it waits and takes the next."""
    client = make_client({"platform": '"none"', "assignment": '"balanced"'})
    db = client.app.state.context.db
    study_id = client.app.state.context.study.study.id
    first_claimed, second_done = threading.Event(), threading.Event()
    slots: dict[str, int] = {}

    def arrival(name: str, slot_claimed: threading.Event | None) -> None:
        with db.writing() as session:
            slots[name] = next_slot(session, study=study_id)
            if slot_claimed is not None:
                slot_claimed.set()
                second_done.wait(timeout=1.0)  # the second arrival is under way meanwhile
            session.execute(insert(Participant.__table__).values(participant_row(name, slots[name])))

    first = threading.Thread(target=arrival, args=("first", first_claimed))
    first.start()
    assert first_claimed.wait(timeout=30)
    second = threading.Thread(target=lambda: (arrival("second", None), second_done.set()))
    second.start()
    first.join(timeout=60)
    second.join(timeout=60)
    assert slots == {"first": 0, "second": 1}
