"""In Chromium, against `foil serve` with 3-second clips: the skip-to-end attack is undone by the page and refused by
the server, a reload keeps what was typed and the watched clip, the 9-point scale is one row at 360 px, nothing
covers the clip's status panel when it ends, and the ranking page shows its round's clips and a duplicate robot
before sending. Screenshots go to test-artifacts/browser/viewing/."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import select

from app.store.database import Database
from app.store.models import Participant, Response
from app.survey.kinds import pilot_token
from tests.support.browser import ARTIFACTS, SERIOUS, long_clip_server

pytestmark = pytest.mark.browser
PHONE = {"width": 360, "height": 800}
DESKTOP = {"width": 1366, "height": 768}
SHOTS = ARTIFACTS / "viewing"
NEXT = "fieldset[data-answers] button[type=submit]"


@pytest.fixture(scope="module")
def long_server(tmp_path_factory):
    with long_clip_server(tmp_path_factory.mktemp("browser-viewing")) as live:
        yield live


def shoot(page, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"), full_page=True)


def serious_violations(page) -> list:
    found = page.evaluate("async () => (await axe.run(document, {resultTypes: ['violations']})).violations")
    return [(v["id"], [n["html"][:120] for n in v["nodes"]]) for v in found if v["impact"] in SERIOUS]


def to_first_clip(page, base: str, query: str = "") -> None:
    page.goto(base + "/" + query)
    with page.expect_navigation():
        page.click("button[value=agree]")
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")
    page.click("[data-play]")  # the example, watched to the end before the study starts
    page.wait_for_function("() => document.querySelector('video').ended", timeout=20_000)
    with page.expect_navigation():
        page.click("button[type=submit]")
    assert page.locator("input[name=step]").get_attribute("value") == "1"
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")


def responses(server) -> tuple[list, list]:
    db = Database(server.database_url)
    try:
        with db.reading() as session:
            return list(session.scalars(select(Participant))), list(session.scalars(select(Response)))
    finally:
        db.dispose()


def test_skipping_to_the_end_is_undone_by_the_page_and_refused_by_the_server(long_server, new_context):
    page = new_context(DESKTOP).new_page()
    to_first_clip(page, long_server.url)
    assert page.locator(NEXT).is_disabled()
    page.click("[data-play]")
    page.wait_for_timeout(300)
    page.evaluate("() => { const v = document.querySelector('video'); v.currentTime = v.duration - 0.1; }")
    page.wait_for_timeout(500)
    assert page.evaluate("document.querySelector('video').currentTime") < 2.0  # jumped back
    assert page.locator(NEXT).is_disabled()
    assert "seek_blocked" in page.locator("[data-events]").input_value()
    # The attacker goes on anyway: unlocks the form, claims the clip ended, and sends it at once.
    page.evaluate("""() => {
        document.querySelector('fieldset[data-answers]').disabled = false;
        document.querySelector('input[name=better]').checked = true;
        document.querySelector('textarea[name=justification]').value = 'skipped';
        document.querySelector('input[name=difficulty][value="5"]').checked = true;
        document.querySelector('[data-events]').value = JSON.stringify(
            [{type: 'loaded', t: 5}, {type: 'play', t: 10}, {type: 'ended', t: 20}]);
        document.querySelector('form[data-step-form]').submit();
    }""")
    page.wait_for_load_state("load")
    shoot(page, "skip-refused-desktop")
    assert "cannot have been watched to the end" in page.content()
    assert page.locator(NEXT).is_disabled()  # locked again
    people, saved = responses(long_server)
    mine = max(people, key=lambda p: p.id)
    assert [r.step for r in saved if r.participant_id == mine.id] == [0]  # nothing saved for the clip


def test_reload_keeps_the_text_the_choices_and_the_watched_clip(long_server, new_context):
    page = new_context(PHONE).new_page()
    to_first_clip(page, long_server.url)
    page.click("[data-play]")
    page.wait_for_function("() => document.querySelector('video').ended", timeout=20_000)
    # Nothing covers the clip's status panel at its bottom when it ends: no browser controls over the picture.
    covered = page.evaluate("""() => {
        const v = document.querySelector('video'); const r = v.getBoundingClientRect();
        v.scrollIntoView({block: 'center'});
        const s = v.getBoundingClientRect();
        return [v.controls, document.elementFromPoint(s.left + s.width / 2, s.bottom - 4) === v,
                Math.round(r.width), Math.round(r.height)];
    }""")
    assert covered[0] is False and covered[1] is True
    assert abs(covered[2] / covered[3] - 72 / 88) < 0.02  # the box has the clip's own shape
    shoot(page, "clip-ended-phone")
    page.fill("textarea[name=justification]", "It kept its distance")
    page.check("input[name=difficulty][value='4']")
    better = page.locator("input[name=better]").first.get_attribute("value")
    page.check(f"input[name=better][value='{better}']")
    page.reload()
    page.wait_for_function("() => document.querySelector('video').readyState >= 2")
    assert page.input_value("textarea[name=justification]") == "It kept its distance"
    assert page.is_checked("input[name=difficulty][value='4']")
    assert page.is_checked(f"input[name=better][value='{better}']")
    assert page.locator(NEXT).is_enabled()  # still unlocked
    page.click("[data-play]")  # a second viewing after the reload
    page.wait_for_function("() => document.querySelector('video').ended", timeout=20_000)
    with page.expect_navigation():
        page.click("fieldset[data-answers] button[type=submit]")
    people, saved = responses(long_server)
    mine = max(people, key=lambda p: p.id)
    clip = next(r for r in saved if r.participant_id == mine.id and r.step == 1)
    assert clip.plays == 2 and any(e["type"] == "reload" for e in clip.video_events)
    assert clip.answers["justification"] == "It kept its distance" and clip.answers["difficulty"] == 4
    assert clip.details == {"viewport": "360x800"}


@pytest.mark.parametrize("viewport", [PHONE, DESKTOP], ids=["phone", "desktop"])
def test_scales_are_one_even_row_and_the_pages_are_accessible(long_server, new_context, viewport):
    page = new_context(viewport).new_page()
    token = pilot_token(Database(long_server.database_url), "paper")
    to_first_clip(page, long_server.url, f"?pilot={token}")
    shoot(page, f"clip-{viewport['width']}")
    boxes = [page.locator(f"input[name=difficulty][value='{p}']").bounding_box() for p in range(1, 10)]
    assert len({round(b["y"]) for b in boxes}) == 1  # one row
    xs = [b["x"] for b in boxes]
    gaps = [b - a for a, b in zip(xs, xs[1:], strict=False)]
    assert all(g > 0 for g in gaps) and max(gaps) - min(gaps) < 2  # in order, evenly spaced
    assert page.locator(".anchors span").all_inner_texts() == ["Very Easy", "Very Hard"]  # the end labels once
    assert page.evaluate("document.documentElement.scrollWidth") <= viewport["width"]
    assert serious_violations(page) == []


def test_ranking_page_shows_the_rounds_clips_and_a_duplicate_robot_at_once(long_server, new_context):
    page = new_context(DESKTOP).new_page()
    token = pilot_token(Database(long_server.database_url), "paper")
    to_first_clip(page, long_server.url, f"?pilot={token}")
    for _ in range(20):  # a pilot is not held to the clips' playing time: unlock and answer each screen
        if page.locator("select[name^=ranking]").count():
            break
        page.evaluate("""() => {
            document.querySelector('fieldset[data-answers]').disabled = false;
            const played = [{type: 'play', t: 0}, {type: 'ended', t: 1}];
            document.querySelector('[data-events]').value = JSON.stringify(played);
            for (const name of ['better', 'difficulty']) {
                const first = document.querySelector(`input[name=${name}]`); if (first) first.checked = true; }
            const text = document.querySelector('textarea'); if (text) text.value = 'a reason';
        }""")
        with page.expect_navigation():
            page.click("fieldset[data-answers] button[type=submit]")
    assert page.locator(".round-clips video").count() == 3 and page.locator(".robot-key li").count() == 3
    options = page.locator("select[name=ranking-1] option[value]:not([value=''])").all_inner_texts()
    page.select_option("select[name=ranking-1]", options[0])
    page.select_option("select[name=ranking-2]", options[0])
    message = page.locator("[data-rank-error]")
    assert message.is_visible() and options[0] in message.inner_text()  # before anything is sent
    assert page.evaluate("document.querySelector('select[name=ranking-2]').validity.valid") is False
    shoot(page, "ranking-duplicate-desktop")
    page.set_viewport_size(PHONE)
    shoot(page, "ranking-phone")
    assert serious_violations(page) == []
    page.select_option("select[name=ranking-2]", options[1])
    assert not message.is_visible()
    assert page.locator(NEXT).is_enabled()  # the round's clips were watched before: nothing to unlock
    assert {e["type"] for e in json.loads(page.locator("[data-events]").input_value())} == {"loaded"}
