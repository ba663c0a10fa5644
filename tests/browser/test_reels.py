"""In Chromium, against `foil serve` whose pairwise screens show pairs of reels (each robot on its own): the answers
stay locked until every reel has played to its end, one reel plays at a time, a desktop shows the reels side by
side as large as a pairwise clip while a phone stacks them full width, and an answer refused because a reel was not
watched leaves the Play button in view and its message goes once every reel has ended. Screenshots go to
test-artifacts/browser/reels/."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import select

from app.store.database import Database
from app.store.models import Response
from app.survey.kinds import pilot_token
from search.clips.render import MIN_PHONE_TEXT, PHONE_WIDTH
from tests.support.analysis import add_reels
from tests.support.browser import ARTIFACTS, SERIOUS, long_clip_server
from tests.support.survey import make_clip, watched_reels

pytestmark = pytest.mark.browser
DESKTOP = {"width": 1366, "height": 768}
PHONE = {"width": 360, "height": 740}
SHOTS = ARTIFACTS / "reels"
NEXT = "fieldset[data-answers] button[type=submit]"
REEL_S = 1.5


@pytest.fixture(scope="module")
def reels_server(tmp_path_factory):
    work = tmp_path_factory.mktemp("browser-reels")
    reel = work / "reel.mp4"
    make_clip(reel, "testsrc2", size="72x88", seconds=REEL_S)
    with long_clip_server(work, lambda bundle: add_reels(bundle, reel)) as live:
        yield live


def to_reels(page, server) -> None:
    """A pilot's first screen after the instructions (the pilot is not held to the example's playing time; the page
    gates every clip all the same)."""
    db = Database(server.database_url)
    try:
        token = pilot_token(db, "paper")
    finally:
        db.dispose()
    page.goto(f"{server.url}/?pilot={token}")
    with page.expect_navigation():
        page.click("button[value=agree]")
    with page.expect_navigation():
        page.evaluate(
            "() => { document.querySelector('fieldset[data-answers]').disabled = false; "
            "document.querySelector('form[data-step-form]').requestSubmit(); }"
        )
    assert page.locator("[data-reel] video").count() == 2
    page.wait_for_function("() => [...document.querySelectorAll('[data-reel] video')].every(v => v.readyState >= 2)")


def reel_boxes(page) -> list[dict]:
    return page.evaluate("""() => [...document.querySelectorAll('[data-reel] video')].map(v => {
        const r = v.getBoundingClientRect(); return {top: r.top, bottom: r.bottom, left: r.left, width: r.width}; })""")


def ended(page, k: int) -> None:
    page.wait_for_function(f"() => document.querySelectorAll('[data-reel] video')[{k}].ended", timeout=20_000)


def test_the_answers_unlock_only_once_every_reel_has_played_to_its_end(reels_server, new_context):
    page = new_context(DESKTOP).new_page()
    to_reels(page, reels_server)
    assert page.locator(NEXT).is_disabled()
    page.click("[data-reel='0'] [data-play]")
    page.wait_for_timeout(300)
    page.click("[data-reel='1'] [data-play]")  # one reel at a time: the first one pauses
    page.wait_for_function("() => document.querySelectorAll('[data-reel] video')[0].paused")
    ended(page, 1)
    assert page.locator(NEXT).is_disabled()  # one reel played to its end, the other not yet
    assert "play the other robot's clip" in page.locator("[data-reel='1'] [data-status]").inner_text()
    page.click("[data-reel='0'] [data-play]")
    ended(page, 0)
    assert page.locator(NEXT).is_enabled()
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "reels-desktop.png"))

    first, second = reel_boxes(page)
    assert abs(first["top"] - second["top"]) < 2 and second["left"] >= first["left"] + first["width"]  # side by side
    assert max(first["bottom"], second["bottom"]) <= DESKTOP["height"]
    # each as large as a pairwise clip of its shape is here (445 px wide): its legend, drawn MIN_PHONE_TEXT px high
    # per PHONE_WIDTH px of clip (search/clips/render.py), reads at 16 px, not the 13 px of 369-px reels
    assert min(first["width"], second["width"]) * MIN_PHONE_TEXT / PHONE_WIDTH >= 16
    next_button = page.locator(NEXT).bounding_box()  # the questions beside the reels, Next in the first view
    assert next_button["x"] > second["left"] + second["width"] and next_button["y"] + next_button["height"] <= 768
    found = page.evaluate("async () => (await axe.run(document, {resultTypes: ['violations']})).violations")
    assert [v["id"] for v in found if v["impact"] in SERIOUS] == []

    page.check("input[name=better] >> nth=0")
    page.fill("textarea[name=justification]", "It kept its distance")
    page.check("input[name=difficulty][value='3']")
    events = json.loads(page.locator("[data-events]").input_value())
    with page.expect_navigation():
        page.click(NEXT)
    assert page.locator("input[name=step]").get_attribute("value") == "2"
    db = Database(reels_server.database_url)
    try:
        with db.reading() as session:
            saved = session.scalars(select(Response).order_by(Response.id.desc())).first()
    finally:
        db.dispose()
    assert saved.step == 1 and saved.video_events == events
    assert [(e["type"], e["reel"]) for e in events if e["type"] == "ended"] == [("ended", 1), ("ended", 0)]


def test_a_phone_stacks_the_reels_full_width(reels_server, new_context):
    page = new_context(PHONE).new_page()
    to_reels(page, reels_server)
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "reels-phone.png"), full_page=True)
    first, second = reel_boxes(page)
    assert second["top"] >= first["bottom"] and abs(first["left"] - second["left"]) < 2  # one above the other
    assert min(first["width"], second["width"]) >= 0.8 * (PHONE["width"] - 32)  # nearly full width
    play = page.locator("[data-reel='0'] [data-play]").bounding_box()
    assert play["y"] + play["height"] <= PHONE["height"]  # the first reel's Play button in the first view
    assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]


def test_a_refused_answer_keeps_the_play_button_in_view_and_its_message_goes_once_every_reel_ended(
    reels_server, new_context
):
    """Sent with only the first reel played to its end: refused. On a phone the message at the top leaves the first
    reel's Play button in the window; once both reels have played to their ends, the message is gone."""
    page = new_context(PHONE).new_page()
    to_reels(page, reels_server)
    page.evaluate(
        """(events) => {
        document.querySelector('fieldset[data-answers]').disabled = false;
        document.querySelector('input[name=better]').checked = true;
        document.querySelector('textarea[name=justification]').value = 'a reason';
        document.querySelector('input[name=difficulty][value="5"]').checked = true;
        document.querySelector('[data-events]').value = events;
    }""",
        watched_reels([0]),
    )
    with page.expect_navigation():
        page.click(NEXT)
    page.wait_for_function("() => [...document.querySelectorAll('[data-reel] video')].every(v => v.readyState >= 2)")
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "refused-phone.png"))
    summary, play = page.locator(".error-summary"), page.locator("[data-reel='0'] [data-play]")
    assert "Please watch each clip to the end" in summary.inner_text() and page.locator(NEXT).is_disabled()
    assert summary.bounding_box()["y"] >= 0  # the message, and under it the first reel with its Play button
    assert play.bounding_box()["y"] + play.bounding_box()["height"] <= PHONE["height"]
    for k in (0, 1):
        page.click(f"[data-reel='{k}'] [data-play]")
        ended(page, k)
    page.screenshot(path=str(SHOTS / "refused-then-watched-phone.png"))
    assert page.locator(NEXT).is_enabled()
    assert not summary.is_visible() and not page.locator("#video-error").is_visible()
    assert "watch each clip" not in page.locator("main").inner_text()
