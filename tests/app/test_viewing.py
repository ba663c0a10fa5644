"""The server's own viewing check, participant kinds and answers sent again: the real app on a real SQLite file,
with a bundle of 3-second clips (longer than the check's 1-second tolerance)."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest
from sqlalchemy import select

from app.analysis.exclusions import ExclusionRules
from app.analysis.export_csv import export_study
from app.analysis.report import tally_study
from app.store.models import Participant, Response
from app.survey.kinds import pilot_token
from app.survey.screens import parse_plan
from tests.support.survey import CLIP_S, FormReader, answer_for, finish, start, stored, write_long_bundle


@pytest.fixture(scope="module")
def bundle_dir(tmp_path_factory) -> Path:
    return write_long_bundle(tmp_path_factory.mktemp("long-clips"), tmp_path_factory.mktemp("long-bundle"))


ANONYMOUS = {"platform": '"none"', "assignment": '"balanced"'}


def to_first_clip(client, query: str = "") -> str:
    page = start(client, query)
    assert "Instructions" in page
    response = client.post("/study", data=answer_for(page))
    assert response.status_code == 200
    return response.text


@pytest.mark.slow  # waits out a clip's length
def test_a_clip_answered_sooner_than_it_plays_is_refused_and_nothing_saved(make_client):
    client = make_client(ANONYMOUS)
    page = to_first_clip(client)
    assert FormReader(page).hidden["step"] == "1"
    # The skip-to-end attack: the page's record says the clip played and ended, 0.1 s after it was shown.
    refused = client.post("/study", data=answer_for(page))
    assert refused.status_code == 422
    assert "cannot have been watched to the end" in refused.text and "plays for 3 seconds" in refused.text
    assert [r.step for r in stored(client, Response)] == [0]  # the instructions only: nothing saved
    assert FormReader(refused.text).disabled_answers  # the answers are locked again until the clip ends
    plan = stored(client, Participant)[0].plan
    assert plan[1]["clip_ms"] == 3000 and (plan[1]["width"], plan[1]["height"]) == (72, 88)

    time.sleep(CLIP_S - 0.8)  # the screen has now been open for the clip's length, less the tolerance
    accepted = client.post("/study", data=answer_for(page))
    assert accepted.status_code == 200 and FormReader(accepted.text).hidden["step"] == "2"
    assert [r.step for r in stored(client, Response)] == [0, 1]


def test_pilot_and_bot_links_are_recorded_and_only_the_token_skips_the_wait(make_client):
    client = make_client(ANONYMOUS)
    db = client.app.state.context.db
    token = pilot_token(db, "paper")
    assert pilot_token(db, "paper") == token and len(token) >= 20

    assert client.get("/?pilot=wrong-token").status_code == 400
    fast = make_client(ANONYMOUS)
    page = to_first_clip(fast, f"?pilot={token}&bot=1")
    assert fast.post("/study", data=answer_for(page)).status_code == 200  # no wait for a bot with the token
    finish(fast, fast.get("/study").text)

    selfdeclared = make_client(ANONYMOUS)
    page = to_first_clip(selfdeclared, "?bot=1")
    assert selfdeclared.post("/study", data=answer_for(page)).status_code == 422  # held to the rule

    pilot = make_client(ANONYMOUS)
    to_first_clip(pilot, f"?pilot={token}")
    kinds = sorted(p.kind for p in stored(client, Participant))
    assert kinds == ["bot", "bot", "pilot"]
    versions = {p.consent_version for p in stored(client, Participant)}
    assert len(versions) == 1 and next(iter(versions)).startswith("sha256:")


@pytest.mark.slow  # waits out a clip's length
def test_the_report_and_export_leave_pilots_and_bots_out_by_default(make_client, tmp_path):
    token = None
    clients = []
    for query in ("", "?pilot={token}&bot=1", "?pilot={token}"):
        client = make_client(ANONYMOUS)
        token = token or pilot_token(client.app.state.context.db, "paper")
        page = to_first_clip(client, query.format(token=token))
        if not query:
            time.sleep(CLIP_S)  # a real participant waits on every clip: answer the first one only
            client.post("/study", data=answer_for(page))
        else:
            finish(client, page)
        clients.append(client)
    ctx = clients[0].app.state.context
    data = tally_study(ctx.db, ctx.study)
    assert data.exclusions.before == 3 and data.exclusions.per_reason["pilot_or_bot"] == 2
    with_bots = tally_study(ctx.db, ctx.study, ExclusionRules(include_kinds=("bot", "pilot")))
    assert with_bots.exclusions.per_reason["pilot_or_bot"] == 0
    # analysed: the pilot's unwatched clips are flagged; a bot, a rehearsal of the analysis, is held to no viewing rule
    assert with_bots.exclusions.per_reason["skipped_viewing"] == 1

    export_study(ctx.db, ctx.study, tmp_path / "export")
    import csv

    people = list(csv.DictReader((tmp_path / "export" / "participants.csv").open(encoding="utf-8")))
    assert sorted((p["kind"], p["pilot_or_bot"]) for p in people) == [("bot", "1"), ("pilot", "1"), ("real", "0")]
    long = list(csv.DictReader((tmp_path / "export" / "long.csv").open(encoding="utf-8")))
    real = next(p["participant"] for p in people if p["kind"] == "real")
    clip_row = next(r for r in long if r["participant"] == real and r["screen"] == "pairwise")
    assert clip_row["clip_ms"] == "3000" and int(clip_row["time_on_screen_ms"]) >= 2000
    assert clip_row["skipped_viewing"] == "0" and clip_row["plays"] == "1"
    bot = next(p["participant"] for p in people if p["kind"] == "bot")
    assert {r["skipped_viewing"] for r in long if r["participant"] == bot and r["screen"] == "pairwise"} == {"1"}
    book = json.loads((tmp_path / "export" / "codebook.json").read_text())
    assert book["exclusion_rules"]["analysed_kinds"] == ["real"]


def test_an_answered_screen_sent_again_with_other_answers_says_the_first_is_kept(make_client):
    client = make_client(ANONYMOUS)
    token = pilot_token(client.app.state.context.db, "paper")
    page = to_first_clip(client, f"?pilot={token}")
    first = answer_for(page, choice=0)
    client.post("/study", data=first)
    again = client.post("/study", data=first)  # a double click: same answers, nothing to say
    assert "first answers" not in again.text
    changed = client.post("/study", data=answer_for(page, choice=1))  # the back button, then another choice
    assert changed.status_code == 200 and FormReader(changed.text).hidden["step"] == "2"
    assert "first answers" in changed.text and first["better"] in changed.text
    saved = [r for r in stored(client, Response) if r.step == 1]
    assert len(saved) == 1 and saved[0].answers["better"] == first["better"]
    assert "first answers" not in client.get("/study").text  # said once


def test_the_kept_answers_notice_keeps_the_cookie_small_whatever_was_typed(make_client):
    """Browsers drop a cookie over 4 KB, and then every later request would fail: the cookie holds only which
    screen's answers were kept, and the page reads them from the database."""
    client = make_client(ANONYMOUS)
    token = pilot_token(client.app.state.context.db, "paper")
    page = to_first_clip(client, f"?pilot={token}")
    first = {**answer_for(page, choice=0), "justification": "é" * 2000}
    assert client.post("/study", data=first).status_code == 200
    changed = client.post("/study", data={**answer_for(page, choice=1), "justification": "è" * 2000})
    assert changed.status_code == 200 and "first answers" in changed.text and first["better"] in changed.text
    notice = changed.text.split("data-notice>", 1)[1].split("</div>", 1)[0]
    assert "é" * 60 + "…" in notice and len(notice) < 400  # short, with the start of the text that was kept
    assert max(len(value) for value in client.cookies.values()) < 4096 - 100
    assert client.get("/study").status_code == 200


def test_events_of_the_new_kinds_are_kept_with_their_values(make_client):
    client = make_client(ANONYMOUS)
    token = pilot_token(client.app.state.context.db, "paper")
    page = to_first_clip(client, f"?pilot={token}")
    events = [
        {"type": "loaded", "t": 5},
        {"type": "play", "t": 10},
        {"type": "seek_blocked", "t": 50, "v": 2.9},
        {"type": "ratechange", "t": 60, "v": 2},
        {"type": "hidden", "t": 100},
        {"type": "visible", "t": 600},
        {"type": "ended", "t": 3100},
        {"type": "reload", "t": 0},
        {"type": "play", "t": 40},
        {"type": "ended", "t": 3040},
    ]
    data = answer_for(page) | {"video_events": json.dumps(events), "viewport": "360x800"}
    assert client.post("/study", data=data).status_code == 200
    with client.app.state.context.db.reading() as session:
        response = session.scalar(select(Response).where(Response.step == 1))
    assert response.plays == 2 and response.details == {"viewport": "360x800"}
    assert response.video_events[2] == {"type": "seek_blocked", "t": 50, "v": 2.9}
    from app.analysis.exclusions import viewing_problems

    plan = parse_plan(stored(client, Participant)[0].plan)
    viewing = viewing_problems(response, plan[1])
    assert viewing["seeks_blocked"] == 1 and viewing["hidden_ms"] == 500 and viewing["reloads"] == 1
    assert viewing["skipped"]  # sped up before the first end


@pytest.mark.slow  # PostgreSQL
@pytest.mark.parametrize("database_url", ["postgresql"], indirect=True)
def test_a_concurrent_resubmit_with_other_answers_gets_the_kept_notice_on_postgresql(make_client, database_url):
    """Two submissions of the same screen at once (two tabs, a double click with a change in between): PostgreSQL
    lets both read the screen as open, and the second insert fails on the unique (participant, step). The losing
    one is a resubmit and must say so, as on SQLite, where writers take turns. The race is made certain by holding
    inserts into `response` until both requests wait at theirs."""
    from sqlalchemy import create_engine, text
    from starlette.testclient import TestClient

    client = make_client(ANONYMOUS)
    token = pilot_token(client.app.state.context.db, "paper")
    page = to_first_clip(client, f"?pilot={token}")
    other_tab = TestClient(client.app, follow_redirects=True)
    other_tab.cookies.update(client.cookies)
    answers = [answer_for(page, choice=0), answer_for(page, choice=1)]
    assert answers[0]["better"] != answers[1]["better"]
    engine = create_engine(database_url)
    replies = [None, None]
    try:
        with engine.connect() as holder, engine.connect() as watcher:
            holder.execute(text("BEGIN"))
            holder.execute(text("LOCK TABLE response IN EXCLUSIVE MODE"))  # reads go on, inserts wait
            threads = [
                threading.Thread(
                    target=lambda n=n, tab=tab: replies.__setitem__(n, tab.post("/study", data=answers[n]))
                )
                for n, tab in enumerate((client, other_tab))
            ]
            for thread in threads:
                thread.start()
            deadline = time.monotonic() + 30
            while (
                watcher.scalar(
                    text("SELECT count(*) FROM pg_locks WHERE NOT granted AND relation = 'response'::regclass")
                )
                < 2
            ):
                assert time.monotonic() < deadline, "the two submissions did not both reach their insert"
                time.sleep(0.05)
                watcher.rollback()
            holder.execute(text("COMMIT"))
            for thread in threads:
                thread.join(30)
    finally:
        engine.dispose()
    assert all(reply.status_code == 200 and FormReader(reply.text).hidden["step"] == "2" for reply in replies)
    saved = [r for r in stored(client, Response) if r.step == 1]
    assert len(saved) == 1
    winner = next(n for n in (0, 1) if answers[n]["better"] == saved[0].answers["better"])
    assert "first answers" not in replies[winner].text
    assert "first answers" in replies[1 - winner].text and answers[winner]["better"] in replies[1 - winner].text


def test_a_record_of_clips_that_ended_without_playing_is_no_viewing(make_client):
    """A page's record that says the clip ended but never that it played: the server refuses it as unwatched
    (the study requires full views), and the same record under a study that does not is flagged as skipped."""
    from app.analysis.exclusions import viewing_problems
    from app.survey.answers import clips_played, full_view_at

    assert full_view_at([{"type": "ended", "t": 0}], 1) is None
    assert full_view_at([{"type": "play", "t": 0}, {"type": "ended", "t": 9}], 1) == 1
    reels = [
        {"type": "play", "t": 0, "reel": 0},
        {"type": "ended", "t": 9, "reel": 0},
        {"type": "ended", "t": 9, "reel": 1},
    ]
    assert full_view_at(reels, 2) is None and clips_played(reels, 2) == 1

    client = make_client(ANONYMOUS)
    token = pilot_token(client.app.state.context.db, "paper")
    page = to_first_clip(client, f"?pilot={token}")
    ended_only = answer_for(page) | {"video_events": json.dumps([{"type": "ended", "t": 3100}])}
    refused = client.post("/study", data=ended_only)
    assert refused.status_code == 422 and "watch the clip to the end" in refused.text

    lenient = make_client(ANONYMOUS | {"require_full_view": "false"})
    page = to_first_clip(lenient, f"?pilot={pilot_token(lenient.app.state.context.db, 'paper')}")
    assert (
        lenient.post("/study", data=answer_for(page) | {"video_events": ended_only["video_events"]}).status_code == 200
    )
    with lenient.app.state.context.db.reading() as session:
        response = session.scalar(select(Response).where(Response.step == 1))
    plan = parse_plan(stored(lenient, Participant)[0].plan)
    assert response.plays == 0 and viewing_problems(response, plan[1])["skipped"]


def test_a_record_whose_play_is_stamped_after_its_end_is_no_viewing(make_client, tmp_path):
    """The page stamps its events in milliseconds since it loaded: a record of a clip that ends 90 s before it
    starts playing was written by no page. Where full views are required the server refuses it as unwatched; where
    not, the export flags it as skipped viewing."""
    forged = json.dumps([{"type": "loaded", "t": 5}, {"type": "play", "t": 91000}, {"type": "ended", "t": 1000}])
    client = make_client(ANONYMOUS)
    page = to_first_clip(client, f"?pilot={pilot_token(client.app.state.context.db, 'paper')}")  # no clip-time wait
    refused = client.post("/study", data=answer_for(page) | {"video_events": forged})
    assert refused.status_code == 422 and "watch the clip to the end" in refused.text
    assert [r.step for r in stored(client, Response)] == [0]

    lenient = make_client(ANONYMOUS | {"require_full_view": "false"})
    ctx = lenient.app.state.context
    page = to_first_clip(lenient, f"?pilot={pilot_token(ctx.db, 'paper')}")
    assert lenient.post("/study", data=answer_for(page) | {"video_events": forged}).status_code == 200
    export_study(ctx.db, ctx.study, tmp_path / "export")
    import csv

    long = list(csv.DictReader((tmp_path / "export" / "long.csv").open(encoding="utf-8")))
    assert {r["skipped_viewing"] for r in long if r["screen"] == "pairwise"} == {"1"}
