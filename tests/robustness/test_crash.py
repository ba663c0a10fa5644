"""The server is killed with SIGKILL while bots take the study, then restarted: the bots reopen their links and
finish, every answer the server acknowledged is in the database, nobody is duplicated, assignment stays balanced."""

from __future__ import annotations

import threading
import time

import pytest

from app.survey.assignment import conditions
from app.survey.study import parse_study
from tests.support.crowd import Crowd, audit
from tests.support.live_server import CROWD_FROM_ONE_ADDRESS, LiveServer
from tests.support.survey import study_text

pytestmark = pytest.mark.slow  # a real server killed mid-study

BOTS = 16


def acknowledged(crowd: Crowd) -> int:
    return sum(len(person.client.acknowledged) for person in crowd.people)


def test_sigkill_mid_study_loses_no_acknowledged_answer(tmp_path, bundle_dir):
    study_file = tmp_path / "study.toml"
    study_file.write_text(study_text(assignment='"balanced"'))
    study = parse_study(study_file.read_text())
    url = f"sqlite:///{tmp_path / 'survey.sqlite3'}"
    server = LiveServer(
        bundle=bundle_dir, study=study_file, database_url=url, workdir=tmp_path, env=CROWD_FROM_ONE_ADDRESS
    )
    with server:
        crowd = Crowd(server.url, str(bundle_dir), BOTS, pause_s=0.2, ramp_s=1.0, outage_s=60)
        runner = threading.Thread(target=crowd.run)
        runner.start()
        deadline = time.monotonic() + 120
        while acknowledged(crowd) < BOTS * 6 and time.monotonic() < deadline:  # about halfway through
            time.sleep(0.05)
        server.kill()
        at_kill = acknowledged(crowd)
        time.sleep(0.5)
        server.start()
        runner.join(timeout=240)
    assert not runner.is_alive(), "the bots did not finish"
    assert crowd.errors == []
    assert crowd.completed == BOTS
    assert 0 < at_kill < acknowledged(crowd)
    assert sum(person.interruptions for person in crowd.people) > 0  # the kill hit bots mid-study

    result = audit(url, crowd, seed=study.study.seed, n_conditions=len(conditions(study)))
    assert result.missing == [] and result.duplicated == [] and result.balance_problems == []
    assert result.participants == BOTS
    assert result.responses == BOTS * 15  # every screen of every bot, once
    # Only an answer saved just before the kill, whose reply never left, may lack an acknowledgement.
    interrupted = sum(person.interruptions for person in crowd.people)
    assert result.responses - interrupted <= result.acknowledged <= result.responses
